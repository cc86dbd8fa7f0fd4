"""The ``trackenv`` command line.

    trackenv simulate go_stop_dry_sand --out out/sim       # one thesis test (reconstructed voltages)
    trackenv simulate --voltages 12,-12 --t-end 5 --terrain asphalt --out out/zrt
    trackenv demo --out out/demo                           # every thesis test: figures + summary
    trackenv replay logs/go_stop_01 --out out/replay       # a field-log folder (MODEL.md §9) vs the model
    trackenv replay go_stop_dry_sand --out out/r           # a thesis test (reconstructed voltages)
    trackenv replay --list                                 # the thesis test ids
    trackenv field-twin --out data/field/thesis --seed 0   # SYNTHETIC field twin (known effects + noise)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

RECONSTRUCTED = ("voltages RECONSTRUCTED from the thesis text (configs/field), not measured; "
                 "simulated with the base model")


def _simulate_test(test_id: str, terrain: str | None, internal: str | None, substep: float):
    import numpy as np

    import trackenv as te
    from trackenv.field_profiles import load_field_profile

    prof = load_field_profile(test_id)
    params = te.load_params(terrain or prof.terrain, internal_resistance=internal or prof.internal_resistance)
    vp = te.VoltageProfile.from_arrays(prof.t, prof.volts, source=f"configs/field/{test_id}.yaml")
    t_end = float(np.ceil(prof.t_end / 0.05 - 1e-9) * 0.05)
    traj = te.simulate(params, vp, t_end, substep=substep)
    return prof, params, traj


def _summary(prof, traj) -> dict:
    import numpy as np

    from trackenv.replay import anchor_metrics

    ch = {k: np.asarray(v) for k, v in traj.channels.items()}
    out = {
        "test": prof.id, "terrain": prof.terrain, "maneuver": prof.maneuver,
        "peak_speed_ideal_m_s": float(np.max(np.abs(ch["speed_ideal"]))),
        "peak_yaw_rate_rad_s": float(np.max(np.abs(ch["yaw_rate"]))),
        "peak_current_A": float(np.max(np.abs([ch["i_left"], ch["i_right"]]))),
        "final_position_m": [float(ch["x"][-1]), float(ch["y"][-1])],
        "final_heading_deg": float(np.degrees(ch["heading"][-1])),
        "anchors": [],
    }
    for a in anchor_metrics(prof, traj, 0.05):
        if a["simulated"] is not None:
            out["anchors"].append({"signal": a["signal"], "window_s": [a["t0"], a["t1"]],
                                   "thesis_field": a["thesis_field"], "simulated": a["simulated"],
                                   "rel_diff": a["rel_diff"]})
    return out


def cmd_simulate(args) -> int:
    import numpy as np

    import trackenv as te
    from trackenv.plots import maneuver_figure

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.test:
        prof, params, traj = _simulate_test(args.test, args.terrain, args.internal_resistance, args.substep)
        title, caption = f"{prof.id} ({prof.terrain})", RECONSTRUCTED
    else:
        if not args.voltages:
            print("error: give a thesis test id or --voltages VL,VR", file=sys.stderr)
            return 2
        try:
            vl, vr = (float(x) for x in args.voltages.split(","))
        except ValueError:
            print(f"error: --voltages must be two numbers 'VL,VR', got {args.voltages!r}", file=sys.stderr)
            return 2
        params = te.load_params(args.terrain or "dry_sand", internal_resistance=args.internal_resistance or "constant")
        vp = te.VoltageProfile.from_breakpoints([[0, 0, 0], [args.ramp, vl, vr]])
        traj = te.simulate(params, vp, args.t_end, substep=args.substep)
        title, caption = f"constant {vl:g}/{vr:g} V on {args.terrain or 'dry_sand'}", None
    fig = maneuver_figure(traj, title, out / "simulation.png", caption=caption)
    np.savez(out / "trajectory.npz", t=np.asarray(traj.t), voltage=np.asarray(traj.voltage),
             **{k: np.asarray(v) for k, v in traj.channels.items()})
    print(f"wrote {fig} and {out / 'trajectory.npz'}")
    return 0


def cmd_demo(args) -> int:
    from tqdm import tqdm

    from trackenv.field_profiles import list_field_tests
    from trackenv.plots import maneuver_figure

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    t0 = time.perf_counter()
    for test in tqdm(list_field_tests(), desc="simulating thesis tests", unit="test"):
        prof, params, traj = _simulate_test(test, None, None, args.substep)
        maneuver_figure(traj, f"{prof.id} ({prof.terrain})", out / f"{test}.png", caption=RECONSTRUCTED)
        rows.append(_summary(prof, traj))
    (out / "summary.json").write_text(json.dumps({"note": RECONSTRUCTED, "tests": rows}, indent=2))
    lines = ["# trackenv demo: the thesis's field tests on the base model", "",
             f"*{RECONSTRUCTED}.* Wall time {time.perf_counter() - t0:.1f} s.", "",
             "| test | peak speed m/s | peak yaw rate rad/s | peak current A | anchor: thesis field vs simulated |",
             "|---|---|---|---|---|"]
    for r in rows:
        anchors = "; ".join(f"{a['signal']} {a['window_s'][0]:g}-{a['window_s'][1]:g} s: {a['thesis_field']:g} vs "
                            f"{a['simulated']:.3f} ({a['rel_diff']:+.1%})" for a in r["anchors"]) or "-"
        lines.append(f"| [{r['test']}]({r['test']}.png) | {r['peak_speed_ideal_m_s']:.3f} | "
                     f"{r['peak_yaw_rate_rad_s']:.3f} | {r['peak_current_A']:.2f} | {anchors} |")
    lines += _demo_twin_replays(out, args.substep)
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nwrote {out / 'report.md'}, {out / 'summary.json'} and the figures")
    return 0


def _demo_twin_replays(out: Path, substep: float) -> list[str]:
    """Replay the SYNTHETIC field twin (data/field/thesis) on the base model: where the gap shows."""
    from tqdm import tqdm

    from trackenv.replay import replay

    twin = Path(__file__).resolve().parent.parent / "data" / "field" / "thesis"
    folders = sorted(p for p in twin.glob("*") if (p / "log.csv").exists())
    if not folders:
        return []
    channels = ("speed_ideal", "yaw_rate", "i_left", "i_right")
    lines = ["", "## The synthetic field twin replayed on the base model", "",
             "*The logs in `data/field/thesis` are SYNTHETIC: reconstructed voltages simulated with unmodelled "
             "effects and instrument noise (the truth is withheld in each folder's truth.json). Replaying them on "
             "the base model shows where the gap lies; naming its cause is the diagnosis's job.*", "",
             "| test | " + " | ".join(f"NRMSE {c}" for c in channels) + " |", "|---|" + "---|" * len(channels)]
    for folder in tqdm(folders, desc="replaying the field twin", unit="test"):
        res = replay(folder, out / "twin" / folder.name, substep=substep)
        m = res.metrics["channels"]
        cells = [f"{m[c]['nrmse']:.2f}" if c in m and m[c].get("nrmse") is not None else "-" for c in channels]
        lines.append(f"| [{folder.name}](twin/{folder.name}/replay.png) | " + " | ".join(cells) + " |")
    return lines


REPLAY_HELP = """Replay a field test through the simulator and compare with what was measured.

