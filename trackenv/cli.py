"""The ``trackenv`` command line.

    trackenv simulate go_stop_dry_sand --out out/sim       # one thesis test (reconstructed voltages)
    trackenv simulate --voltages 12,-12 --t-end 5 --terrain asphalt --out out/zrt
    trackenv demo --out out/demo                           # every thesis test: figures + summary
    trackenv replay logs/go_stop_01 --out out/replay       # a field-log folder (docs/model.md §9) vs the model
    trackenv replay go_stop_dry_sand --out out/r           # a thesis test (reconstructed voltages)
    trackenv replay --list                                 # the thesis test ids
    trackenv field-twin --out data/field/thesis --seed 0   # SYNTHETIC field twin (known effects + noise)
    trackenv diagnose data/field/thesis --out out/diag     # sim-to-real gap: where, which effect, how far (per terrain)
    trackenv diagnose-benchmark --cases 14                 # the withheld-effect check on blind cases
    trackenv import borealtc data/measured/borealtc --out out/borealtc   # MEASURED runs -> speed-mode field logs
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def cmd_simulate(args) -> int:
    import numpy as np

    import trackenv as te
    from trackenv.demo import RECONSTRUCTED, simulate_test
    from trackenv.outputs import prepare_output_dir
    from trackenv.plots import maneuver_figure

    out = prepare_output_dir(args.out, "simulate", force=args.force)
    if args.test:
        prof, params, traj = simulate_test(args.test, args.terrain, args.internal_resistance, args.substep)
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
    """``trackenv demo``: every thesis test, the field twin replayed, the gaps diagnosed (trackenv/demo.py)."""
    from trackenv.demo import run_demo

    run_demo(args.out, args.substep, diagnose=not getattr(args, "no_diagnose", False), force=args.force,
             full_budget=args.full_budget)
    return 0


REPLAY_HELP = """Replay a field test through the simulator and compare with what was measured.

SOURCE is a field-log folder (docs/model.md §9: log.csv + meta.json) or a thesis test id
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
                     effects=tuple(args.effects or ()), substep=args.substep, dt=args.dt, progress=progress,
                     force=args.force)
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
            elif a.get("missing") == "output_step":
                print(f"  anchor {a['signal']} {a['stat']}: {a['note']}")
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


def cmd_train(args) -> int:
    """``trackenv train <task> --terrain T --algo ppo|sac``: train an SB3 driver (trackenv/drivers/train.py)."""
    from trackenv.drivers import driver_name, load_config, resolve_algo, resolve_task, resolve_terrain, train

    task, terrain, algo = resolve_task(args.task), resolve_terrain(args.terrain), resolve_algo(args.algo)
    load_config(algo, task, terrain, args.config)  # validate before anything is built
    command = None
    if len(sys.argv) > 1 and sys.argv[1] == "train":
        command = "trackenv " + " ".join(sys.argv[1:])
    res = train(task, terrain, algo, config=args.config, seed=args.seed, timesteps=args.timesteps, out_dir=args.out,
                run_dir=args.run_dir, resume=args.resume, progress_bar=not args.no_progress,
                verbose=1 if args.verbose else 0, command=command, randomize=args.randomize,
                grounds=args.grounds.split(",") if args.grounds else None, init=args.init)
    i = res.info
    if i["final_mean_return"] is None:
        outcome = "no episode finished during training (no mean return or success rate to report)"
    else:
        outcome = f"final mean return {i['final_mean_return']:.4g}, success {i['final_success_rate']:.2f}"
    print(f"{driver_name(task, terrain, args.randomize)} ({algo}, seed {args.seed}): {i['n_timesteps']} steps in "
          f"{i['train_seconds']:.0f} s "
          f"(env stepping {100 * i['env_step_share']:.0f}%); {outcome}")
    print(f"wrote {res.model_path} and {res.info_path}")
    return 0


def cmd_evaluate(args) -> int:
    """``trackenv evaluate <policy.zip> --task T``: learned vs open-loop vs classical (trackenv/drivers/episodes.py)."""
    from trackenv.drivers.episodes import evaluate_cli

    try:
        return evaluate_cli(args)
    except FileNotFoundError as exc:
        print(f"trackenv: error: {exc}", file=sys.stderr)
        return 2


