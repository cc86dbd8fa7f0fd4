"""The ``trackenv`` command line.

    trackenv simulate go_stop_dry_sand --out out/sim       # one thesis test (reconstructed voltages)
    trackenv simulate --voltages 12,-12 --t-end 5 --terrain asphalt --out out/zrt
    trackenv demo --out out/demo                           # every thesis test: figures + summary
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

    t = np.asarray(traj.t)
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
    for a in prof.anchors:
        if a.get("stat") != "mean" or a.get("t0") is None:
            continue
        m = (t >= a["t0"]) & (t <= a["t1"])
        if a["signal"] == "current":
            sim = float(np.mean(0.5 * (np.abs(ch["i_left"][m]) + np.abs(ch["i_right"][m]))))
        elif a["signal"] in ch:
            sim = float(np.mean(ch[a["signal"]][m]))
        else:
            continue
        out["anchors"].append({"signal": a["signal"], "window_s": [a["t0"], a["t1"]], "thesis_field": a["value"],
                               "simulated": sim, "rel_diff": (sim - a["value"]) / a["value"]})
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
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nwrote {out / 'report.md'}, {out / 'summary.json'} and {len(rows)} figures")
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