SOURCE is a field-log folder (MODEL.md §9: log.csv + meta.json) or a thesis test id
(`trackenv replay --list`; their voltages are RECONSTRUCTED from the thesis text, not measured).
A bare thesis id wins over a folder of the same name: write ./NAME for the folder.

The logged voltages are linear between samples; the simulation starts from rest at the log's
first sample (times are shifted to start at 0 if needed) and the simulated channels are
compared at the log's own sample times (|i| when meta.json says current_sensor "absolute").

Writes to --out: log.csv + meta.json (the simulated log, labelled synthetic), replay.png
(simulated vs measured), metrics.json (per-channel RMSE and NRMSE = RMSE / measured range,
or the thesis-text anchors for a thesis test). Bad input exits with code 2 and a message
naming the file, column and row."""


def cmd_replay(args) -> int:
    from trackenv.field_profiles import list_field_tests, load_field_profile

    if args.list:
        print("thesis tests (voltages RECONSTRUCTED from the thesis text, not measured; configs/field):")
        for tid in list_field_tests():
            prof = load_field_profile(tid)
            print(f"  {tid:28s} {prof.maneuver:17s} {prof.terrain:9s} {prof.t_end:5.1f} s")
        return 0
    if not args.source:
        print("trackenv replay: error: give a field-log folder or a thesis test id (see --list)", file=sys.stderr)
        return 2
    from tqdm import tqdm

    from trackenv.replay import replay

    # a status line (stage + elapsed time) on a terminal; the simulation is one compiled call
    stages = tqdm(desc=f"replay {args.source}", leave=False, disable=None, bar_format="{desc} [{elapsed}]")

    def progress(msg: str) -> None:
        stages.set_description_str(f"replay: {msg}")
        stages.update(1)

    t0 = time.perf_counter()
    try:
        res = replay(args.source, args.out, terrain=args.terrain, internal_resistance=args.internal_resistance,
                     effects=tuple(args.effects or ()), substep=args.substep, dt=args.dt, progress=progress)
    except OSError as exc:
        print(f"trackenv: error: {exc}", file=sys.stderr)
        return 2
    finally:
        stages.close()
    m = res.metrics
    if res.kind == "thesis_test":
        print(f"{res.source}: {m['note']}")
        for a in m["anchors"]:
            if a["simulated"] is not None:
                print(f"  anchor {a['signal']} {a['stat']} {a['t0']:g}-{a['t1']:g} s: thesis {a['thesis_field']:g} "
                      f"{a['unit']}, simulated {a['simulated']:.3f} ({a['rel_diff']:+.1%})")
    else:
        synth = " (a synthetic log)" if m["log_is_synthetic"] else ""
        print(f"{res.source}{synth}: {m['n_samples']} samples, {m['duration_s']:.2f} s, {m['terrain']}, "
              f"ammeter {m['current_sensor']}")
        for ch, c in m["channels"].items():
            nr = "n/a (constant)" if c["nrmse"] is None else f"{c['nrmse']:.4f}"
            print(f"  {ch:12s} RMSE {c['rmse']:.4g}  NRMSE {nr}  ({c['n']} samples)")
        if m["not_in_log"]:
            print(f"  not in the log: {', '.join(m['not_in_log'])}")
    files = ", ".join(str(p) for p in res.files.values())
    print(f"wrote {files} in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_field_twin(args) -> int:
    from trackenv.fieldtwin import make_field_twin

    t0 = time.perf_counter()
    folders = make_field_twin(args.out, seed=args.seed, sample_rate=args.rate, tests=args.tests or None)
    size = sum(f.stat().st_size for d in folders for f in d.iterdir() if f.is_file())
    print(f"wrote the SYNTHETIC field twin ({len(folders)} tests, {size / 1e6:.2f} MB) to {args.out} "
          f"in {time.perf_counter() - t0:.1f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from trackenv.simulate import DEFAULT_SUBSTEP

    p = argparse.ArgumentParser(prog="trackenv", description="PackBot tracked-vehicle simulator (JAX).",
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("simulate", help="simulate one thesis test or constant voltages; write a figure")
    s.add_argument("test", nargs="?", help="thesis test id (configs/field), e.g. go_stop_dry_sand")
    s.add_argument("--voltages", help="constant 'VL,VR' in volts instead of a thesis test")
    s.add_argument("--t-end", type=float, default=5.0, help="duration [s] with --voltages (default 5)")
    s.add_argument("--ramp", type=float, default=0.3, help="ramp time [s] with --voltages (default 0.3)")
    s.add_argument("--terrain", help="terrain id of configs/terrain (default: the test's)")
    s.add_argument("--internal-resistance", choices=("constant", "viscous"))
    s.add_argument("--substep", type=float, default=DEFAULT_SUBSTEP, help="integration substep [s]")
    s.add_argument("--out", default="out/simulate", help="output folder")
    s.set_defaults(func=cmd_simulate)
    d = sub.add_parser("demo", help="simulate every thesis test; write figures and a report")
    d.add_argument("--out", default="out/demo")
    d.add_argument("--substep", type=float, default=DEFAULT_SUBSTEP)
    d.set_defaults(func=cmd_demo)
    r = sub.add_parser("replay", help="replay a field-log folder or thesis test; compare, write log + figure",
                       description=REPLAY_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("source", nargs="?", metavar="SOURCE", help="field-log folder or thesis test id")
    r.add_argument("--list", action="store_true", help="list the thesis test ids and exit")
    r.add_argument("--out", default="out/replay", help="output folder (default out/replay)")
    r.add_argument("--terrain", help="terrain id of configs/terrain (default: meta.json's or the test's)")
    r.add_argument("--effects", nargs="+", metavar="ID", default=(),
                   help="MODEL.md §8 effect ids to add to the base model (none implemented yet); "
                        "give SOURCE before this option")
    r.add_argument("--internal-resistance", choices=("constant", "viscous"),
                   help="internal track resistance model (default: the test's; constant for logs)")
    r.add_argument("--substep", type=float, default=DEFAULT_SUBSTEP, help="integration substep [s] (default 0.001)")
    r.add_argument("--dt", type=float, default=0.05,
                   help="largest simulation output step [s] (default 0.05; finer for faster logs)")
    r.set_defaults(func=cmd_replay)
    f = sub.add_parser("field-twin", help="write the SYNTHETIC field twin of the thesis tests (known effects + noise)")
    f.add_argument("--out", default="data/field/thesis", help="output folder (default data/field/thesis)")
    f.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    f.add_argument("--rate", type=float, default=50.0, help="sample rate [Hz] (default 50)")
    f.add_argument("--tests", nargs="+", metavar="ID", help="test ids (default: all)")
    f.set_defaults(func=cmd_field_twin)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from trackenv.params import ConfigError
    from trackenv.simulate import SimulationDiverged

    try:
        return args.func(args)
    except (ConfigError, SimulationDiverged, ValueError, KeyError) as exc:
        print(f"trackenv: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