def cmd_diagnose(args) -> int:
    from trackenv.diagnose import diagnose
    from trackenv.diagnose.core import check_options
    from trackenv.outputs import prepare_output_dir

    only = [x for x in args.tests.split(",") if x] if args.tests else None
    cands = [x for x in args.candidates.split(",") if x] if args.candidates else None
    check_options(seed=args.seed, polish_iters=args.polish_iters, alpha=args.alpha, candidates=cands)  # before --out is made
    from trackenv.diagnose.terrains import summary_of, terrain_groups

    inputs = [args.folder]
    summary = summary_of(args.after) if args.after is not None else None
    each = args.terrains == "each"
    if args.terrains == "auto":  # a summary is continued terrain by terrain, a pooled report pooled
        if args.after is not None:
            each = summary is not None
        else:
            each = len(terrain_groups(args.folder, only)[0]) > 1
            if each:
                print("the tests span several terrains: one diagnosis per terrain (--terrains pooled fits one effect "
                      "to all of them)", file=sys.stderr)
    if args.after is not None:
        from trackenv.diagnose.candidates import named_fits_from_report

        if each and summary is not None:
            inputs.append(summary.parent)
        else:
            named = named_fits_from_report(args.after, args.internal_resistance)  # readable, and names an effect
            inputs.append(Path(named[-1].source).parent)  # --out must not overwrite the report it continues
    prepare_output_dir(args.out, "diagnose", force=args.force, inputs=inputs)
    options = dict(tests=only, internal_resistance=args.internal_resistance, candidates=cands, seed=args.seed,
                   figures=not args.no_figures, progress=True, polish_iters=args.polish_iters, alpha=args.alpha,
                   vehicle=args.vehicle, after=args.after)
    if each:
        from trackenv.diagnose.terrains import diagnose_each_terrain

        r = diagnose_each_terrain(args.folder, args.out, **options)
        print(f"{r.report['data_label']}")
        shrink = ("" if r.verdict["effect"] == "none" else f" (over all tests: held-out gap shrink "
                  f"{100 * r.verdict['heldout_gap_shrink']:.0f}%, in-sample {100 * r.verdict['insample_gap_shrink']:.0f}%)")
        print(f"verdict: {r.verdict['effect']}{shrink}")
        for terrain, e in r.report["terrains"].items():
            print(f"  {terrain} ({', '.join(e['tests'])}): {e['verdict']['verdict_line']}")
        print(f"report: {Path(args.out) / 'report.md'} ({r.report['timing']['wall_s']:.0f} s)")
        if r.verdict["effect"] not in ("none", None):
            print(f"what remains once they are in the model: the same command with --after "
                  f"{Path(args.out) / 'report.json'} and another --out")
        return 0
    d = diagnose(args.folder, args.out, **options)
    v = d.verdict
    print(f"{d.report['data_label']}")
    print(f"verdict: {v['verdict_line']}")
    for c in d.report["gap_cells"][:3]:
        print(f"  gap in {c['test']} / {c['signal']} / {c['phase']}: NRMSE {100 * c['nrmse_before']:.1f}%, "
              f"bias {c['bias_before']:+.3g}")
    print(f"report: {Path(args.out) / 'report.md'} ({d.report['timing']['wall_s']:.0f} s)")
    if v["effect"] not in ("none", None):
        print(f"what remains once it is in the model: the same command with --after {Path(args.out) / 'report.json'} "
              "and another --out")
    return 0


