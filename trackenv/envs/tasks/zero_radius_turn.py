"""Zero-radius turn (thesis Fig. 4.9 D, §5.3.4): spin in place at a target yaw rate through a target angle."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from .base import (
    PrimaryError,
    RewardParams,
    Task,
    TaskEval,
    as_range,
    as_scalar,
    is_stopped,
    kernel,
    obs_bounds,
    reward_params,
    sample,
    split_task_kwargs,
)

_OBS = [
    ("yaw_rate_error", -30.0, 30.0),  # rad/s, r_ref - r
    ("angle_to_go", -100.0, 100.0),  # rad, target - turned (signed)
    ("target_yaw_rate", -15.0, 15.0),  # rad/s
    ("drift_x", -5.0, 5.0),  # m, CG displacement from the start, start frame
    ("drift_y", -5.0, 5.0),  # m
    ("braking_phase", 0.0, 1.0),  # 1 when the reference yaw rate brakes for the target angle
]


class ZeroRadiusTurn(Task):
    """Zero-radius turn: spin in place at ``target_yaw_rate`` through ``target_angle``, then stop.

    Derived from the thesis's zero-radius turn (Fig. 4.9 D, §5.3.4): equal and opposite voltages on the
    two motors. The reconstructed inputs (configs/field/zero_radius_turn_*.yaml, +12/-12 V, clockwise)
    spin the base model at -5.0 rad/s on dry sand and -6.1 rad/s on asphalt; the default target is a
    gentler -3 rad/s (clockwise, as the reconstruction) through one revolution.

    Reference: r_ref = sign * min(|r*|, sqrt(2 alpha_b max(sign * angle_to_go, 0))), sign = sign(r*),
    angle_to_go = sign * target_angle - (psi - psi_0).

    Task observation (prepended to the common part):

    ================  ===============  ==================================================
    yaw_rate_error    [-30, 30] rad/s  r_ref - r
    angle_to_go       [-100, 100] rad  signed yaw angle still to turn
    target_yaw_rate   [-15, 15] rad/s  r* of this episode (sign = direction)
    drift_x, drift_y  [-5, 5] m        CG displacement from the start in the start frame
    braking_phase     {0, 1}           1 when r_ref is braking for the target angle
    ================  ===============  ==================================================

    Tracking reward: 0.7 k(e_r, 0.5 rad/s) + 0.3 k(drift, 0.1 m); primary error: e_r.
    Termination: success when |angle_to_go| <= ``angle_tolerance``, |r| < 0.1 rad/s, the sprockets are
    at rest (< 0.5 rad/s) and the drift <= ``drift_tolerance``; off course when the drift exceeds
    ``drift_limit`` or the turn overshoots the target by more than ``overshoot_limit``.
    Completion: clip(turned / target_angle, 0, 1).
    """

    name = "zero_radius_turn"
    env_name = "ZeroRadiusTurn-v0"
    field_profile = "zero_radius_turn"
    kernel_scales = {"yaw_rate_error": 0.5, "drift": 0.1}  # rad/s, m
    primary_error = PrimaryError("yaw_rate_error", "rad/s", "yaw rate", kernel_scales["yaw_rate_error"])
    steering = "spin"
    obs_names, obs_low, obs_high = obs_bounds(_OBS)

    @staticmethod
    def reference_speed(col, v_star, a_b):
        """None: no speed loop (the mean voltage is 0 in a spin in place)."""
        return None

    reward: RewardParams
    target_yaw_rate: jax.Array  # rad/s (low, high), signed; must not include 0
    target_angle: jax.Array  # rad (low, high), magnitude
    brake_decel: jax.Array  # rad/s^2
    angle_tolerance: jax.Array  # rad
    drift_tolerance: jax.Array  # m
    drift_limit: jax.Array  # m
    overshoot_limit: jax.Array  # rad

    DEFAULTS = dict(target_yaw_rate=-3.0, target_angle=2 * math.pi, brake_decel=10.0,
                    angle_tolerance=math.radians(10.0), drift_tolerance=0.25, drift_limit=0.5,
                    overshoot_limit=math.radians(45.0), max_time=6.0, reward=None)

    @classmethod
    def create(cls, **kwargs):
        o = split_task_kwargs(cls.DEFAULTS, kwargs, "ZeroRadiusTurn")
        rate = as_range("target_yaw_rate", o["target_yaw_rate"], -12.0, 12.0, nonzero=True)
        task = cls(
            reward=o["reward"] if isinstance(o["reward"], RewardParams) else reward_params(**(o["reward"] or {})),
            target_yaw_rate=rate,
            target_angle=as_range("target_angle", o["target_angle"], 0.05, 60.0),
            brake_decel=as_scalar("brake_decel", o["brake_decel"], 1e-3),
            angle_tolerance=as_scalar("angle_tolerance", o["angle_tolerance"], 0.0),
            drift_tolerance=as_scalar("drift_tolerance", o["drift_tolerance"], 0.0),
            drift_limit=as_scalar("drift_limit", o["drift_limit"], 0.0),
            overshoot_limit=as_scalar("overshoot_limit", o["overshoot_limit"], 0.0),
        )
        return task, float(o["max_time"])

    def init(self, key, sim) -> dict:
        k1, k2 = jax.random.split(key)
        rate = sample(k1, self.target_yaw_rate)
        return {"target_yaw_rate": rate, "target_angle": sample(k2, self.target_angle) * jnp.sign(rate)}

    def _errors(self, ts, phys):
        sign = jnp.sign(ts["target_yaw_rate"])
        to_go = ts["target_angle"] - phys.pose[2]  # the episode starts at psi = 0
        mag = jnp.minimum(jnp.abs(ts["target_yaw_rate"]), jnp.sqrt(2.0 * self.brake_decel * jnp.maximum(sign * to_go, 0.0)))
        r_ref = sign * mag
        return sign, to_go, r_ref, r_ref - phys.vel[2]

    def observe(self, ts, phys, sim):
        _, to_go, r_ref, e_r = self._errors(ts, phys)
        braking = (jnp.abs(r_ref) < jnp.abs(ts["target_yaw_rate"]) - 1e-3).astype(jnp.float32)
        return jnp.stack([e_r, to_go, ts["target_yaw_rate"], phys.pose[0], phys.pose[1], braking])

    def evaluate(self, ts, phys, sim):
        sign, to_go, _, e_r = self._errors(ts, phys)
        drift = jnp.sqrt(phys.pose[0] ** 2 + phys.pose[1] ** 2)
        tracking = 0.7 * kernel(e_r, self.kernel_scales["yaw_rate_error"]) + 0.3 * kernel(drift, self.kernel_scales["drift"])
        success = ((jnp.abs(to_go) <= self.angle_tolerance) & (jnp.abs(phys.vel[2]) < 0.1)
                   & is_stopped(phys, 0.05, 0.5) & (drift <= self.drift_tolerance))
        off = (drift > self.drift_limit) | (sign * to_go < -self.overshoot_limit)
        completion = jnp.clip(phys.pose[2] / ts["target_angle"], 0.0, 1.0)
        return ts, TaskEval(tracking, e_r, success, off, completion)

    def drawing(self, ts) -> dict:
        ang = float(ts["target_angle"])
        return {"arrows": [(0.0, 0.0, ang)], "bounds": (-1.0, 1.0, -1.0, 1.0), "target_angle": ang}
