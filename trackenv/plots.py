"""Thesis-style figures of a trajectory: voltages, currents, ideal speed, yaw rate, path (PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def maneuver_figure(traj, title: str, path: Path, label: str = "simulated (base model)", measured: dict | None = None,
                    caption: str | None = None) -> Path:
    """Write a 5-panel figure of ``traj`` (a single-vehicle :class:`~trackenv.simulate.Trajectory`)."""
    t = np.asarray(traj.t)
    ch = {k: np.asarray(v) for k, v in traj.channels.items()}
    volts = np.asarray(traj.voltage)
    fig = plt.figure(figsize=(11, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(3, 2)
    ax = fig.add_subplot(grid[0, 0])
    ax.plot(t, volts[:, 0], label="left")
    ax.plot(t, volts[:, 1], "--", label="right")
    ax.set(ylabel="motor voltage [V]", title="(a) input voltages")
    ax.legend()
    ax = fig.add_subplot(grid[0, 1])
    ax.plot(t, ch["i_left"], label="left")
    ax.plot(t, ch["i_right"], "--", label="right")
    if measured is not None and "i_left" in measured:
        ax.plot(measured["t"], measured["i_left"], ".", ms=2, alpha=0.5, label="left (log)")
        ax.plot(measured["t"], measured["i_right"], ".", ms=2, alpha=0.5, label="right (log)")
    ax.set(ylabel="motor current [A] (signed)", title="(b) motor currents")
    ax.legend()
    ax = fig.add_subplot(grid[1, 0])
    ax.plot(t, ch["speed_ideal"], label="ideal speed r_s(ω_l+ω_r)/2")
    ax.plot(t, ch["u"], ":", label="CG forward speed u")
    if measured is not None and "speed_ideal" in measured:
        ax.plot(measured["t"], measured["speed_ideal"], ".", ms=2, alpha=0.5, label="ideal speed (log)")
    ax.set(ylabel="speed [m/s]", title="(c) speed")
    ax.legend()
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, ch["yaw_rate"], label="yaw rate")
    if measured is not None and "yaw_rate" in measured:
        ax.plot(measured["t"], measured["yaw_rate"], ".", ms=2, alpha=0.5, label="yaw rate (log)")
    ax.set(ylabel="yaw rate [rad/s]", title="(d) yaw rate")
    ax.legend()
    for a in fig.axes:
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
    ax = fig.add_subplot(grid[2, :])
    ax.plot(ch["x"], ch["y"])
    ax.plot(ch["x"][0], ch["y"][0], "go", label="start")
    ax.plot(ch["x"][-1], ch["y"][-1], "rs", label="end")
    ax.set(xlabel="X [m]", ylabel="Y [m]", title="(e) CG trajectory", aspect="equal")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.suptitle(f"{title} — {label}")
    if caption:
        fig.text(0.01, 0.002, caption, fontsize=8, style="italic")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
