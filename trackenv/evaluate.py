"""Evaluate drivers on the same seeded episodes: learned (SB3 zip), open loop (thesis profile), classical (PI).

    trackenv evaluate train/drivers/JTurn-v0-dry_sand.zip --task j_turn --terrain dry_sand \\
        --episodes 8 --json out/eval/jt.json --figures out/eval/jt --log-dir out/eval/jt/logs
    trackenv evaluate none --task go_stop --terrain asphalt          # the two baselines only

    from trackenv.evaluate import evaluate
    res = evaluate("j_turn", "dry_sand", policy="train/drivers/JTurn-v0-dry_sand.zip", episodes=8)
    res["methods"]["classical"]["summary"]["tracking_rmse"]

Methods (each drives the same N episodes, same seeds, in one :class:`~trackenv.envs.vector.TrackVectorEnv`):

- ``learned``: the SB3 policy, deterministic actions (loading warns that zips are pickles).
- ``open_loop``: the **reconstructed** thesis voltage profile of the maneuver and terrain
  (``configs/field/<task>_<terrain>.yaml``; other deformable soils use the dry-sand profile, hard
  ground the asphalt one) played as actions: each control step applies the profile's mean voltage
  over that step, then 0 V once the profile has ended. It is what the thesis's operator did (as far as
  it can be reconstructed), with no feedback.
- ``classical``: :class:`~trackenv.envs.controllers.ClassicalController`, PI on speed and yaw rate mapped to the mean and the
  right-left difference of the two voltages, with gains tuned per task x terrain by the procedure of
  :func:`tune_classical` (stored in ``configs/train/classical_gains.yaml``).

Metrics per episode (the environment's own, :mod:`trackenv.envs.core`):

==================  =====  =====================================================================
success             -      the task's success criterion (:class:`~trackenv.envs.tasks.base.TaskEval`)
tracking_rmse       SI     RMS of the task's primary tracking error over the episode's control steps
                           (go-stop: speed error [m/s]; J-turn, lane change: cross-track [m];
                           zero-radius turn: yaw-rate error [rad/s])
completion_time     s      time of success (NaN when the episode did not succeed)
energy              J      electrical energy drawn, integral of sum_k max(V_k i_k, 0) dt over the
                           1 ms substeps (regeneration not credited)
peak_current        A      max |i| of both motors at the control-step samples (20 Hz)
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
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .envs.controllers import DEFAULT_GAINS, GAIN_GRID, GAINS_FILE, OpenLoop, classical_for, load_gains
from .envs.tasks import task_class
from .train import ENV_NAME, TASKS, load_policy, resolve_task, resolve_terrain

METHODS = ("learned", "open_loop", "classical")
METRICS = ("success", "tracking_rmse", "completion_time", "energy", "peak_current", "episode_return")

# ----------------------------------------------------------------------------------------------
# learned driver


class Learned:
    """An SB3 policy as a batch driver (deterministic actions).

    A residual driver (trained with ``residual: r`` in its config; the zip stores ``trackenv_driver``
    with r and the PI gains) applies clip(classical(obs) + r * policy(obs), -1, 1) with ``params``'s
    classical controller.
    """

    def __init__(self, model, params=None):
        self.model = model
        meta = getattr(model, "trackenv_driver", None) or {}
        self.scale = float(meta.get("residual", 0.0) or 0.0)
        self.ctrl = None
        if self.scale > 0:
            if params is None:
                raise ValueError("a residual driver needs the environment's params for its classical part")
            self.ctrl = classical_for(params, meta.get("gains") or DEFAULT_GAINS)

    def reset(self):
        if self.ctrl is not None:
            self.ctrl.reset()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        a, _ = self.model.predict(obs, deterministic=True)
        a = np.asarray(a, np.float32)
        if self.ctrl is not None:
            a = np.clip(self.ctrl(obs) + self.scale * a, -1.0, 1.0)
        return a.astype(np.float32)


# ----------------------------------------------------------------------------------------------
# episodes


def make_eval_env(task: str, terrain: str, n: int, *, randomize: Any = False, env_kwargs: dict | None = None):
    """A :class:`TrackVectorEnv` for evaluation: normalised actions, no autoreset, physical state in info."""
    from .envs.vector import TrackVectorEnv  # noqa: PLC0415

    kw = dict(env_kwargs or {})
    return TrackVectorEnv(resolve_task(task), n, terrain=terrain, normalize_action=True, autoreset_mode="disabled",
                          info_state=True, domain_randomization=randomize, **kw)


def run_episodes(venv, driver: Callable, seeds) -> list[dict]:
    """Run one episode per environment of ``venv`` (seeded ``seeds``) with ``driver``; traces + metrics.

    Every environment keeps stepping until all have ended; each trace and metric is cut at the
    environment's first end (terminated or truncated).
    """
    seeds = [int(s) for s in seeds]
    n = venv.num_envs
    if len(seeds) != n:
        raise ValueError(f"need {n} seeds, got {len(seeds)}")
    obs, info = venv.reset(seed=seeds)
    if hasattr(driver, "reset"):
        driver.reset()
    vlim = venv.params.voltage_limit
    r_s = float(venv.params.sim.vehicle.sprocket_radius)
    dt = venv.params.control_dt
    st = info["state"]
    traces = [{"t": [0.0], "v": [], "i": [st["current"][k].copy()], "pose": [st["pose"][k].copy()],
               "vel": [st["vel"][k].copy()], "omega": [st["omega"][k].copy()]} for k in range(n)]
    drawing = _drawings(venv)
    done = np.zeros(n, bool)
    final: list[dict | None] = [None] * n
    max_steps = int(venv.params.max_steps)
    for step in range(max_steps):
        a = np.asarray(driver(obs), np.float32).reshape(n, 2)
        obs, rew, term, trunc, info = venv.step(a)
        st = info["state"]
        volts = np.clip(a, -1.0, 1.0) * vlim
        for k in np.flatnonzero(~done):
            tr = traces[k]
            tr["v"].append(volts[k].astype(np.float64))
            tr["t"].append((step + 1) * dt)
            tr["i"].append(st["current"][k].copy())
            tr["pose"].append(st["pose"][k].copy())
            tr["vel"].append(st["vel"][k].copy())
            tr["omega"].append(st["omega"][k].copy())
            if term[k] or trunc[k]:
                done[k] = True
                final[k] = {m: info[m][k] for m in ("success", "off_course", "diverged", "timeout", "time",
                                                    "tracking_rmse", "energy", "episode_return", "completion")}
        if done.all():
            break
    episodes = []
    for k in range(n):
        tr = traces[k]
        f = final[k] or {m: info[m][k] for m in ("success", "off_course", "diverged", "timeout", "time",
                                                 "tracking_rmse", "energy", "episode_return", "completion")}
        t = np.asarray(tr["t"])
        v = np.asarray(tr["v"]).reshape(-1, 2)
        v = np.vstack([v, v[-1:] if len(v) else np.zeros((1, 2))])  # hold the last action on the last sample
        i = np.asarray(tr["i"])
        omega = np.asarray(tr["omega"])
        ep = {
            "seed": seeds[k],
            "success": bool(f["success"]), "off_course": bool(f["off_course"]), "diverged": bool(f["diverged"]),
            "timeout": bool(f["timeout"]),
            "tracking_rmse": float(f["tracking_rmse"]),
            "completion_time": float(f["time"]) if bool(f["success"]) else math.nan,
            "energy": float(f["energy"]), "peak_current": float(np.max(np.abs(i))),
            "episode_return": float(f["episode_return"]), "completion": float(f["completion"]),
            "time": float(f["time"]),
            "trace": {"t": t, "v_left": v[:, 0], "v_right": v[:, 1], "i_left": i[:, 0], "i_right": i[:, 1],
                      "x": np.asarray(tr["pose"])[:, 0], "y": np.asarray(tr["pose"])[:, 1],
                      "heading": np.asarray(tr["pose"])[:, 2], "u": np.asarray(tr["vel"])[:, 0],
                      "yaw_rate": np.asarray(tr["vel"])[:, 2],
                      "speed_ideal": r_s * 0.5 * (omega[:, 0] + omega[:, 1])},
            "drawing": drawing[k] if drawing else None,
        }
        if "params" in info:
            ep["params"] = {p: float(vals[k]) for p, vals in info["params"].items()}
        episodes.append(ep)
    return episodes


def _drawings(venv):
    import jax  # noqa: PLC0415

    try:
        state = venv.state
        return [venv.params.task.drawing(jax.tree.map(lambda x, k=k: x[k], state.task)) for k in range(venv.num_envs)]
    except Exception:  # noqa: BLE001 - drawings only decorate the figures
        return None


def summarize(episodes: list[dict]) -> dict:
    """Success rate and the mean/std of every metric (completion time over successful episodes)."""
    out: dict[str, Any] = {"episodes": len(episodes)}
    out["success_rate"] = float(np.mean([e["success"] for e in episodes])) if episodes else math.nan
    for m in ("tracking_rmse", "energy", "peak_current", "episode_return", "completion_time"):
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
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or episodes < 1:
        raise ValueError(f"episodes must be a positive integer, got {episodes!r}")
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown method(s) {bad}; known: {', '.join(METHODS)}")
    venv = make_eval_env(task, sim_t, int(episodes), randomize=randomize, env_kwargs=env_kwargs)
    model = None
    if "learned" in methods and policy is not None:
        if isinstance(policy, (str, Path)):
            model = load_policy(policy, task, sim_t, env=None)
        else:
            model = policy
        from gymnasium import spaces  # noqa: PLC0415

        from .train import PolicySpaceError, _same_box  # noqa: PLC0415

        want = spaces.Box(np.asarray(venv.params.obs_low), np.asarray(venv.params.obs_high), dtype=np.float32)
        if not _same_box(model.observation_space, want):
            raise PolicySpaceError(f"the policy's observation space {model.observation_space} does not match "
                                   f"{ENV_NAME[task]}'s {want}")
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
    result: dict[str, Any] = {"task": task, "env_id": f"trackenv/{ENV_NAME[task]}", "terrain": terrain,
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
        result["figures"] = [str(f) for f in make_figures(all_eps, task, sim_t, Path(figures))]
    return result


# ----------------------------------------------------------------------------------------------
# outputs


def write_logs(all_eps: dict, task: str, terrain: str, log_dir: Path) -> list[Path]:
    """Each episode as a docs/model.md §9 field-log folder ``<log_dir>/<method>_seed<seed>/`` (SYNTHETIC)."""
    from .fieldlog import write_log_columns  # noqa: PLC0415

    out = []
    for m, eps in all_eps.items():
        for e in eps:
            tr = e["trace"]
            folder = log_dir / f"{m}_seed{e['seed']}"
            cols = {c: tr[c] for c in ("t", "v_left", "v_right", "i_left", "i_right", "speed_ideal", "yaw_rate", "x",
                                       "y", "heading")}
            meta = {"terrain": terrain, "maneuver": task, "current_sensor": "signed", "vehicle": "packbot",
                    "synthetic": True, "simulated": True,
                    "source": f"trackenv evaluate: {m} driver, simulated with the base model (not a field test)",
                    "driver": m, "seed": e["seed"], "success": e["success"],
                    "notes": "SYNTHETIC: simulated episode logged at the 20 Hz control rate; the voltage of a row is "
                             "the action held from that time to the next row (replay interpolates linearly)"}
            write_log_columns(folder, cols, meta)
            out.append(folder)
    return out


COLORS = {"learned": "tab:blue", "open_loop": "tab:orange", "classical": "tab:green"}


def make_figures(all_eps: dict, task: str, terrain: str, folder: Path) -> list[Path]:
    """Trajectories, voltages, speed and yaw-rate traces of the first episode of each method (PNG)."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    folder.mkdir(parents=True, exist_ok=True)
    name = f"{task}_{terrain}"
    paths = []
    fig, ax = plt.subplots(figsize=(6, 4.5))
    first = next(iter(all_eps.values()))[0]
    if first.get("drawing"):
        for line in first["drawing"].get("lines", []):
            ax.plot(line[:, 0], line[:, 1], "k--", lw=0.8, label="reference")
        for mx, my in first["drawing"].get("marks", []):
            ax.plot(mx, my, "kx")
    for m, eps in all_eps.items():
        tr = eps[0]["trace"]
        ax.plot(tr["x"], tr["y"], color=COLORS[m], label=f"{m} ({'success' if eps[0]['success'] else 'fail'})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{task} on {terrain}: CG path (simulated; open loop = RECONSTRUCTED thesis voltages)", fontsize=8)
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles))
    ax.legend(uniq.values(), uniq.keys(), fontsize=8)
    p = folder / f"{name}_trajectories.png"
    fig.tight_layout()
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)

    fig, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for m, eps in all_eps.items():
        tr = eps[0]["trace"]
        axes[0].step(tr["t"], tr["v_left"], where="post", color=COLORS[m], label=m)
        axes[1].step(tr["t"], tr["v_right"], where="post", color=COLORS[m], label=m)
    axes[0].set_ylabel("V_left [V]")
    axes[1].set_ylabel("V_right [V]")
    axes[1].set_xlabel("t [s]")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{task} on {terrain}: motor voltages", fontsize=9)
    p = folder / f"{name}_voltages.png"
    fig.tight_layout()
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)

    fig, axes = plt.subplots(3, 1, figsize=(7, 6.5), sharex=True)
    for m, eps in all_eps.items():
        tr = eps[0]["trace"]
        axes[0].plot(tr["t"], tr["u"], color=COLORS[m], label=m)
        axes[1].plot(tr["t"], tr["yaw_rate"], color=COLORS[m], label=m)
        axes[2].plot(tr["t"], tr["i_left"], color=COLORS[m], label=f"{m} left")
        axes[2].plot(tr["t"], tr["i_right"], color=COLORS[m], ls="--", label=f"{m} right")
    axes[0].set_ylabel("u [m/s]")
    axes[1].set_ylabel("yaw rate [rad/s]")
    axes[2].set_ylabel("current [A]")
    axes[2].set_xlabel("t [s]")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{task} on {terrain}: speed, yaw rate, currents", fontsize=9)
    p = folder / f"{name}_traces.png"
    fig.tight_layout()
    fig.savefig(p, dpi=110)
    plt.close(fig)
    paths.append(p)
    return paths


