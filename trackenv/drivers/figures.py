"""Figures of an evaluation: the first episode of each method (CG path, motor voltages, speed, yaw rate, currents)."""

from __future__ import annotations

from pathlib import Path

COLORS = {"learned": "tab:blue", "open_loop": "tab:orange", "classical": "tab:green"}


def _save(fig, path):
    """Lay out, write (110 dpi) and close ``fig``; returns ``path``."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


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
    paths.append(_save(fig, p))

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
    paths.append(_save(fig, p))

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
    paths.append(_save(fig, p))
    return paths
