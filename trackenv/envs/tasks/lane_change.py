"""Double lane change (thesis Fig. 4.9 C, §5.3.3): leave the lane, run in the offset lane, return."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import paths
from .base import (
    FOOTPRINT_LENGTH,
    FOOTPRINT_WIDTH,
    PATH_KERNEL_SCALES,
    PATH_PRIMARY_ERROR,
    RewardParams,
    Task,
    TaskEval,
    as_range,
    as_scalar,
    kernel,
    obs_bounds,
    reward_params,
    sample,
    split_task_kwargs,
)

_OBS = [
    ("speed_error", -5.0, 5.0),  # m/s, v* - u
    ("cross_track", -10.0, 10.0),  # m, > 0 left of the reference line
    ("heading_error", -math.pi, math.pi),  # rad
    ("yaw_rate_error", -30.0, 30.0),  # rad/s, v* kappa - r
    ("curvature", -5.0, 5.0),  # 1/m
    ("curvature_preview", -5.0, 5.0),  # 1/m, 0.5 m ahead
    ("gate_distance", 0.0, 30.0),  # m, to the entry of the next gate (0 inside it)
    ("gate_offset", -10.0, 10.0),  # m, y - centre of the next gate
    ("gate_half_width", 0.0, 2.0),  # m
    ("distance_to_finish", -20.0, 30.0),  # m
]

_DX = 0.025  # m, polyline spacing along X
_LEAD_IN = 1.0
_RUN_OUT = 2.0
PREVIEW = 0.5
# ISO 3888-1 lane widths: a_k * vehicle width + 0.25 m for the entry, offset and exit lanes.
ISO_WIDTH_FACTORS = (1.1, 1.2, 1.3)
ISO_WIDTH_MARGIN = 0.25  # m


class LaneChange(Task):
    """Double lane change through three gated lane sections (cones), PackBot-scale.

    Derived from the thesis's double lane change (Fig. 4.9 C, §5.3.3): straight at 1.1 m/s, turn right,
    turn left back onto the previous line, then stop. The thesis gives no gate geometry; the layout here
    follows the reconstructed input (configs/field/lane_change_dry_sand.yaml), which in the base model
    leaves the line 2.0 m down the course, runs straight about 1.0 m to the right from x = 4.2 to 5.0 m
    and is back on the line by x = 7.2 m. Lane widths use the ISO 3888-1 rule a * W + 0.25 m
    (a = 1.1, 1.2, 1.3) with the PackBot's width W = 0.406 m (0.70, 0.74, 0.78 m).

    Layout along +X: entry lane [0, L_e] centred on y = 0; transition of length L_t; offset lane
    [L_e + L_t, + L_o] centred on y = ``lane_offset`` (< 0: right); transition L_t; exit lane of
    length L_x centred on y = 0; the course finishes at its end. Reference line: y = 0, a half-cosine
    to the offset, straight, a half-cosine back. Reference speed: ``target_speed`` throughout.

    Task observation (prepended to the common part):

    ===================  ===============  ============================================
    speed_error          [-5, 5] m/s      v* - u
    cross_track          [-10, 10] m      signed distance to the reference line, > 0 left
    heading_error        [-pi, pi] rad    psi - psi_line (wrapped)
    yaw_rate_error       [-30, 30] rad/s  v* kappa - r
    curvature            [-5, 5] 1/m      reference curvature at the closest point
    curvature_preview    [-5, 5] 1/m      0.5 m ahead
    gate_distance        [0, 30] m        to the entry of the next gate (0 inside it)
    gate_offset          [-10, 10] m      y - centre of the next (or current) gate
    gate_half_width      [0, 2] m         half its width
    distance_to_finish   [-20, 30] m      x_finish - x
    ===================  ===============  ============================================

    Tracking reward: 0.3 k(e_v, 0.2 m/s) + 0.4 k(e_y, 0.15 m) + 0.2 k(e_psi, 0.25 rad)
    + 0.1 k(e_r, 0.5 rad/s); primary error: e_y.
    Termination: success when the CG crosses the finish (end of the exit lane) without a cone hit;
    off course on a cone hit (a corner of the 0.686 m x 0.406 m footprint outside a lane while within
    its x-range), |e_y| > ``cross_track_limit``, |e_psi| > ``heading_error_limit``, or backing up 1 m
    behind the start. Completion: clip(x / x_finish, 0, 1).
    """

    name = "lane_change"
    env_name = "LaneChange-v0"
    field_profile = "lane_change"
    kernel_scales = PATH_KERNEL_SCALES
    primary_error = PATH_PRIMARY_ERROR
    steering = "path"
    obs_names, obs_low, obs_high = obs_bounds(_OBS)

    @staticmethod
    def reference_speed(col, v_star, a_b):
        """v_ref = v* throughout (the course ends at the finish line, no stop)."""
        return np.full(np.shape(col("speed_error")), v_star)

    reward: RewardParams
    target_speed: jax.Array  # m/s (low, high)
    lane_offset: jax.Array  # m (low, high), < 0 right
    entry_length: jax.Array  # m
    transition_length: jax.Array  # m
    offset_length: jax.Array  # m
    exit_length: jax.Array  # m
    lane_widths: jax.Array  # m, (3,)
    cross_track_limit: jax.Array  # m
    heading_error_limit: jax.Array  # rad
    footprint: jax.Array  # m, (length, width)
    n_path: int = eqx.field(static=True)

    DEFAULTS = dict(target_speed=1.1, lane_offset=-1.0, entry_length=2.0, transition_length=2.2,
                    offset_length=0.8, exit_length=1.2, lane_widths=None, cross_track_limit=1.0,
                    heading_error_limit=math.radians(75.0), max_time=14.0, reward=None)

    @classmethod
    def create(cls, **kwargs):
        o = split_task_kwargs(cls.DEFAULTS, kwargs, "LaneChange")
        lengths = {k: float(as_scalar(k, o[k], 0.0)) for k in ("entry_length", "transition_length", "offset_length", "exit_length")}
        if lengths["transition_length"] <= 0:
            raise ValueError("task parameter 'transition_length' must be > 0")
        widths = o["lane_widths"]
        if widths is None:
            widths = [a * FOOTPRINT_WIDTH + ISO_WIDTH_MARGIN for a in ISO_WIDTH_FACTORS]
        widths = np.asarray(widths, np.float64)
        if widths.shape != (3,) or not np.all(np.isfinite(widths)) or np.any(widths <= 0):
            raise ValueError(f"task parameter 'lane_widths' must be 3 positive numbers, got {o['lane_widths']!r}")
        finish = lengths["entry_length"] + 2 * lengths["transition_length"] + lengths["offset_length"] + lengths["exit_length"]
        n_path = int(math.ceil((_LEAD_IN + finish + _RUN_OUT) / _DX)) + 1
        f = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731
        task = cls(
            reward=o["reward"] if isinstance(o["reward"], RewardParams) else reward_params(**(o["reward"] or {})),
            target_speed=as_range("target_speed", o["target_speed"], 0.05, 2.5),
            lane_offset=as_range("lane_offset", o["lane_offset"], -5.0, 5.0),
            **{k: f(v) for k, v in lengths.items()},
            lane_widths=f(widths),
            cross_track_limit=as_scalar("cross_track_limit", o["cross_track_limit"], 0.0),
            heading_error_limit=as_scalar("heading_error_limit", o["heading_error_limit"], 0.0),
            footprint=f([FOOTPRINT_LENGTH, FOOTPRINT_WIDTH]),
            n_path=n_path,
        )
        return task, float(o["max_time"])

    def _layout(self, offset):
        x1 = self.entry_length
        x2 = x1 + self.transition_length
        x3 = x2 + self.offset_length
        x4 = x3 + self.transition_length
        x5 = x4 + self.exit_length
        starts = jnp.stack([jnp.zeros_like(x1), x2, x4])
        ends = jnp.stack([x1, x3, x5])
        centres = jnp.stack([jnp.zeros_like(offset), offset, jnp.zeros_like(offset)])
        return (x1, x2, x3, x4, x5), starts, ends, centres

    def init(self, key, sim) -> dict:
        k1, k2 = jax.random.split(key)
        v = sample(k1, self.target_speed)
        offset = sample(k2, self.lane_offset)
        (x1, x2, x3, x4, x5), starts, ends, centres = self._layout(offset)
        x = -_LEAD_IN + jnp.arange(self.n_path, dtype=jnp.float32) * _DX
        lt = self.transition_length
        xi1 = jnp.clip((x - x1) / lt, 0.0, 1.0)
        xi2 = jnp.clip((x - x3) / lt, 0.0, 1.0)
        in1 = (x > x1) & (x < x2)
        in2 = (x > x3) & (x < x4)
        half = 0.5 * offset
        y = jnp.where(x <= x3, half * (1.0 - jnp.cos(jnp.pi * xi1)), half * (1.0 + jnp.cos(jnp.pi * xi2)))
        k1_ = jnp.pi / lt
        dy = jnp.where(in1, half * k1_ * jnp.sin(jnp.pi * xi1), jnp.where(in2, -half * k1_ * jnp.sin(jnp.pi * xi2), 0.0))
        d2y = jnp.where(in1, half * k1_**2 * jnp.cos(jnp.pi * xi1), jnp.where(in2, -half * k1_**2 * jnp.cos(jnp.pi * xi2), 0.0))
        path = paths.from_lateral_profile(x, y, dy, d2y)
        return {"path": path, "target_speed": v, "gate_start": starts, "gate_end": ends, "gate_centre": centres,
                "finish": x5}

    def _errors(self, ts, phys):
        proj = paths.project(ts["path"], phys.pose[:2])
        e_psi = paths.wrap_angle(phys.pose[2] - proj.heading)
        v = ts["target_speed"]
        return proj, v - phys.vel[0], e_psi, v * proj.curvature - phys.vel[2]

    def _corners(self, phys):
        x, y, psi = phys.pose[0], phys.pose[1], phys.pose[2]
        hl, hw = 0.5 * self.footprint[0], 0.5 * self.footprint[1]
        lx = jnp.array([1.0, 1.0, -1.0, -1.0]) * hl
        ly = jnp.array([1.0, -1.0, -1.0, 1.0]) * hw
        c, s = jnp.cos(psi), jnp.sin(psi)
        return x + c * lx - s * ly, y + s * lx + c * ly

    def observe(self, ts, phys, sim):
        proj, e_v, e_psi, e_r = self._errors(ts, phys)
        x, y = phys.pose[0], phys.pose[1]
        preview = paths.curvature_at(ts["path"], proj.s + PREVIEW)
        upcoming = ts["gate_end"] > x
        nxt = jnp.where(upcoming.any(), jnp.argmax(upcoming), 2)
        gate_distance = jnp.maximum(ts["gate_start"][nxt] - x, 0.0)
        gate_offset = y - ts["gate_centre"][nxt]
        half_width = 0.5 * self.lane_widths[nxt]
        return jnp.stack([e_v, proj.cross_track, e_psi, e_r, proj.curvature, preview, gate_distance, gate_offset,
                          half_width, ts["finish"] - x])

    def evaluate(self, ts, phys, sim):
        proj, e_v, e_psi, e_r = self._errors(ts, phys)
        e_y = proj.cross_track
        s = self.kernel_scales
        tracking = (0.3 * kernel(e_v, s["speed_error"]) + 0.4 * kernel(e_y, s["cross_track"])
                    + 0.2 * kernel(e_psi, s["heading_error"]) + 0.1 * kernel(e_r, s["yaw_rate_error"]))
        cx, cy = self._corners(phys)  # (4,)
        inside_x = (cx[:, None] >= ts["gate_start"][None]) & (cx[:, None] <= ts["gate_end"][None])  # (4, 3)
        outside_y = jnp.abs(cy[:, None] - ts["gate_centre"][None]) > 0.5 * self.lane_widths[None]
        cone_hit = (inside_x & outside_y).any()
        x = phys.pose[0]
        success = (x >= ts["finish"]) & ~cone_hit
        off = cone_hit | (jnp.abs(e_y) > self.cross_track_limit) | (jnp.abs(e_psi) > self.heading_error_limit) | (x < -1.0)
        completion = jnp.clip(x / ts["finish"], 0.0, 1.0)
        return ts, TaskEval(tracking, e_y, success, off, completion)

    def drawing(self, ts) -> dict:
        p = ts["path"]
        xy = np.asarray(p.xy)
        starts, ends, centres = (np.asarray(ts[k]) for k in ("gate_start", "gate_end", "gate_centre"))
        widths = np.asarray(self.lane_widths)
        gates = [(float(a), float(b), float(c), float(w)) for a, b, c, w in zip(starts, ends, centres, widths)]
        finish = float(ts["finish"])
        ys = [c for _, _, c, _ in gates]
        return {"lines": [xy], "gates": gates, "finish": finish,
                "bounds": (-1.0, finish + 1.0, min(ys) - 1.2, max(ys) + 1.2)}