def cmd_diagnose_benchmark(args) -> int:
    from trackenv.diagnose.benchmark import run_benchmark

    labels = [x for x in args.labels.split(",") if x] if args.labels else None
    if args.rescore:
        from trackenv.diagnose.benchmark import rescore

        s = rescore(args.out, alpha=args.alpha)
        s.pop("rows")
        print(json.dumps({k: v for k, v in s.items() if k != "confusion"}, indent=1))
        return 0
    res = run_benchmark(args.out, args.cases, seed=args.seed, null_fraction=args.null_fraction, labels=labels,
                        n_tests=args.tests_per_case, t_max=args.t_max, near_limit_fraction=args.near_limit_fraction,
                        rounds=args.rounds, search_points=args.search_points, polish_iters=args.polish_iters,
                        alpha=args.alpha)
    s = res["summary"]
    print(json.dumps({k: v for k, v in s.items() if k != "confusion"}, indent=1))
    print(f"report: {Path(args.out) / 'benchmark.md'}")
    if args.min_top1 is not None and (s["top1_accuracy"] or 0.0) < args.min_top1:
        print(f"FAILED: top-1 accuracy {s['top1_accuracy']:.2f} < {args.min_top1}", file=sys.stderr)
        return 1
    return 0


def cmd_import_borealtc(args) -> int:
    """``trackenv import borealtc <folder> --out <dir>``: BorealTC runs -> field logs (trackenv/importers/borealtc.py)."""
    from trackenv.importers import import_borealtc

    t0 = time.perf_counter()
    try:
        folders = import_borealtc(args.folder, args.out, runs=args.runs, force=args.force, progress=True,
                                  report=print)
    except OSError as exc:
        print(f"trackenv: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {len(folders)} MEASURED field log(s) (speed mode) to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


IMPORT_BOREALTC_HELP = """Convert runs of the BorealTC dataset (a Clearpath Husky A200; MEASURED, MIT licence) into
docs/model.md §9.1 field-log folders <out>/<CLASS>_<XX>/ in speed mode: the wheel surface speeds are
the input, the motor currents and the IMU's yaw rate (box-averaged onto the wheel-service time base)
the measurements. FOLDER holds one sub-folder per terrain class (ASPHALT/, SANDY_LOAM/) with
pro_XX.csv and imu_XX.csv files, e.g. data/measured/borealtc. Existing field logs in --out are not
overwritten without --force. Bad input exits with code 2 and a message naming the file."""


def build_parser() -> argparse.ArgumentParser:
    from trackenv.envs.tasks import TASK_CLASSES
    from trackenv.simulate import DEFAULT_SUBSTEP

    task_help = " | ".join(c.name for c in TASK_CLASSES) + f" (or {TASK_CLASSES[0].env_name} ...)"

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
    s.add_argument("--force", action="store_true",
                   help="write into the output folder even if it holds field logs trackenv did not write")
    s.set_defaults(func=cmd_simulate)
    d = sub.add_parser("demo", help="simulate every thesis test; write figures and a report")
    d.add_argument("--out", default="out/demo")
    d.add_argument("--substep", type=float, default=DEFAULT_SUBSTEP)
    d.add_argument("--no-diagnose", action="store_true", help="skip the gap diagnoses (the slowest part)")
    d.add_argument("--full-budget", action="store_true",
                   help="diagnose with trackenv diagnose's default search budget (about 1.4x the simulations "
                        "of the demo's, trackenv/demo.py DEMO_BUDGET)")
    d.add_argument("--force", action="store_true",
                   help="write into the output folder even if it holds field logs trackenv did not write")
    d.set_defaults(func=cmd_demo)
    r = sub.add_parser("replay", help="replay a field-log folder or thesis test; compare, write log + figure",
                       description=REPLAY_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("source", nargs="?", metavar="SOURCE", help="field-log folder or thesis test id")
    r.add_argument("--list", action="store_true", help="list the thesis test ids and exit")
    r.add_argument("--out", default="out/replay", help="output folder (default out/replay)")
    r.add_argument("--terrain", help="terrain id of configs/terrain (default: meta.json's or the test's)")
    r.add_argument("--effects", nargs="+", metavar="ID", default=(),
                   help="docs/model.md §8 effect ids to add to the base model (none implemented yet); "
                        "give SOURCE before this option")
    r.add_argument("--internal-resistance", choices=("constant", "viscous"),
                   help="internal track resistance model (default: the test's; constant for logs)")
    r.add_argument("--substep", type=float, default=DEFAULT_SUBSTEP, help="integration substep [s] (default 0.0005)")
    r.add_argument("--dt", type=float, default=0.05,
                   help="largest simulation output step [s] (default 0.05; finer for faster logs)")
    r.add_argument("--force", action="store_true",
                   help="write into the output folder even if it holds field logs trackenv did not write")
    r.set_defaults(func=cmd_replay)
    f = sub.add_parser("field-twin", help="write the SYNTHETIC field twin of the thesis tests (known effects + noise)")
    f.add_argument("--out", default="data/field/thesis", help="output folder (default data/field/thesis)")
    f.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    f.add_argument("--rate", type=float, default=50.0, help="sample rate [Hz] (default 50)")
    f.add_argument("--tests", nargs="+", metavar="ID", help="test ids (default: all)")
    f.set_defaults(func=cmd_field_twin)
    t = sub.add_parser("train", help="train a Stable-Baselines3 driver (configs/train/<algo>.yaml)")
    t.add_argument("task", help=task_help)
    t.add_argument("--terrain", default="dry_sand", help="terrain id of configs/terrain (default dry_sand)")
    t.add_argument("--algo", default="ppo", help="ppo | sac (default ppo)")
    t.add_argument("--config", help="training YAML (default configs/train/<algo>.yaml)")
    t.add_argument("--seed", type=int, default=0, help="seed of the policy and the environments (default 0)")
    t.add_argument("--timesteps", type=int, help="override the config's n_timesteps")
    t.add_argument("--out", help="folder for <EnvName>-<terrain>.zip/.json (default out/train/<name>-<algo>-s<seed>)")
    t.add_argument("--run-dir", help="folder for checkpoints/ and tb/ (default --out)")
    t.add_argument("--resume", action="store_true", help="continue from the latest checkpoint in the run folder")
    t.add_argument("--randomize", action="store_true",
                   help="domain-randomised training: every episode on parameters drawn from the terrain's default "
                        "ranges (trackenv/envs/randomization.py); the driver is named <EnvName>-<terrain>-randomized")
    t.add_argument("--grounds", metavar="T1,T2",
                   help="with --randomize: a ground mixture, every episode on one of these terrain ids drawn first, "
                        "then within its default ranges (e.g. asphalt,dry_sand)")
    t.add_argument("--init", metavar="ZIP",
                   help="start from this trained driver's weights (the config's hyperparameters, n_timesteps more "
                        "steps; e.g. a polish stage at a lower learning rate); never overwritten")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.add_argument("--verbose", action="store_true", help="print SB3's training table")
    t.set_defaults(func=cmd_train)
    e = sub.add_parser("evaluate", help="evaluate a policy zip against the open-loop and classical baselines")
    e.add_argument("policy", help="SB3 policy zip (or 'none': baselines only). SB3 zips are pickles: trusted sources only")
    e.add_argument("--task", required=True, help=task_help)
    e.add_argument("--terrain", default="dry_sand", help="terrain id of configs/terrain (default dry_sand)")
    e.add_argument("--episodes", type=int, default=8, help="seeded episodes per method (default 8)")
    e.add_argument("--seed", type=int, default=1000, help="first episode seed (default 1000)")
    e.add_argument("--randomize", action="store_true",
                   help="sample the terrain per episode (Table 5.6 ranges, trackenv/envs/randomization.py)")
    e.add_argument("--methods", default="learned,open_loop,classical", help="comma-separated subset")
    e.add_argument("--json", help="write the metrics of every method to this JSON file")
    e.add_argument("--figures", help="folder for trajectory / voltage / speed and yaw-rate figures (PNG)")
    e.add_argument("--log-dir", help="write every episode as a docs/model.md §9 field-log folder here (SYNTHETIC)")
    e.add_argument("--force", action="store_true",
                   help="write into the output folder even if it holds field logs trackenv did not write")
    e.set_defaults(func=cmd_evaluate)

    g = sub.add_parser("diagnose", help="sim-to-real gap diagnosis of a folder of field logs: where, which effect, "
                                        "how far it closes")
    g.add_argument("folder", help="folder with one sub-folder per field test (docs/model.md §9), or one field-log folder")
    g.add_argument("--out", required=True, help="output folder (report.md, report.json, figures)")
    g.add_argument("--tests", default=None, help="comma-separated sub-folder names to use (default: all)")
    g.add_argument("--internal-resistance", default="constant", choices=["constant", "viscous"],
                   help="the base model's internal resistance (default constant, Table 5.4)")
    g.add_argument("--candidates", default=None, help="comma-separated candidate names (default: all)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    g.add_argument("--polish-iters", type=int, default=4, help="Levenberg-Marquardt iterations per fit (0: none)")
    g.add_argument("--alpha", type=float, default=0.05, help="significance level of the verdict rule")
    g.add_argument("--vehicle", default=None,
                   help="vehicle id or YAML path for every test instead of its meta.json vehicle (e.g. a calibrated one)")
    g.add_argument("--after", default=None, metavar="REPORT",
                   help="report.json (or its folder) of an earlier diagnosis: the fit it named joins the base model, "
                        "and the candidates look for what remains")
    g.add_argument("--terrains", default="auto", choices=["auto", "each", "pooled"],
                   help="each: diagnose each terrain's tests on its own (<out>/<terrain>/) and summarise the verdicts "
                        "in <out>/report.md; pooled: fit one effect to the tests of every terrain; auto (default): "
                        "each where the tests span several terrains (or --after names a per-terrain summary)")
    g.add_argument("--force", action="store_true",
                   help="write into the output folder even if it holds field logs trackenv did not write")
    g.set_defaults(func=cmd_diagnose)
    b = sub.add_parser("diagnose-benchmark", help="withheld-effect check: blind SYNTHETIC cases, confusion matrix")
    b.add_argument("--cases", type=int, default=14, help="number of blind cases")
    b.add_argument("--out", default="out/diagnose-benchmark")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--null-fraction", type=float, default=0.2)
    b.add_argument("--labels", default=None, help="comma-separated labels, one case each (overrides --cases)")
    b.add_argument("--min-top1", type=float, default=None, help="exit 1 if top-1 accuracy is below this")
    b.add_argument("--tests-per-case", type=int, default=None, help="tests per case (default random 3-6)")
    b.add_argument("--t-max", type=float, default=None, help="longest test [s] (default 15)")
    b.add_argument("--near-limit-fraction", type=float, default=1 / 3,
                   help="fraction of effect cases drawn near the detection limit (1-3 noise sigma)")
    b.add_argument("--rounds", type=int, default=3, help="cross-entropy rounds of the search")
    b.add_argument("--search-points", type=int, default=16, help="points per search round")
    b.add_argument("--polish-iters", type=int, default=4, help="Levenberg-Marquardt iterations per fit")
    b.add_argument("--alpha", type=float, default=0.05, help="significance level of the verdict rule")
    b.add_argument("--rescore", action="store_true",
                   help="re-apply the verdict rule to the cached cases in --out (no fitting)")
    b.set_defaults(func=cmd_diagnose_benchmark)
    imp = sub.add_parser("import", help="convert a public dataset of a real vehicle into field-log folders")
    isub = imp.add_subparsers(dest="dataset", required=True)
    ib = isub.add_parser("borealtc", help="BorealTC (Clearpath Husky A200): MEASURED runs -> speed-mode field logs",
                         description=IMPORT_BOREALTC_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    ib.add_argument("folder", help="the dataset folder (ASPHALT/, SANDY_LOAM/ with pro_XX.csv + imu_XX.csv)")
    ib.add_argument("--out", required=True, help="output folder: one <CLASS>_<XX>/ field log per run")
    ib.add_argument("--runs", default=None, help="comma-separated runs CLASS/XX, e.g. ASPHALT/00,SANDY_LOAM/02 "
                                                 "(default: every run found)")
    ib.add_argument("--force", action="store_true", help="overwrite existing field logs in the output folder")
    ib.set_defaults(func=cmd_import_borealtc)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from trackenv.compile_cache import enable_compilation_cache
    from trackenv.params import ConfigError
    from trackenv.simulate import SimulationDiverged

    enable_compilation_cache()  # compiled programs reused by the next command (trackenv/compile_cache.py)
    try:
        return args.func(args)
    except (ConfigError, SimulationDiverged, ValueError, KeyError) as exc:
        print(f"trackenv: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
