"""Small environment wrappers of the driver jobs, one concern each (in the style of Brax's training wrappers).

Stable-Baselines3 ``VecEnvWrapper`` s around :class:`~trackenv.envs.vector.SB3VecEnv` (whose
same-step autoreset is the jitted core's, :func:`trackenv.envs.core.step_autoreset`):

- :class:`StepTimer`: wall time spent stepping and resetting the environment [s];
- :class:`ResidualVecEnv`: the applied action is the PI controller's (times a weight, which
  :class:`GuideSchedule` lowers to 0 for a plain driver's curriculum) plus a scaled policy action;
- :class:`ErrorPenalty`: training reward shaping on the task's primary tracking error;
- :class:`ActionRatePenalty`: training reward shaping against a command that chatters.

For evaluation, :class:`EpisodeRecorder` wraps a :class:`~trackenv.envs.vector.TrackVectorEnv` without
autoreset and keeps each environment's trace and final metrics up to its first end (the episode
statistics).
"""

from __future__ import annotations

import math
import time

import numpy as np

try:
    from stable_baselines3.common.vec_env import VecEnvWrapper as _VecEnvWrapper
except ImportError:  # pragma: no cover - SB3 is a dependency, but keep the module importable
    _VecEnvWrapper = object


class StepTimer(_VecEnvWrapper):
    """Accumulates the wall time spent in the wrapped env's ``step_wait`` and ``reset`` [s]."""

    def __init__(self, venv):
        super().__init__(venv)
        self.step_seconds = 0.0
        self.reset_seconds = 0.0
        self.steps = 0

    def reset(self):
        t0 = time.perf_counter()
        obs = self.venv.reset()
        self.reset_seconds += time.perf_counter() - t0
        return obs

    def step_async(self, actions):
        self.venv.step_async(actions)

    def step_wait(self):
        t0 = time.perf_counter()
        out = self.venv.step_wait()
        self.step_seconds += time.perf_counter() - t0
        self.steps += self.num_envs
        return out


class ResidualVecEnv(_VecEnvWrapper):
    """Residual driver: applied action = clip(w * classical(obs) + scale * policy action, -1, 1) (units of the
    vehicle's voltage limit), ``w`` = ``classical_weight`` (1 for a residual driver; a plain driver's
    guided curriculum lowers it from 1 to 0, :class:`GuideSchedule`).

    The classical PI controller (:class:`trackenv.envs.controllers.ClassicalController`) runs on the same
    observations, one integrator per environment, reset when an episode ends. With ``release_column`` (the
    index of a 0/1 observation, the J-turn's ``phase_stop``), ``w`` is 0 in the environments where that
    observation is 1: a guided plain policy brakes for the stop on its own from the start of training.
    """

    def __init__(self, venv, scale: float, gains: dict, classical_weight: float = 1.0,
                 release_column: int | None = None):
        super().__init__(venv)
        from ..envs.controllers import classical_for  # noqa: PLC0415

        base = venv
        while not hasattr(base, "venv") or not hasattr(base.venv, "params"):
            base = base.venv
        self.params = base.venv.params
        self.scale = float(scale)
        self.ctrl = classical_for(self.params, gains)
        self.classical_weight = float(classical_weight)
        self.release_column = release_column
        self._obs = None

    def reset(self):
        self._obs = self.venv.reset()
        self.ctrl.reset()
        return self._obs

    def step_async(self, actions):
        self.last_classical = self.ctrl(self._obs)
        w = np.full((len(self._obs), 1), self.classical_weight, np.float32)
        if self.release_column is not None:
            w = w * (1.0 - self._obs[:, self.release_column, None])
        self.last_weight = w[:, 0]  # the classical part's weight in each environment at this step
        a = w * self.last_classical + self.scale * np.asarray(actions, np.float32)
        self.venv.step_async(np.clip(a, -1.0, 1.0).astype(np.float32))

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        if dones.any():
            self.ctrl.reset_rows(dones)
        self._obs = obs
        return obs, rew, dones, infos


