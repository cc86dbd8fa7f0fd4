"""Learning curves of a training run: return and success against environment steps and wall time.

:class:`LearningCurve` is a Stable-Baselines3 callback that appends one row per rollout (PPO) or per
``every`` steps (SAC) to a table; :func:`write_curve` saves it as ``<driver>.curve.csv`` and
:func:`curve_figure` draws ``<driver>.curve.png`` (mean episode return and success rate of the last
100 finished episodes, against steps and against wall time, with the share of the wall time spent in
the environment).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

try:
    from stable_baselines3.common.callbacks import BaseCallback as _BaseCallback
except ImportError:  # pragma: no cover - SB3 is a dependency, but keep the module importable
    _BaseCallback = object

COLUMNS = ("timesteps", "wall_s", "env_s", "mean_return", "success_rate", "episodes")


class LearningCurve(_BaseCallback):
    """Records ``COLUMNS`` at each rollout end, or every ``every`` steps if ``every`` > 0 (off-policy
    algorithms, whose rollouts are a few steps long).

    ``timer``: the run's :class:`~trackenv.drivers.wrappers.StepTimer` (seconds in the environment);
    ``offset``: (steps, wall s, env s) already spent before this run (a resumed one).
    """

    def __init__(self, timer, every: int = 0, offset: tuple = (0, 0.0, 0.0), rows: list | None = None):
        super().__init__()
        self.timer = timer
        self.every = int(every)
        self.offset = offset
        self.rows = list(rows or [])
        self._t0 = time.perf_counter()  # made just before ``learn``, whose setup already steps the env
        self._last = 0

    def _record(self) -> None:
        ep = list(self.model.ep_info_buffer)
        self.rows.append({
            "timesteps": int(self.model.num_timesteps),
            "wall_s": self.offset[1] + time.perf_counter() - self._t0,
            "env_s": self.offset[2] + self.timer.step_seconds + self.timer.reset_seconds,
            "mean_return": float(np.mean([e["r"] for e in ep])) if ep else float("nan"),
            "success_rate": float(np.mean([e.get("is_success", 0.0) for e in ep])) if ep else float("nan"),
            "episodes": len(ep),
        })
        self._last = self.model.num_timesteps

    def _on_rollout_end(self) -> None:
        if not self.every:
            self._record()

    def _on_step(self) -> bool:
        if self.every and self.model.num_timesteps - self._last >= self.every:
            self._record()
        return True


def write_curve(rows: list[dict], path: Path) -> Path:
    """The curve as CSV (``COLUMNS``)."""
    import pandas as pd  # noqa: PLC0415

    pd.DataFrame(rows, columns=list(COLUMNS)).to_csv(path, index=False, float_format="%.6g")
    return path


def read_curve(path: Path) -> list[dict]:
    import pandas as pd  # noqa: PLC0415

    return pd.read_csv(path).to_dict("records")


def curve_figure(rows: list[dict], title: str, path: Path, guide_steps: int | None = None) -> Path:
    """Return and success rate against steps (left) and wall time (right); PNG. ``guide_steps``: a guided
    plain driver's curriculum length (the step at which the classical part's weight reaches 0), marked by
    a dotted line."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from .figures import _save  # noqa: PLC0415

    steps = np.array([r["timesteps"] for r in rows], float)
    wall = np.array([r["wall_s"] for r in rows], float)
    ret = np.array([r["mean_return"] for r in rows], float)
    succ = np.array([r["success_rate"] for r in rows], float)
    share = rows[-1]["env_s"] / max(rows[-1]["wall_s"], 1e-9) if rows else float("nan")
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, x, xlabel in ((axes[0], steps, "environment steps"), (axes[1], wall, "wall time [s]")):
        ax.plot(x, ret, color="tab:blue")
        ax.set_xlabel(xlabel)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))  # 140000 steps as 1.4 x 1e5
        ax.set_ylabel("mean episode return (last 100)", color="tab:blue")
        tw = ax.twinx()
        tw.plot(x, succ, color="tab:green", ls="--")
        tw.set_ylim(-0.05, 1.05)
        tw.set_ylabel("success rate (last 100)", color="tab:green")
        if guide_steps and len(rows) > 1:
            xg = guide_steps if x is steps else float(np.interp(guide_steps, steps, wall))
            ax.axvline(xg, color="0.4", ls=":", lw=1)
            ax.text(xg, 0.02, " PI weight 0", transform=ax.get_xaxis_transform(), fontsize=7, color="0.3")
    fig.suptitle(f"{title} (SIMULATED training; env share of wall time {100 * share:.0f} %)", fontsize=9)
    return _save(fig, path)