def format_table(result: dict) -> str:
    """Markdown table of the methods' summaries."""
    unit = result.get("rmse_unit", "")
    lines = [f"{result['env_id']} on {result['sim_terrain']}"
             + (f" (driver for {result['terrain']})" if result["sim_terrain"] != result["terrain"] else "")
             + f", {len(result['seeds'])} episodes, seeds {result['seeds'][0]}..{result['seeds'][-1]}"
             + (", randomised terrain" if result.get("randomize") else ", nominal terrain"),
             "",
             f"| method | success | tracking RMSE [{unit}] | completion time [s] | energy [J] | peak current [A] | return |",
             "|---|---|---|---|---|---|---|"]
    for m, r in result["methods"].items():
        s = r["summary"]
        lines.append(f"| {m} | {s['success_rate']:.0%} | {s['tracking_rmse']:.4f} | {_f(s['completion_time'], 2)} "
                     f"| {s['energy']:.1f} | {s['peak_current']:.2f} | {s['episode_return']:.1f} |")
    return "\n".join(lines)


def _f(x, nd):
    return "-" if not np.isfinite(x) else f"{x:.{nd}f}"


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(result: dict, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_jsonable(result), indent=2) + "\n")
    return path


def evaluate_cli(args) -> int:
    task = resolve_task(args.task)
    terrain = resolve_terrain(args.terrain)
    methods = tuple(m.strip() for m in args.methods.split(",") if m.strip())
    policy = None if str(args.policy).lower() == "none" else args.policy
    from .outputs import prepare_output_dir  # noqa: PLC0415

    force = bool(getattr(args, "force", False))
    for folder in (args.log_dir, args.figures):
        if folder:
            prepare_output_dir(folder, "evaluate", force=force)
    if args.json:
        from .outputs import OutputFolderError, is_trackenv_output  # noqa: PLC0415

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