class GuideSchedule:
    """A plain driver's guided curriculum: the classical controller's weight in a :class:`ResidualVecEnv`
    (policy scale 1) falls linearly from 1 at step 0 to 0 at ``guide_steps``, and stays 0 after.

    Early episodes then run close to the PI controller's, so the policy sees stops and successes from the
    start, and it takes the whole action over gradually; the saved policy acts alone (plain). Called with
    the number of environment steps trained so far (SB3's ``num_timesteps``; a resumed run continues).
    """

    def __init__(self, env: ResidualVecEnv, guide_steps: int):
        self.env, self.guide_steps = env, int(guide_steps)

    def weight(self, steps: int) -> float:
        return max(0.0, 1.0 - float(steps) / self.guide_steps) if self.guide_steps > 0 else 0.0

    def __call__(self, steps: int) -> float:
        self.env.classical_weight = self.weight(steps)
        return self.env.classical_weight


class ErrorPenalty(_VecEnvWrapper):
    """Training reward shaping: r - weight * (e / scale)^2, e = observation column ``index`` after the step
    (the terminal observation on the step an episode ends)."""

    def __init__(self, venv, index: int, scale: float, weight: float):
        super().__init__(venv)
        self.index, self.scale, self.weight = int(index), float(scale), float(weight)

    def reset(self):
        return self.venv.reset()

    def step_async(self, actions):
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        e = obs[:, self.index].astype(np.float64).copy()
        for i in np.flatnonzero(dones):
            term = infos[i].get("terminal_observation")
            if term is not None:
                e[i] = float(term[self.index])
        return obs, (rew - self.weight * np.square(e / self.scale)).astype(np.float32), dones, infos


class ActionRatePenalty(_VecEnvWrapper):
    """Training reward shaping against a chattering command: r - weight * mean_k (a_k - a_k,prev)^2, with a the
    policy's action (normalised: units of the voltage limit, both motors) and a_prev the one before it in the
    same episode; an episode's first step is not penalised. For a plain driver whose guide has faded, a is
    the applied voltage over the limit: the penalty prices the evaluation's ``voltage_step_rms``."""

    def __init__(self, venv, weight: float):
        super().__init__(venv)
        self.weight = float(weight)
        self._prev = np.zeros((self.num_envs, int(np.prod(self.action_space.shape))))
        self._first = np.ones(self.num_envs, bool)
        self._actions = self._prev

    def reset(self):
        self._first[:] = True
        return self.venv.reset()

    def step_async(self, actions):
        self._actions = np.clip(np.asarray(actions, np.float64).reshape(self.num_envs, -1), -1.0, 1.0)
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        rate = np.where(self._first, 0.0, np.mean(np.square(self._actions - self._prev), axis=1))
        self._prev, self._first = self._actions, np.asarray(dones, bool).copy()
        return obs, (rew - self.weight * rate).astype(np.float32), dones, infos


FINAL_KEYS = ("success", "off_course", "diverged", "timeout", "time", "tracking_rmse", "energy", "episode_return",
              "completion")


