"""Top-down ``rgb_array`` view of one environment (matplotlib Agg; imported only when rendering).

Draws the reference (path, stop mark, gates or target heading), the trail of the CG, the vehicle's
footprint with both tracks (coloured by the sign of their current: red driving, blue generating),
and a readout of time, forward speed, yaw rate, voltages and currents.
"""

from __future__ import annotations

import math

import numpy as np

from ..physics.geometry import patch_centres
from .tasks.base import FOOTPRINT_LENGTH, FOOTPRINT_WIDTH

WIDTH, HEIGHT, DPI = 640, 480, 100


class Renderer:
    def __init__(self, width: int = WIDTH, height: int = HEIGHT):
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
        from matplotlib.figure import Figure  # noqa: PLC0415

        self.fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI)
        self.canvas = FigureCanvasAgg(self.fig)
        self.ax = self.fig.add_axes((0.12, 0.11, 0.85, 0.8))

    def close(self):
        self.fig.clear()

    def frame(self, drawing: dict, trail, info: dict | None, params, task_name: str) -> np.ndarray:
        from matplotlib.patches import Polygon, Rectangle  # noqa: PLC0415

        ax = self.ax
        ax.clear()
        for xy in drawing.get("dashed", []):
            ax.plot(xy[:, 0], xy[:, 1], ls=":", color="0.6", lw=1)
        for xy in drawing.get("lines", []):
            ax.plot(xy[:, 0], xy[:, 1], ls="--", color="tab:green", lw=1.5, label="reference")
        for mx, my in drawing.get("marks", []):
            ax.plot([mx], [my], marker="x", ms=12, mew=2.5, color="tab:red")
        for x0, x1, yc, w in drawing.get("gates", []):
            ax.add_patch(Rectangle((x0, yc - w / 2), x1 - x0, w, fill=False, ec="tab:orange", lw=1.5))
            for yy in (yc - w / 2, yc + w / 2):
                ax.plot([x0, x1], [yy, yy], ls="none", marker="^", ms=5, color="tab:orange")
        if "finish" in drawing:
            ax.axvline(drawing["finish"], color="tab:red", lw=1, ls="-.")
        for x0, y0, ang in drawing.get("arrows", []):
            ax.annotate("", xy=(x0 + 0.7 * math.cos(ang), y0 + 0.7 * math.sin(ang)), xytext=(x0, y0),
                        arrowprops=dict(arrowstyle="->", color="tab:green", lw=2))
            ax.text(x0 + 0.75 * math.cos(ang), y0 + 0.75 * math.sin(ang), f"target {math.degrees(ang):+.0f} deg",
                    color="tab:green", fontsize=8)
        tr = np.asarray(trail, dtype=float).reshape(-1, 2)
        if len(tr):
            ax.plot(tr[:, 0], tr[:, 1], color="tab:blue", lw=1, alpha=0.8, label="trail")

        state = (info or {}).get("state", {})
        pose = np.asarray(state.get("pose", np.zeros(3)), float)
        vel = np.asarray(state.get("vel", np.zeros(3)), float)
        current = np.asarray(state.get("current", np.zeros(2)), float)
        x, y, psi = pose
        c, s = math.cos(psi), math.sin(psi)
        rot = np.array([[c, -s], [s, c]])

        def box(cx, cy, length, width):
            pts = np.array([[length / 2, width / 2], [length / 2, -width / 2], [-length / 2, -width / 2],
                            [-length / 2, width / 2]]) + np.array([cx, cy])
            return pts @ rot.T + np.array([x, y])

        ax.add_patch(Polygon(box(0.0, 0.0, FOOTPRINT_LENGTH, FOOTPRINT_WIDTH), closed=True, fc="0.85", ec="k", lw=1))
        veh = params.sim.vehicle
        gauge, length, tw = float(veh.track_gauge), float(veh.contact_length), float(veh.track_width)
        centres = np.ravel(np.asarray(patch_centres(veh, 0), float))  # one track, or one patch per tyre
        for k, side in enumerate((1.0, -1.0)):
            col = "tab:red" if current[k] >= 0 else "tab:blue"
            for cx in centres:
                ax.add_patch(Polygon(box(cx, side * gauge / 2, length, tw), closed=True, fc=col, ec="k", lw=0.5))
        nose = np.array([x, y]) + 0.45 * np.array([c, s])
        ax.plot([x, nose[0]], [y, nose[1]], color="k", lw=1.5)

        x0, x1, y0, y1 = drawing.get("bounds", (-2.0, 2.0, -2.0, 2.0))
        if len(tr):
            x0, x1 = min(x0, tr[:, 0].min() - 0.5), max(x1, tr[:, 0].max() + 0.5)
            y0, y1 = min(y0, tr[:, 1].min() - 0.5), max(y1, tr[:, 1].max() + 0.5)
        # equal scale: widen the shorter side to the axes' pixel aspect ratio
        bbox = ax.get_position()
        ratio = (bbox.height * self.fig.get_figheight()) / (bbox.width * self.fig.get_figwidth())
        w, h = x1 - x0, y1 - y0
        if h / w < ratio:
            pad = (ratio * w - h) / 2
            y0, y1 = y0 - pad, y1 + pad
        else:
            pad = (h / ratio - w) / 2
            x0, x1 = x0 - pad, x1 + pad
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.grid(True, lw=0.3)
        ax.set_xlabel("X (m)")
        ax.set_ylabel("Y (m)")
        t = (info or {}).get("time", 0.0)
        self.fig.suptitle(
            f"{task_name}  t = {t:5.2f} s   u = {vel[0]:5.2f} m/s   r = {vel[2]:+5.2f} rad/s   "
            f"i = {current[0]:+5.1f} / {current[1]:+5.1f} A", fontsize=9)
        self.canvas.draw()
        buf = np.asarray(self.canvas.buffer_rgba())
        return np.ascontiguousarray(buf[..., :3])
