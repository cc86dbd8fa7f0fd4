"""Tuning of the classical PI controller's gains (``configs/train/classical_gains.yaml``).

    python -m trackenv.drivers.tune          # every task x terrain; rewrites configs/train/classical_gains.yaml

    from trackenv.drivers.tune import tune_classical
    tune_classical("j_turn", "asphalt")["gains"]
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..envs.controllers import DEFAULT_GAINS, GAIN_GRID, GAINS_FILE, classical_for
from ..envs.tasks import task_class
from .config import TASKS, resolve_task, resolve_terrain
from .episodes import make_eval_env, run_episodes


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
    if task_class(task).steering == "spin":  # no speed loop: only the yaw gains vary
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
        "procedure": ("Grid search (trackenv.drivers.tune.tune_classical; rerun: python -m trackenv.drivers.tune): "
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
                   "# Written by `python -m trackenv.drivers.tune`; the procedure is stated below.\n"
                   + yaml.safe_dump(doc, sort_keys=False, width=110))
    return doc


if __name__ == "__main__":  # python -m trackenv.drivers.tune
    tune_all()
