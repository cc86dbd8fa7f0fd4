"""Go-stop (thesis Fig. 4.9 A, §5.3.1): reach and hold a target speed, then stop at a mark."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..paths import wrap_angle
from .base import (
    PrimaryError,
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
    ("distance_to_mark", -20.0, 20.0),  # m, x_mark - x
    ("cross_track", -5.0, 5.0),  # m, y (> 0: left of the line)
    ("heading_error", -math.pi, math.pi),  # rad, psi wrapped
    ("target_speed", 0.0, 3.0),  # m/s
    ("braking_phase", 0.0, 1.0),  # 1 once the reference speed brakes for the mark
]


class GoStop(Task):
    """Go-stop: drive straight along +X at ``target_speed`` and stop with the CG on the mark.

    Derived from the thesis's go-stop (Fig. 4.9 A, §5.3.1): the vehicle accelerates along a straight
    line to a steady speed (1.1 m/s in the thesis's tests, §5.4.1), then the torques are removed and it
    brakes to a stop. With the reconstructed thesis input (configs/field/go_stop_dry_sand.yaml: 11.8 V
    on both motors, released at 3.0 s) the base model stops 3.23 m down the line on dry sand, hence the
    default mark at 3.2 m.

    Reference: v_ref(d) = min(v*, sqrt(2 a_b max(d, 0))), d = x_mark - x (hold v*, then brake at a_b).

    Task observation (prepended to the common part, see :mod:`trackenv.envs.core`):

    ======================  ===============  ============================================
    speed_error             [-5, 5] m/s      v_ref - u (u: forward speed of the CG)
    distance_to_mark        [-20, 20] m      x_mark - x
    cross_track             [-5, 5] m        y, > 0 left of the line
    heading_error           [-pi, pi] rad    psi (wrapped)
    target_speed            [0, 3] m/s       v* of this episode
    braking_phase           {0, 1}           1 when v_ref < v* (approaching the mark)
    ======================  ===============  ============================================

    Tracking reward (in [0, 1]): 0.6 k(e_v, 0.2 m/s) + 0.2 k(y, 0.2 m) + 0.2 k(psi, 0.2 rad),
    k(e, s) = exp(-(e/s)^2); plus the common energy/smoothness/success/failure terms
    (:class:`~trackenv.envs.tasks.base.RewardParams`). Primary error (tracking RMSE): e_v.

    Termination: success when |x_mark - x| <= ``stop_tolerance`` and the vehicle is at rest
    (|u|, |v| < 0.05 m/s, |omega| < 0.5 rad/s); off course when |y| > ``lateral_limit``,
    |psi| > ``heading_limit``, it passes the mark by more than ``overshoot_limit`` or backs up
    0.5 m behind the start. Completion: clip(x / x_mark, 0, 1).
    """

    name = "go_stop"
    env_name = "GoStop-v0"
    field_profile = "go_stop"
    kernel_scales = {"speed_error": 0.2, "cross_track": 0.2, "heading_error": 0.2}  # m/s, m, rad
    primary_error = PrimaryError("speed_error", "m/s", "speed", kernel_scales["speed_error"])
    steering = "heading"
    obs_names, obs_low, obs_high = obs_bounds(_OBS)

    reward: RewardParams
    target_speed: jax.Array  # m/s, (low, high)
    mark_distance: jax.Array  # m, (low, high)
    brake_decel: jax.Array  # m/s^2
    stop_tolerance: jax.Array  # m
    lateral_limit: jax.Array  # m
    heading_limit: jax.Array  # rad
    overshoot_limit: jax.Array  # m

    DEFAULTS = dict(target_speed=1.1, mark_distance=3.2, brake_decel=3.0, stop_tolerance=0.15,
                    lateral_limit=0.5, heading_limit=math.radians(45.0), overshoot_limit=0.5, max_time=8.0,
                    reward=None)

    @classmethod
    def create(cls, **kwargs) -> tuple[GoStop, float]:
        o = split_task_kwargs(cls.DEFAULTS, kwargs, "GoStop")
        task = cls(
            reward=o["reward"] if isinstance(o["reward"], RewardParams) else reward_params(**(o["reward"] or {})),
            target_speed=as_range("target_speed", o["target_speed"], 0.05, 2.5),
            mark_distance=as_range("mark_distance", o["mark_distance"], 0.1, 15.0),
            brake_decel=as_scalar("brake_decel", o["brake_decel"], 1e-3),
            stop_tolerance=as_scalar("stop_tolerance", o["stop_tolerance"], 0.0),
            lateral_limit=as_scalar("lateral_limit", o["lateral_limit"], 0.0),
            heading_limit=as_scalar("heading_limit", o["heading_limit"], 0.0),
            overshoot_limit=as_scalar("overshoot_limit", o["overshoot_limit"], 0.0),
        )
        return task, float(o["max_time"])

    @staticmethod
    def reference_speed(col, v_star, a_b):
        """v_ref = min(v*, sqrt(2 a_b max(d, 0))) with v* and d = distance_to_mark read from the observation
        (``v_star`` is not used: the episode's target speed is observed)."""
        return np.minimum(col("target_speed"), np.sqrt(2.0 * a_b * np.maximum(col("distance_to_mark"), 0.0)))

    @staticmethod
    def reference_yaw_rate(col):
        """0: a straight line."""
        return 0.0

    def init(self, key, sim) -> dict:
        k1, k2 = jax.random.split(key)
        return {"target_speed": sample(k1, self.target_speed), "mark": sample(k2, self.mark_distance)}

    def _errors(self, ts, phys):
        x, y, psi = phys.pose[0], phys.pose[1], wrap_angle(phys.pose[2])
        dist = ts["mark"] - x
        v_ref = braking_speed(ts["target_speed"], dist, self.brake_decel)
        return x, y, psi, dist, v_ref, v_ref - phys.vel[0]

    def observe(self, ts, phys, sim):
        _, y, psi, dist, v_ref, e_v = self._errors(ts, phys)
        braking = (v_ref < ts["target_speed"] - 1e-3).astype(jnp.float32)
        return jnp.stack([e_v, dist, y, psi, ts["target_speed"], braking])

    def evaluate(self, ts, phys, sim):
        x, y, psi, dist, _, e_v = self._errors(ts, phys)
        s = self.kernel_scales
        tracking = (0.6 * kernel(e_v, s["speed_error"]) + 0.2 * kernel(y, s["cross_track"])
                    + 0.2 * kernel(psi, s["heading_error"]))
        success = (jnp.abs(dist) <= self.stop_tolerance) & is_stopped(phys, 0.05, 0.5)
        off = (jnp.abs(y) > self.lateral_limit) | (jnp.abs(psi) > self.heading_limit) | (dist < -self.overshoot_limit) | (x < -0.5)
        completion = jnp.clip(x / ts["mark"], 0.0, 1.0)
        return ts, TaskEval(tracking, e_v, success, off, completion)

    def drawing(self, ts) -> dict:
        mark = float(ts["mark"])
        return {"lines": [np.array([[-0.5, 0.0], [mark + 1.0, 0.0]])], "marks": [(mark, 0.0)],
                "bounds": (-1.0, mark + 1.5, -1.2, 1.2)}