# ----------------------------------------------------------------------------------------------
# tuning of the classical controller


def tune_classical(task: str, terrain: str, *, seeds=(0,), grid: dict | None = None) -> dict:
    """Grid-search the PI gains for ``task`` on ``terrain``; returns the best gains and the search record.

    Procedure (documented in train/README.md): every combination of ``GAIN_GRID`` (kp_speed x ki_speed
    x kp_yaw x ki_yaw = 4 x 3 x 3 x 3 = 108 sets; the zero-radius turn has no speed loop, so only the
    yaw gains vary) drives one episode per training seed (0; the terrain is nominal) in one vector
    env. The cost of a gain set is its mean tracking RMSE plus a penalty of 10x the task's worst RMSE
    for every episode that does not succeed, so a successful set always beats a failing one; ties
    are broken by the smaller gains (the first in grid order). The evaluation seeds (1000+) are not
    used for tuning.
    """
    task = resolve_task(task)
    terrain = resolve_terrain(terrain)
    grid = dict(grid or GAIN_GRID)
    if task == "zero_radius_turn":
        grid["kp_speed"] = (DEFAULT_GAINS["kp_speed"],)
        grid["ki_speed"] = (DEFAULT_GAINS["ki_speed"],)
    keys = list(DEFAULT_GAINS)
    combos = np.array(np.meshgrid(*[np.asarray(grid[k], np.float64) for k in keys], indexing="ij")).reshape(len(keys), -1).T
    seeds = [int(s) for s in seeds]
    n_sets = combos.shape[0]
    env_seeds = [s for _ in range(n_sets) for s in seeds]
    venv = make_eval_env(task, terrain, len(env_seeds))
    p = venv.params
    gains = {k: np.repeat(combos[:, j], len(seeds)) for j, k in enumerate(keys)}
    ctrl = classical_for(p, gains)
    eps = run_episodes(venv, ctrl, env_seeds)
    venv.close()
    rmse = np.array([e["tracking_rmse"] for e in eps]).reshape(n_sets, len(seeds))
    succ = np.array([e["success"] for e in eps]).reshape(n_sets, len(seeds))
    worst = float(np.nanmax(rmse)) if np.isfinite(rmse).any() else 1.0
    cost = np.where(succ, rmse, rmse + 10.0 * worst).mean(axis=1)
    best = int(np.argmin(cost))
    return {"task": task, "terrain": terrain, "gains": {k: float(combos[best, j]) for j, k in enumerate(keys)},
            "tracking_rmse": float(rmse[best].mean()), "success_rate": float(succ[best].mean()),
            "sets_tried": n_sets, "sets_successful": int(succ.all(axis=1).sum()), "seeds": seeds}


