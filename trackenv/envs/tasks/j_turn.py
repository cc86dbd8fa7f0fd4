"""J-turn (thesis Fig. 4.9 B, §5.3.2): straight run, turn through a heading change, stop."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import paths
from .base import (
    PATH_KERNEL_SCALES,
    PATH_PRIMARY_ERROR,
    RewardParams,
    Task,
    TaskEval,
    as_range,
    as_scalar,
    braking_speed,
    is_stopped,
    kernel,
    obs_bounds,
    reward_params,
    sample,
    split_task_kwargs,
)

_OBS = [
    ("speed_error", -5.0, 5.0),  # m/s, v_ref - u
    ("cross_track", -10.0, 10.0),  # m, > 0 left of the path
    ("heading_error", -math.pi, math.pi),  # rad, psi - psi_path (wrapped)
    ("yaw_rate_error", -30.0, 30.0),  # rad/s, v_ref kappa - r
    ("distance_to_go", -20.0, 20.0),  # m, path length left to the stop point
    ("heading_to_go", -math.pi, math.pi),  # rad, final heading - psi (wrapped)
    ("curvature", -5.0, 5.0),  # 1/m, path curvature at the closest point
    ("curvature_preview", -5.0, 5.0),  # 1/m, 0.5 m ahead
    ("phase_straight", 0.0, 1.0),
    ("phase_turn", 0.0, 1.0),
    ("phase_stop", 0.0, 1.0),
]

_DS = 0.025  # m, polyline spacing
_LEAD_IN = 1.0  # m of straight path behind the start
_RUN_OUT = 2.0  # m of straight path beyond the stop point
PREVIEW = 0.5  # m


class JTurn(Task):
    """J-turn: follow a straight line, then a circular arc through ``heading_change``, and stop at its end.

    Derived from the thesis's J-turn (Fig. 4.9 B, §5.3.2): straight at 1.1 m/s, then the left track is
    driven harder than the right (a right turn) during 2-3 s, then the torques are removed. With the
    reconstructed input (configs/field/j_turn_dry_sand.yaml: 11.8 V, then 16.8/6.8 V from 2.0 to 3.0 s)
    the base model starts turning 2.0 m down the line at about -1.85 rad/s and 1.08 m/s (radius
    ~0.58 m) and rests at -94 degrees, hence the defaults: 2.1 m straight, 0.6 m radius, -90 degrees.

    Reference path: straight ``straight_length`` along +X from the start, then an arc of radius
    ``turn_radius`` through ``heading_change`` (< 0: clockwise/right), ending at the stop point.
    Reference speed v_ref = min(v*, sqrt(2 a_b d)), d = distance left along the path; reference yaw
    rate r_ref = v_ref kappa(s).

    Task observation (prepended to the common part):

    ==================  ================  ==========================================
    speed_error         [-5, 5] m/s       v_ref - u
    cross_track         [-10, 10] m       signed distance to the path, > 0 left
    heading_error       [-pi, pi] rad     psi - psi_path (wrapped)
    yaw_rate_error      [-30, 30] rad/s   r_ref - r
    distance_to_go      [-20, 20] m       path length to the stop point (< 0: past it)
    heading_to_go       [-pi, pi] rad     final heading - psi (wrapped)
    curvature           [-5, 5] 1/m       at the closest path point
    curvature_preview   [-5, 5] 1/m       0.5 m further along the path
    phase_straight/turn/stop  one-hot     straight section / on the arc / braking for the stop
    ==================  ================  ==========================================

    Tracking reward: 0.4 k(e_v, 0.2 m/s) + 0.3 k(e_y, 0.15 m) + 0.2 k(e_psi, 0.25 rad)
    + 0.1 k(e_r, 0.5 rad/s); primary error (tracking RMSE): the cross-track error e_y.
    Termination: success when the CG is within ``end_tolerance`` of the stop point, the heading within
    ``heading_tolerance`` of the final heading and the vehicle at rest; off course when |e_y| >
    ``cross_track_limit``, |e_psi| > ``heading_error_limit`` or it runs ``overshoot_limit`` past the
    stop point. Completion: clip(s / path length, 0, 1).
    """

    name = "j_turn"
    env_name = "JTurn-v0"
    field_profile = "j_turn"
    kernel_scales = PATH_KERNEL_SCALES
    primary_error = PATH_PRIMARY_ERROR
    steering = "path"
    obs_names, obs_low, obs_high = obs_bounds(_OBS)

    @staticmethod
    def reference_speed(col, v_star, a_b):
        """v_ref = min(v*, sqrt(2 a_b max(d, 0))), d = distance_to_go along the path to the stop point."""
        return np.minimum(v_star, np.sqrt(2.0 * a_b * np.maximum(col("distance_to_go"), 0.0)))

    reward: RewardParams
    target_speed: jax.Array  # m/s (low, high)
    straight_length: jax.Array  # m (low, high)
    turn_radius: jax.Array  # m (low, high)
    heading_change: jax.Array  # rad (low, high), signed, < 0 right
    brake_decel: jax.Array  # m/s^2
    end_tolerance: jax.Array  # m
    heading_tolerance: jax.Array  # rad
    cross_track_limit: jax.Array  # m
    heading_error_limit: jax.Array  # rad
    overshoot_limit: jax.Array  # m
    n_path: int = eqx.field(static=True)

    DEFAULTS = dict(target_speed=1.1, straight_length=2.1, turn_radius=0.6, heading_change=-math.pi / 2,
                    brake_decel=3.0, end_tolerance=0.3, heading_tolerance=math.radians(15.0),
                    cross_track_limit=0.75, heading_error_limit=math.radians(60.0), overshoot_limit=1.0,
                    max_time=8.0, reward=None)

    @classmethod
    def create(cls, **kwargs):
        o = split_task_kwargs(cls.DEFAULTS, kwargs, "JTurn")
        straight = as_range("straight_length", o["straight_length"], 0.0, 20.0)
        radius = as_range("turn_radius", o["turn_radius"], 0.05, 20.0)
        change = as_range("heading_change", o["heading_change"], -2 * math.pi, 2 * math.pi, nonzero=True)
        longest = float(straight[1]) + float(radius[1]) * float(jnp.abs(change).max())
        n_path = int(math.ceil((_LEAD_IN + longest + _RUN_OUT) / _DS)) + 1
        task = cls(
            reward=o["reward"] if isinstance(o["reward"], RewardParams) else reward_params(**(o["reward"] or {})),
            target_speed=as_range("target_speed", o["target_speed"], 0.05, 2.5),
            straight_length=straight, turn_radius=radius, heading_change=change,
            brake_decel=as_scalar("brake_decel", o["brake_decel"], 1e-3),
            end_tolerance=as_scalar("end_tolerance", o["end_tolerance"], 0.0),
            heading_tolerance=as_scalar("heading_tolerance", o["heading_tolerance"], 0.0),
            cross_track_limit=as_scalar("cross_track_limit", o["cross_track_limit"], 0.0),
            heading_error_limit=as_scalar("heading_error_limit", o["heading_error_limit"], 0.0),
            overshoot_limit=as_scalar("overshoot_limit", o["overshoot_limit"], 0.0),
            n_path=n_path,
        )
        return task, float(o["max_time"])

    def init(self, key, sim) -> dict:
        k1, k2, k3, k4 = jax.random.split(key, 4)
        v = sample(k1, self.target_speed)
        straight = sample(k2, self.straight_length)
        radius = sample(k3, self.turn_radius)
        change = sample(k4, self.heading_change)
        arc = radius * jnp.abs(change)
        path = paths.from_curvature(jnp.stack([straight, arc]), jnp.stack([jnp.zeros_like(radius), jnp.sign(change) / radius]),
                                    _DS, self.n_path, -_LEAD_IN)
        return {"path": path, "target_speed": v, "straight": straight, "length": straight + arc, "final_heading": change}

    def _errors(self, ts, phys):
        proj = paths.project(ts["path"], phys.pose[:2])
        to_go = ts["length"] - proj.s
        v_ref = braking_speed(ts["target_speed"], to_go, self.brake_decel)
        e_psi = paths.wrap_angle(phys.pose[2] - proj.heading)
        r_ref = v_ref * proj.curvature
        return proj, to_go, v_ref, v_ref - phys.vel[0], e_psi, r_ref - phys.vel[2]

    def observe(self, ts, phys, sim):
        proj, to_go, v_ref, e_v, e_psi, e_r = self._errors(ts, phys)
        stop = v_ref < ts["target_speed"] - 1e-3
        turn = (~stop) & (proj.s >= ts["straight"])
        straight = (~stop) & (~turn)
        preview = paths.curvature_at(ts["path"], proj.s + PREVIEW)
        to_heading = paths.wrap_angle(ts["final_heading"] - phys.pose[2])
        f = lambda b: b.astype(jnp.float32)  # noqa: E731
        return jnp.stack([e_v, proj.cross_track, e_psi, e_r, to_go, to_heading, proj.curvature, preview,
                          f(straight), f(turn), f(stop)])

    def evaluate(self, ts, phys, sim):
        proj, to_go, _, e_v, e_psi, e_r = self._errors(ts, phys)
        e_y = proj.cross_track
        s = self.kernel_scales
        tracking = (0.4 * kernel(e_v, s["speed_error"]) + 0.3 * kernel(e_y, s["cross_track"])
                    + 0.2 * kernel(e_psi, s["heading_error"]) + 0.1 * kernel(e_r, s["yaw_rate_error"]))
        end = jnp.interp(ts["length"], ts["path"].s, ts["path"].xy[:, 0]), jnp.interp(ts["length"], ts["path"].s, ts["path"].xy[:, 1])
        dist_end = jnp.sqrt((phys.pose[0] - end[0]) ** 2 + (phys.pose[1] - end[1]) ** 2)
        heading_ok = jnp.abs(paths.wrap_angle(ts["final_heading"] - phys.pose[2])) <= self.heading_tolerance
        success = (dist_end <= self.end_tolerance) & heading_ok & is_stopped(phys, 0.05, 0.5)
        off = (jnp.abs(e_y) > self.cross_track_limit) | (jnp.abs(e_psi) > self.heading_error_limit) | (to_go < -self.overshoot_limit)
        completion = jnp.clip(proj.s / ts["length"], 0.0, 1.0)
        return ts, TaskEval(tracking, e_y, success, off, completion)

    def drawing(self, ts) -> dict:
        p = ts["path"]
        s = np.asarray(p.s)
        xy = np.asarray(p.xy)
        length = float(ts["length"])
        keep = (s >= 0.0) & (s <= length + 1e-6)
        end = (float(np.interp(length, s, xy[:, 0])), float(np.interp(length, s, xy[:, 1])))
        pts = xy[keep]
        lo = pts.min(axis=0) - 1.0
        hi = pts.max(axis=0) + 1.0
        return {"lines": [xy[keep]], "dashed": [xy], "marks": [end], "bounds": (lo[0], hi[0], lo[1], hi[1])}
