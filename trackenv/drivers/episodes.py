"""Evaluate drivers on the same seeded episodes: learned (SB3 zip), open loop (thesis profile), classical (PI).

    trackenv evaluate train/drivers/JTurn-v0-dry_sand.zip --task j_turn --terrain dry_sand \\
        --episodes 8 --json out/eval/jt.json --figures out/eval/jt --log-dir out/eval/jt/logs
    trackenv evaluate none --task go_stop --terrain asphalt          # the two baselines only

    from trackenv.drivers import evaluate
    res = evaluate("j_turn", "dry_sand", policy="train/drivers/JTurn-v0-dry_sand.zip", episodes=8)
    res["methods"]["classical"]["summary"]["tracking_rmse"]

Methods (each drives the same N episodes, same seeds, in one :class:`~trackenv.envs.vector.TrackVectorEnv`):

- ``learned``: the SB3 policy, deterministic actions (loading warns that zips are pickles).
- ``open_loop``: the **reconstructed** thesis voltage profile of the maneuver and terrain
  (:class:`~trackenv.envs.controllers.OpenLoop`, ``configs/field/<task>_<terrain>.yaml``; other
  deformable soils use the dry-sand profile, hard ground the asphalt one): what the thesis's operator
  did (as far as it can be reconstructed), with no feedback.
- ``classical``: :class:`~trackenv.envs.controllers.ClassicalController`, PI on speed and yaw rate mapped
  to the mean and the right-left difference of the two voltages, with gains tuned per task x terrain by
  :func:`trackenv.drivers.tune.tune_classical` (stored in ``configs/train/classical_gains.yaml``).

Metrics per episode (the environment's own, :mod:`trackenv.envs.core`; recorded by
:class:`~trackenv.drivers.wrappers.EpisodeRecorder`):

==================  =====  =====================================================================
success             -      the task's success criterion (:class:`~trackenv.envs.tasks.base.TaskEval`)
tracking_rmse       SI     RMS of the task's primary tracking error (``Task.primary_error``) over the
                           episode's control steps
completion_time     s      time of success (NaN when the episode did not succeed)
energy              J      electrical energy drawn, integral of sum_k max(V_k i_k, 0) dt over the
                           1 ms substeps (regeneration not credited)
peak_current        A      max |i| of both motors at the control-step samples (20 Hz)
voltage_step_rms    V      RMS change of the commanded voltages from one control step to the next
                           (both motors): how much the command chatters
episode_return      -      the environment's return
==================  =====  =====================================================================

The summary per method: success rate, the mean (and std) of each metric over the episodes
(completion time over the successful ones). By default the terrain is nominal, so every episode of
a deterministic method is the same; ``randomize=True`` samples Table 5.6-style ranges per episode
(:mod:`trackenv.envs.randomization`) and the seeds matter. ``log_dir`` writes each episode as a
docs/model.md §9 field-log folder (``log.csv`` at the 20 Hz control rate, signed currents, ``meta.json``
with ``"synthetic": true``) that ``trackenv replay`` reads like a field test.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..envs.controllers import OpenLoop, classical_for, load_gains
from ..envs.tasks import task_class
from ..params import is_integer
from .config import repo_relative, resolve_task, resolve_terrain
from .policy import Learned, check_observation_space, load_policy
from .wrappers import EpisodeRecorder

METHODS = ("learned", "open_loop", "classical")
METRICS = ("success", "tracking_rmse", "completion_time", "energy", "peak_current", "voltage_step_rms",
           "episode_return")


def make_eval_env(task: str, terrain: str, n: int, *, randomize: Any = False, env_kwargs: dict | None = None):
    """A :class:`TrackVectorEnv` for evaluation: normalised actions, no autoreset, physical state in info."""
    from ..envs.vector import TrackVectorEnv  # noqa: PLC0415

    kw = dict(env_kwargs or {})
    return TrackVectorEnv(resolve_task(task), n, terrain=terrain, normalize_action=True, autoreset_mode="disabled",
                          info_state=True, domain_randomization=randomize, **kw)


def run_episodes(venv, driver: Callable, seeds) -> list[dict]:
    """Run one episode per environment of ``venv`` (seeded ``seeds``) with ``driver``; traces + metrics.

    Every environment keeps stepping until all have ended; each trace and metric is cut at the
    environment's first end (terminated or truncated), see :class:`~trackenv.drivers.wrappers.EpisodeRecorder`.
    """
    seeds = [int(s) for s in seeds]
    n = venv.num_envs
    if len(seeds) != n:
        raise ValueError(f"need {n} seeds, got {len(seeds)}")
    rec = EpisodeRecorder(venv)
    obs = rec.reset(seeds)
    if hasattr(driver, "reset"):
        driver.reset()
    for _ in range(int(venv.params.max_steps)):
        obs = rec.step(np.asarray(driver(obs), np.float32).reshape(n, 2))
        if rec.done.all():
            break
    return rec.episodes()


def summarize(episodes: list[dict]) -> dict:
    """Success rate and the mean/std of every metric (completion time over successful episodes)."""
    out: dict[str, Any] = {"episodes": len(episodes)}
    out["success_rate"] = float(np.mean([e["success"] for e in episodes])) if episodes else math.nan
    for m in (m for m in METRICS if m != "success"):  # success: its rate, above
        vals = np.asarray([e[m] for e in episodes], np.float64)
        vals = vals[np.isfinite(vals)]
        out[m] = float(vals.mean()) if vals.size else math.nan
        out[m + "_std"] = float(vals.std()) if vals.size else math.nan
    return out


def evaluate(task: str, terrain: str = "dry_sand", policy: str | Path | Any | None = None, *, episodes: int = 8,
             seed: int = 1000, randomize: Any = False, methods=METHODS, env_kwargs: dict | None = None,
             gains: dict | None = None, log_dir: str | Path | None = None, figures: str | Path | None = None,
             sim_terrain: str | None = None) -> dict:
    """Evaluate the methods on the same ``episodes`` seeds (``seed``, ``seed`` + 1, ...); see the module doc.

    ``policy``: an SB3 zip path or a loaded model (required for ``learned``; without it the learned
    method is skipped). ``sim_terrain``: simulate on another terrain than the one the baselines and
    policy were made for (robustness: the open-loop profile and the classical gains stay those of
    ``terrain``). Returns ``{"task", "terrain", "seeds", "methods": {m: {"summary", "episodes"}}}``
    (episodes without their traces).
    """
    task = resolve_task(task)
    terrain = resolve_terrain(terrain)
    sim_t = resolve_terrain(sim_terrain) if sim_terrain else terrain
    if not (is_integer(episodes) and episodes >= 1):
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    if not (is_integer(seed) and seed >= 0):
        raise ValueError(f"seed (the first episode's) must be an integer >= 0, got {seed!r}")
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown method(s) {bad}; known: {', '.join(METHODS)}")
    venv = make_eval_env(task, sim_t, int(episodes), randomize=randomize, env_kwargs=env_kwargs)
    model = None
    if "learned" in methods and policy is not None:
        model = load_policy(policy, task, sim_t, env=None) if isinstance(policy, (str, Path)) else policy
        check_observation_space(model, venv.params)
    p = venv.params
    drivers: dict[str, Any] = {}
    for m in methods:
        if m == "learned":
            if model is not None:
                drivers[m] = Learned(model, p)
        elif m == "open_loop":
            drivers[m] = OpenLoop(task, terrain, control_dt=p.control_dt, voltage_limit=p.voltage_limit)
        else:
            drivers[m] = classical_for(p, gains or load_gains(task, terrain))
    seeds = [int(seed) + k for k in range(int(episodes))]
    result: dict[str, Any] = {"task": task, "env_id": task_class(task).env_id, "terrain": terrain,
                              "sim_terrain": sim_t, "randomize": bool(randomize) if isinstance(randomize, bool) else randomize,
                              "seeds": seeds, "rmse_unit": task_class(task).primary_error.label, "methods": {}}
    all_eps = {}
    for m, drv in drivers.items():
        eps = run_episodes(venv, drv, seeds)
        all_eps[m] = eps
        result["methods"][m] = {"summary": summarize(eps),
                                "episodes": [{k: v for k, v in e.items() if k not in ("trace", "drawing")} for e in eps]}
    venv.close()
    if log_dir is not None:
        write_logs(all_eps, task, sim_t, Path(log_dir))
    if figures is not None:
        from .figures import make_figures  # noqa: PLC0415  (matplotlib only when drawing)

        result["figures"] = [repo_relative(f) for f in make_figures(all_eps, task, sim_t, Path(figures))]
    return result


# ----------------------------------------------------------------------------------------------
# outputs


def write_logs(all_eps: dict, task: str, terrain: str, log_dir: Path) -> list[Path]:
    """Each episode as a docs/model.md §9 field-log folder ``<log_dir>/<method>_seed<seed>/`` (SYNTHETIC)."""
    from ..fieldlog import write_log_columns  # noqa: PLC0415

    out = []
    for m, eps in all_eps.items():
        for e in eps:
            tr = e["trace"]
            folder = log_dir / f"{m}_seed{e['seed']}"
            cols = {c: tr[c] for c in ("t", "v_left", "v_right", "i_left", "i_right", "speed_ideal", "yaw_rate", "x",
                                       "y", "heading")}
            meta = {"terrain": terrain, "maneuver": task_class(task).field_profile, "current_sensor": "signed",
                    "vehicle": "packbot", "synthetic": True, "simulated": True,
                    "source": f"trackenv evaluate: {m} driver, simulated with the base model (not a field test)",
                    "driver": m, "seed": e["seed"], "success": e["success"],
                    "notes": "SYNTHETIC: simulated episode logged at the 20 Hz control rate; the voltage of a row is "
                             "the action held from that time to the next row (replay interpolates linearly)"}
            write_log_columns(folder, cols, meta)
            out.append(folder)
    return out


def format_table(result: dict) -> str:
    """Markdown table of the methods' summaries."""
    unit = result.get("rmse_unit", "")
    lines = [f"{result['env_id']} on {result['sim_terrain']}"
             + (f" (driver for {result['terrain']})" if result["sim_terrain"] != result["terrain"] else "")
             + f", {len(result['seeds'])} episodes, seeds {result['seeds'][0]}..{result['seeds'][-1]}"
             + (", randomised terrain" if result.get("randomize") else ", nominal terrain"),
             "",
             f"| method | success | tracking RMSE [{unit}] | completion time [s] | energy [J] | peak current [A] "
             "| voltage step RMS [V] | return |",
             "|---|---|---|---|---|---|---|---|"]
    for m, r in result["methods"].items():
        s = r["summary"]
        lines.append(f"| {m} | {s['success_rate']:.0%} | {s['tracking_rmse']:.4f} | {_f(s['completion_time'], 2)} "
                     f"| {s['energy']:.1f} | {s['peak_current']:.2f} | {_f(s['voltage_step_rms'], 2)} "
                     f"| {s['episode_return']:.1f} |")
    return "\n".join(lines)