class EpisodeRecorder:
    """One episode per environment of a ``TrackVectorEnv`` (``autoreset_mode="disabled"``, ``info_state=True``):
    records each environment's trace and final metrics until its first end (terminated or truncated).

    ``reset(seeds)`` -> observation; ``step(actions)`` -> observation (actions normalised, (N, 2));
    ``done`` (bool (N,)) marks the environments that have ended; :meth:`episodes` returns one dict per
    environment: the flags, ``tracking_rmse``, ``completion_time`` [s] (NaN unless it succeeded),
    ``energy`` [J], ``peak_current`` [A], ``voltage_step_rms`` [V], ``episode_return``, ``completion``,
    ``time`` [s], the
    ``trace`` (``t`` [s], ``v_left``/``v_right`` [V], ``i_left``/``i_right`` [A], ``x``/``y`` [m],
    ``heading`` [rad], ``u`` [m/s], ``yaw_rate`` [rad/s], ``speed_ideal`` [m/s]), the task's
    ``drawing`` and the randomised ``params`` when domain randomisation is on.
    """

    def __init__(self, venv):
        self.venv = venv
        self.n = venv.num_envs
        self.vlim = venv.params.voltage_limit
        self.r_s = float(venv.params.sim.vehicle.sprocket_radius)
        self.dt = venv.params.control_dt

    def reset(self, seeds) -> np.ndarray:
        self.seeds = [int(s) for s in seeds]
        obs, info = self.venv.reset(seed=self.seeds)
        st = info["state"]
        self.traces = [{"t": [0.0], "v": [], "i": [st["current"][k].copy()], "pose": [st["pose"][k].copy()],
                        "vel": [st["vel"][k].copy()], "omega": [st["omega"][k].copy()]} for k in range(self.n)]
        self.drawings = _drawings(self.venv)
        self.done = np.zeros(self.n, bool)
        self.final: list[dict | None] = [None] * self.n
        self.steps = 0
        self.info = info
        return obs

    def step(self, actions: np.ndarray) -> np.ndarray:
        obs, _, term, trunc, info = self.venv.step(actions)
        self.steps += 1
        st = info["state"]
        volts = np.clip(actions, -1.0, 1.0) * self.vlim
        for k in np.flatnonzero(~self.done):
            tr = self.traces[k]
            tr["v"].append(volts[k].astype(np.float64))
            tr["t"].append(self.steps * self.dt)
            tr["i"].append(st["current"][k].copy())
            tr["pose"].append(st["pose"][k].copy())
            tr["vel"].append(st["vel"][k].copy())
            tr["omega"].append(st["omega"][k].copy())
            if term[k] or trunc[k]:
                self.done[k] = True
                self.final[k] = {m: info[m][k] for m in FINAL_KEYS}
        self.info = info
        return obs

    def episodes(self) -> list[dict]:
        info = self.info
        out = []
        for k in range(self.n):
            tr = self.traces[k]
            f = self.final[k] or {m: info[m][k] for m in FINAL_KEYS}
            v = np.asarray(tr["v"]).reshape(-1, 2)
            # RMS change of the commanded voltages from one control step to the next, both motors
            dv = np.diff(v, axis=0)
            voltage_step_rms = float(np.sqrt(np.mean(np.square(dv)))) if dv.size else 0.0
            v = np.vstack([v, v[-1:] if len(v) else np.zeros((1, 2))])  # hold the last action on the last sample
            i = np.asarray(tr["i"])
            omega = np.asarray(tr["omega"])
            pose, vel = np.asarray(tr["pose"]), np.asarray(tr["vel"])
            ep = {
                "seed": self.seeds[k],
                "success": bool(f["success"]), "off_course": bool(f["off_course"]), "diverged": bool(f["diverged"]),
                "timeout": bool(f["timeout"]),
                "tracking_rmse": float(f["tracking_rmse"]),
                "completion_time": float(f["time"]) if bool(f["success"]) else math.nan,
                "energy": float(f["energy"]), "peak_current": float(np.max(np.abs(i))),
                "voltage_step_rms": voltage_step_rms,
                "episode_return": float(f["episode_return"]), "completion": float(f["completion"]),
                "time": float(f["time"]),
                "trace": {"t": np.asarray(tr["t"]), "v_left": v[:, 0], "v_right": v[:, 1], "i_left": i[:, 0],
                          "i_right": i[:, 1], "x": pose[:, 0], "y": pose[:, 1], "heading": pose[:, 2],
                          "u": vel[:, 0], "yaw_rate": vel[:, 2],
                          "speed_ideal": self.r_s * 0.5 * (omega[:, 0] + omega[:, 1])},
                "drawing": self.drawings[k] if self.drawings else None,
            }
            if "params" in info:
                ep["params"] = {p: float(vals[k]) for p, vals in info["params"].items()}
            out.append(ep)
        return out


def _drawings(venv):
    import jax  # noqa: PLC0415

    try:
        state = venv.state
        return [venv.params.task.drawing(jax.tree.map(lambda x, k=k: x[k], state.task)) for k in range(venv.num_envs)]
    except Exception:  # noqa: BLE001 - drawings only decorate the figures
        return None