def tune_all(out: Path = GAINS_FILE, terrains=("dry_sand", "asphalt")) -> dict:
    """Tune every task x terrain and write ``configs/train/classical_gains.yaml``."""
    records = {}
    for task in TASKS:
        for terrain in terrains:
            r = tune_classical(task, terrain)
            records[f"{task}/{terrain}"] = r
            print(f"{task}/{terrain}: {r['gains']} rmse {r['tracking_rmse']:.4f} success {r['success_rate']:.0%} "
                  f"({r['sets_successful']}/{r['sets_tried']} sets succeed)", flush=True)
    doc = {
        "procedure": ("Grid search (trackenv.evaluate.tune_classical; rerun: python -m trackenv.evaluate --tune): "
                      "kp_speed in {2,5,10,20} V/(m/s), ki_speed in {0,5,20} V/m, kp_yaw in {1,3,6} V/(rad/s), "
                      "ki_yaw in {0,3,10} V/rad; each set drives the nominal episode (seed 0) of the task on the "
                      "terrain; cost = tracking RMSE, + 10x the worst RMSE if the episode fails; the cheapest set "
                      "wins. Feed-forward gains (11.8/1.1 V per m/s, 5 V and 4.8 V per rad/s) and the outer "
                      "path loop (2 rad/s per rad of heading error, 3 rad/s per m of cross-track) are fixed from "
                      "the thesis's voltage levels (trackenv.envs.controllers)."),
        "gains": {k: r["gains"] for k, r in records.items()},
        "tuning": {k: {kk: vv for kk, vv in r.items() if kk not in ("gains",)} for k, r in records.items()},
    }
    out.write_text("# Tuned PI gains of the classical controller (trackenv.envs.controllers.ClassicalController).\n"
                   "# Written by `python -m trackenv.evaluate --tune`; the procedure is stated below.\n"
                   + yaml.safe_dump(doc, sort_keys=False, width=110))
    return doc


if __name__ == "__main__":  # python -m trackenv.evaluate --tune
    if "--tune" in sys.argv[1:]:
        tune_all()
    else:
        print("usage: python -m trackenv.evaluate --tune   (or: trackenv evaluate --help)", file=sys.stderr)
        sys.exit(2)