def _f(x, nd):
    return "-" if not np.isfinite(x) else f"{x:.{nd}f}"


def jsonable(obj):
    """``obj`` with numpy scalars as Python numbers and non-finite floats as None (for JSON):
    :func:`trackenv.compare.json_clean`."""
    from ..compare import json_clean

    return json_clean(obj)


def write_json(result: dict, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(jsonable(result), indent=2) + "\n")
    return path


def evaluate_cli(args) -> int:
    """``trackenv evaluate``: check the output folders, evaluate, print the table, write the outputs."""
    from ..outputs import OutputFolderError, is_trackenv_output, prepare_output_dir  # noqa: PLC0415

    task = resolve_task(args.task)
    terrain = resolve_terrain(args.terrain)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    policy = None if str(args.policy).lower() == "none" else args.policy
    force = bool(getattr(args, "force", False))
    for folder in (args.log_dir, args.figures):
        if folder:
            prepare_output_dir(folder, "evaluate", force=force)
    if args.json:
        jp = Path(args.json)
        if jp.is_dir():
            raise OutputFolderError(f"{jp}: --json names an existing folder; give a file name")
        parent = jp.parent
        if not force and not is_trackenv_output(parent) and any((parent / f).is_file() for f in ("log.csv", "meta.json")):
            raise OutputFolderError(f"{jp}: --json would write into {parent}, a field-log folder trackenv did not "
                                    "write; choose another file, or pass --force")
    if policy is None:
        methods = tuple(m for m in methods if m != "learned")
    res = evaluate(task, terrain, policy, episodes=args.episodes, seed=args.seed, randomize=bool(args.randomize),
                   methods=methods, log_dir=args.log_dir, figures=args.figures)
    print(format_table(res))
    if args.json:
        print(f"wrote {write_json(res, args.json)}")
    if args.figures:
        print(f"figures in {args.figures}")
    if args.log_dir:
        print(f"field logs (SYNTHETIC, docs/model.md §9) in {args.log_dir}")
    return 0
