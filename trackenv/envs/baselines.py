"""Scripted baseline drivers for the four tasks (observation in, voltages out; numpy).

They read only the observation (by name, see ``env.unwrapped.obs_names``), i.e. what a driver on
the vehicle could know, and serve as sanity baselines for the rewards and terminations and as
references for learned policies::

    env = gym.make("trackenv/JTurn-v0")
    driver = baselines.make_driver(env)
    obs, _ = env.reset(seed=0)
    while True:
        obs, r, term, trunc, info = env.step(driver(obs))
        if term or trunc: break

The gains come from the thesis's voltage levels: 11.8 V cruise for 1.1 m/s (r_s/alpha = 0.099,
§5.4.1) and a 10 V left-right difference for about 1.9-2.3 rad/s at 1.1 m/s (the J-turn), so about
10.7 V per m/s and 5 V per rad/s of yaw rate while driving, and 4.8 V of difference per rad/s in a
zero-radius turn (+-12 V spin at 5-6 rad/s).
"""

from __future__ import annotations

import math

import numpy as np

V_PER_MPS = 11.8 / 1.1  # V per m/s of forward speed (feed-forward)
V_PER_RADPS = 5.0  # V of right-left difference per rad/s of yaw rate while driving
V_PER_RADPS_SPIN = 4.8  # V of right-left difference per rad/s in a zero-radius turn
V_MAX = 24.0


class Driver:
    """Base: maps an observation vector to [V_left, V_right] using the observation names."""

    def __init__(self, obs_names, normalize_action: bool = False, voltage_limit: float = V_MAX):
        self.idx = {n: i for i, n in enumerate(obs_names)}
        self.scale = 1.0 / voltage_limit if normalize_action else 1.0
        self.vmax = voltage_limit

    def o(self, obs, name):
        return float(obs[self.idx[name]])

    def mix(self, mean, diff):
        """Left/right voltages from a mean and a right-minus-left difference (> 0 turns left)."""
        v = np.array([mean - 0.5 * diff, mean + 0.5 * diff], np.float32)
        return (np.clip(v, -self.vmax, self.vmax) * self.scale).astype(np.float32)

    def speed_voltage(self, v_ref, speed_error):
        return V_PER_MPS * v_ref + 4.0 * speed_error

    def __call__(self, obs):  # pragma: no cover - interface
        raise NotImplementedError


class GoStopDriver(Driver):
    """Speed feed-forward + proportional speed feedback; heading and lateral correction."""

    def __call__(self, obs):
        v_ref = min(self.o(obs, "target_speed"), math.sqrt(2.0 * 3.0 * max(self.o(obs, "distance_to_mark"), 0.0)))
        mean = self.speed_voltage(v_ref, self.o(obs, "speed_error"))
        diff = -8.0 * self.o(obs, "heading_error") - 8.0 * self.o(obs, "cross_track")
        return self.mix(mean, diff)


class PathDriver(Driver):
    """Path follower (J-turn, lane change): speed loop plus a yaw-rate loop on a path-error command."""

    def reference_speed(self, obs):
        v_star = 1.1
        if "distance_to_go" in self.idx:
            return min(v_star, math.sqrt(2.0 * 3.0 * max(self.o(obs, "distance_to_go"), 0.0)))
        return v_star

    def __call__(self, obs):
        v_ref = self.reference_speed(obs)
        mean = self.speed_voltage(v_ref, self.o(obs, "speed_error"))
        r = self.o(obs, "yaw_rate")
        r_ff = self.o(obs, "yaw_rate_error") + r  # v_ref * kappa
        r_cmd = r_ff - 2.0 * self.o(obs, "heading_error") - 3.0 * self.o(obs, "cross_track")
        diff = V_PER_RADPS * r_cmd + 3.0 * (r_cmd - r)
        return self.mix(mean, diff)


class ZeroRadiusTurnDriver(Driver):
    """Yaw-rate feed-forward + feedback, equal and opposite voltages."""

    def __call__(self, obs):
        r = self.o(obs, "yaw_rate")
        r_ref = self.o(obs, "yaw_rate_error") + r
        diff = V_PER_RADPS_SPIN * r_ref + 3.0 * (r_ref - r)
        return self.mix(0.0, diff)


DRIVERS = {"go_stop": GoStopDriver, "j_turn": PathDriver, "lane_change": PathDriver,
           "zero_radius_turn": ZeroRadiusTurnDriver}


def make_driver(env) -> Driver:
    """The scripted driver for a ``TrackEnv`` (or a wrapper of one) or a ``TrackVectorEnv`` (per row)."""
    u = getattr(env, "unwrapped", env)
    params = u.params
    return DRIVERS[params.task.name](params.obs_names, params.normalize_action, params.voltage_limit)
