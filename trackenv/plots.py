"""Thesis-style figures of a trajectory: voltages, currents, ideal speed, yaw rate, path (PNG)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _overlay(ax, measured: dict | None, key: str, label: str) -> None:
    """Plot a measured channel (NaN = missing sample) as dots, if it has any sample."""
    if measured is None or key not in measured:
        return
    y = np.asarray(measured[key], dtype=float)
    if not np.any(np.isfinite(y)):
        return
    ax.plot(np.asarray(measured["t"], dtype=float), y, ".", ms=3, alpha=0.6, label=label)


def maneuver_figure(traj, title: str, path: Path, label: str = "simulated (base model)", measured: dict | None = None,
                    caption: str | None = None, current_sensor: str = "signed",
                    measured_label: str = "log", speed_mode: bool = False) -> Path:
    """Write a 5-panel figure of ``traj`` (a single-vehicle :class:`~trackenv.simulate.Trajectory`).

    Args:
        measured: optional ``{"t": (K,), channel: (K,)}`` overlaid as dots (NaN = missing sample);
            channels ``v_left``, ``v_right``, ``i_left``, ``i_right``, ``speed_ideal``, ``yaw_rate``,
            ``x`` and ``y`` (the latter in the trajectory's frame) are used where present.
        current_sensor: ``"signed"`` plots the simulated currents as they are; ``"absolute"`` plots |i|,
            as the thesis's field ammeter reports them (use it to compare with such a log).
        measured_label: legend suffix of the measured data, e.g. ``"field log"``.
        speed_mode: the trajectory was driven by prescribed speeds (:class:`~trackenv.simulate.SpeedProfile`):
            panel (a) shows the voltage the drive needs, panel (c) the prescribed (input) speed.
    """
    t = np.asarray(traj.t)
    ch = {k: np.asarray(v) for k, v in traj.channels.items()}
    volts = np.asarray(traj.voltage)
    fig = plt.figure(figsize=(11, 8.5), constrained_layout=True)
    grid = fig.add_gridspec(3, 2)
    ml = measured_label
    ax = fig.add_subplot(grid[0, 0])
    ax.plot(t, volts[:, 0], label="left")
    ax.plot(t, volts[:, 1], "--", label="right")
    _overlay(ax, measured, "v_left", f"left ({ml} samples)")
    _overlay(ax, measured, "v_right", f"right ({ml} samples)")
    ax.set(ylabel="motor voltage [V]",
           title="(a) drive voltage needed (simulated, 4.2)" if speed_mode else "(a) input voltages")
    ax.legend()
    ax = fig.add_subplot(grid[0, 1])
    absolute = current_sensor == "absolute"
    cur = (lambda x: np.abs(x)) if absolute else (lambda x: x)  # noqa: E731
    ax.plot(t, cur(ch["i_left"]), label="left")
    ax.plot(t, cur(ch["i_right"]), "--", label="right")
    _overlay(ax, measured, "i_left", f"left ({ml})")
    _overlay(ax, measured, "i_right", f"right ({ml})")
    ax.set(ylabel="motor current |i| [A]" if absolute else "motor current [A] (signed)",
           title="(b) motor currents")
    ax.legend()
    ax = fig.add_subplot(grid[1, 0])
    ax.plot(t, ch["speed_ideal"], label="ideal speed r_s(ω_l+ω_r)/2")
    ax.plot(t, ch["u"], ":", label="CG forward speed u")
    _overlay(ax, measured, "speed_ideal", f"ideal speed ({ml})")
    ax.set(ylabel="speed [m/s]", title="(c) speed (ideal speed: the prescribed input)" if speed_mode else "(c) speed")
    ax.legend()
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, ch["yaw_rate"], label="yaw rate")
    _overlay(ax, measured, "yaw_rate", f"yaw rate ({ml})")
    ax.set(ylabel="yaw rate [rad/s]", title="(d) yaw rate")
    ax.legend()
    for a in fig.axes:
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
    ax = fig.add_subplot(grid[2, :])
    ax.plot(ch["x"], ch["y"], label="simulated" if measured is not None and "x" in measured else None)
    if measured is not None and "x" in measured and "y" in measured:
        ax.plot(np.asarray(measured["x"], float), np.asarray(measured["y"], float), ".", ms=3, alpha=0.6,
                label=f"{ml}")
    ax.plot(ch["x"][0], ch["y"][0], "go", label="start")
    ax.plot(ch["x"][-1], ch["y"][-1], "rs", label="end")
    ax.set(xlabel="X [m]", ylabel="Y [m]", title="(e) CG trajectory")
    ax.set_aspect("equal", adjustable="datalim")  # a straight run keeps a readable panel
    ax.grid(alpha=0.3)
    ax.legend()
    fig.suptitle(f"{title} — {label}")
    if caption:
        fig.get_layout_engine().set(rect=(0, 0.035, 1, 0.965))  # room for the caption under the panels
        fig.text(0.01, 0.004, caption, fontsize=8, style="italic", wrap=True)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
