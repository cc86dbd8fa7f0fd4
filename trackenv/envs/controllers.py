"""Controllers of the tasks (observation in, voltages out; numpy): scripted, PI and open loop.

- :class:`ScriptedDriver`: a proportional driver for one environment (``make_driver(env)``), the
  sanity baseline of the rewards and terminations;
- :class:`ClassicalController`: the PI controller on speed and yaw rate, vectorised over N
  environments, the ``classical`` method of evaluation and the base of residual drivers;
- :class:`OpenLoop`: the reconstructed thesis voltage profile of the maneuver played as actions.

The controllers read the observation by name only (``env.unwrapped.obs_names``), i.e. what a
driver on the vehicle could know, and take each task's reference laws and steering mode from its
class (:class:`~trackenv.envs.tasks.base.Task`: ``reference_speed``, ``reference_yaw_rate``,
``steering``). The voltage limit is the vehicle's (``EnvParams.voltage_limit``,
configs/vehicle)::

    env = gym.make("trackenv/JTurn-v0")
    driver = controllers.make_driver(env)
    obs, _ = env.reset(seed=0)
    while True:
        obs, r, term, trunc, info = env.step(driver(obs))
        if term or trunc: break

Feed-forward: the thesis's voltage levels (§5.4.1) rather than the vehicle's back-emf gain. 11.8 V
holds the 1.1 m/s cruise (r_s/alpha = 0.099), i.e. 10.7 V per m/s, where the back-emf alone,
alpha_v / r_s = 10.1 V per m/s, leaves out the R_m i drop of the rolling resistance; a 10 V
left-right difference gives about 1.9-2.3 rad/s at 1.1 m/s (the J-turn), about 5 V per rad/s of
yaw rate while driving; +-12 V spin the vehicle in place at 5-6 rad/s, 4.8 V of difference per rad/s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..params import CONFIG_DIR, ConfigError
from .tasks import task_class

CRUISE_VOLTAGE = 11.8  # V on both motors for the thesis's cruise (§5.4.1)
CRUISE_SPEED = 1.1  # m/s, the thesis's cruise speed (§5.4.1); the controllers' v* when a task has none
BRAKE_DECEL = 3.0  # m/s^2, braking deceleration of the reference speed when a task has none
FF_SPEED = CRUISE_VOLTAGE / CRUISE_SPEED  # V per m/s of forward speed
FF_YAW = 5.0  # V of right-left difference per rad/s of yaw rate while driving
FF_SPIN = 4.8  # V of right-left difference per rad/s of yaw rate spinning in place
K_HEADING = 2.0  # rad/s of yaw-rate command per rad of heading error (outer path loop)
K_CROSS = 3.0  # rad/s of yaw-rate command per m of cross-track error (outer path loop)
K_HOLD_HEADING = 8.0  # V of right-left difference per rad of heading error (scripted straight-line hold)
K_HOLD_LATERAL = 8.0  # V of right-left difference per m of lateral offset (scripted straight-line hold)
I_LIMIT = 6.0  # V, anti-windup clamp of each integral term of the PI controller

DEFAULT_GAINS = {"kp_speed": 4.0, "ki_speed": 4.0, "kp_yaw": 3.0, "ki_yaw": 3.0}  # V/(m/s), V/m, V/(rad/s), V/rad
GAIN_GRID = {"kp_speed": (2.0, 5.0, 10.0, 20.0), "ki_speed": (0.0, 5.0, 20.0),
             "kp_yaw": (1.0, 3.0, 6.0), "ki_yaw": (0.0, 3.0, 10.0)}
GAINS_FILE = CONFIG_DIR / "train" / "classical_gains.yaml"  # the tuned PI gains per task x terrain


# ----------------------------------------------------------------------------------------------
# scripted driver (one environment)


class ScriptedDriver:
    """Proportional driver for one environment: speed feed-forward and feedback, and the task's steering.

    mean = FF_SPEED v_ref + kp_speed e_v, with v_ref the task's reference speed (v* = CRUISE_SPEED,
    a_b = BRAKE_DECEL; go-stop reads v* from the observation), and by the task's ``steering``:

    - ``heading``: diff = -K_HOLD_HEADING e_psi - K_HOLD_LATERAL e_y (hold the line);
    - ``path``: r_cmd = r_ref - K_HEADING e_psi - K_CROSS e_y, diff = FF_YAW r_cmd + kp_yaw (r_cmd - r);
    - ``spin``: mean = 0, diff = FF_SPIN r_ref + kp_yaw (r_ref - r);

    V_l, V_r = mean -+ diff / 2, clipped to the voltage limit (kp_speed, kp_yaw: the PI's defaults).
    """

    def __init__(self, task, obs_names, normalize_action: bool, voltage_limit: float):
        self.task = task_class(task)
        self.idx = {n: i for i, n in enumerate(obs_names)}
        self.scale = 1.0 / voltage_limit if normalize_action else 1.0
        self.vmax = voltage_limit

    def o(self, obs, name):
        return float(obs[self.idx[name]])

    def mix(self, mean, diff):
        """Left/right voltages from a mean and a right-minus-left difference (> 0 turns left)."""
        v = np.array([mean - 0.5 * diff, mean + 0.5 * diff], np.float32)
        return (np.clip(v, -self.vmax, self.vmax) * self.scale).astype(np.float32)

    def __call__(self, obs):
        col = lambda name: self.o(obs, name)  # noqa: E731
        r = col("yaw_rate")
        if self.task.steering == "spin":
            r_ref = self.task.reference_yaw_rate(col)
            return self.mix(0.0, FF_SPIN * r_ref + DEFAULT_GAINS["kp_yaw"] * (r_ref - r))
        v_ref = self.task.reference_speed(col, CRUISE_SPEED, BRAKE_DECEL)
        mean = FF_SPEED * v_ref + DEFAULT_GAINS["kp_speed"] * col("speed_error")
        if self.task.steering == "heading":
            return self.mix(mean, -K_HOLD_HEADING * col("heading_error") - K_HOLD_LATERAL * col("cross_track"))
        r_cmd = self.task.reference_yaw_rate(col) - K_HEADING * col("heading_error") - K_CROSS * col("cross_track")
        return self.mix(mean, FF_YAW * r_cmd + DEFAULT_GAINS["kp_yaw"] * (r_cmd - r))


def make_driver(env) -> ScriptedDriver:
    """The scripted driver for a ``TrackEnv`` (or a wrapper of one) or a ``TrackVectorEnv`` (per row)."""
    params = getattr(env, "unwrapped", env).params
    return ScriptedDriver(type(params.task), params.obs_names, params.normalize_action, params.voltage_limit)


# ----------------------------------------------------------------------------------------------
# PI controller (N environments)


class ClassicalController:
    """PI on forward speed and yaw rate, mapped to the mean and the right-left difference of the voltages.

    Vectorised over N environments (rows of the observation); reads the observation by name only::

        v_ref  = the task's reference speed (Task.reference_speed, with v*, a_b of the task)
        mean   = FF_SPEED v_ref + kp_speed e_v + ki_speed int e_v dt
        r_cmd  = r_ref - K_HEADING e_psi - K_CROSS e_y          (r_ref: Task.reference_yaw_rate)
        diff   = FF_YAW r_cmd + kp_yaw (r_cmd - r) + ki_yaw int (r_cmd - r) dt
        V_l, V_r = mean -+ diff / 2, clipped to +-voltage_limit

    A task steering ``spin`` (zero-radius turn) has mean 0, r_cmd = r_ref and FF_SPIN. The integrals
    are clamped to +-I_LIMIT volts (anti-windup) and reset by :meth:`reset`. ``gains`` are scalars or
    (N,) arrays (one gain set per environment, used by the tuning grid search). ``voltage_limit`` [V]
    is the vehicle's; ``normalize_action`` scales the output to units of it.
    """

    def __init__(self, task, obs_names, gains: dict | None = None, *, voltage_limit: float, control_dt: float = 0.05,
                 normalize_action: bool = True, target_speed: float = CRUISE_SPEED, brake_decel: float = BRAKE_DECEL):
        self.task = task_class(task)
        self.v_star = float(target_speed)
        self.a_b = float(brake_decel)
        self.idx = {n: i for i, n in enumerate(obs_names)}
        g = {**DEFAULT_GAINS, **(gains or {})}
        unknown = set(g) - set(DEFAULT_GAINS)
        if unknown:
            raise ConfigError(f"classical gains: unknown key(s) {sorted(unknown)}; known: {sorted(DEFAULT_GAINS)}")
        self.g = {k: np.asarray(v, np.float64) for k, v in g.items()}
        self.dt = float(control_dt)
        self.vmax = float(voltage_limit)
        self.scale = 1.0 / self.vmax if normalize_action else 1.0
        self.i_v = self.i_r = 0.0

    def reset(self):
        self.i_v = self.i_r = 0.0

    def reset_rows(self, rows):
        """Reset the integrators of the environments where ``rows`` (bool (N,)) is True."""
        rows = np.asarray(rows, bool)
        self.i_v = np.where(rows, 0.0, np.broadcast_to(self.i_v, rows.shape))
        self.i_r = np.where(rows, 0.0, np.broadcast_to(self.i_r, rows.shape))

    def col(self, obs, name):
        return obs[:, self.idx[name]].astype(np.float64)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        obs = np.atleast_2d(obs)
        g = self.g
        col = lambda name: self.col(obs, name)  # noqa: E731
        r = col("yaw_rate")
        if self.task.steering == "spin":
            mean = np.zeros(obs.shape[0])
            r_cmd = self.task.reference_yaw_rate(col)
            ff = FF_SPIN
        else:
            e_v = col("speed_error")
            v_ref = self.task.reference_speed(col, self.v_star, self.a_b)
            self.i_v = np.clip(self.i_v + g["ki_speed"] * e_v * self.dt, -I_LIMIT, I_LIMIT)
            mean = FF_SPEED * v_ref + g["kp_speed"] * e_v + self.i_v
            r_cmd = self.task.reference_yaw_rate(col) - K_HEADING * col("heading_error") - K_CROSS * col("cross_track")
            ff = FF_YAW
        e_r = r_cmd - r
        self.i_r = np.clip(self.i_r + g["ki_yaw"] * e_r * self.dt, -I_LIMIT, I_LIMIT)
        diff = ff * r_cmd + g["kp_yaw"] * e_r + self.i_r
        v = np.stack([mean - 0.5 * diff, mean + 0.5 * diff], axis=1)
        return (np.clip(v, -self.vmax, self.vmax) * self.scale).astype(np.float32)


def classical_for(params, gains: dict) -> ClassicalController:
    """A :class:`ClassicalController` for an env's :class:`~trackenv.envs.core.EnvParams` (normalised actions):
    v* is the mean of the task's target speed and a_b its braking deceleration (a spin has no speed loop)."""
    t = params.task
    v_star = float(np.asarray(t.target_speed).mean()) if hasattr(t, "target_speed") else CRUISE_SPEED
    a_b = float(t.brake_decel) if hasattr(t, "brake_decel") and t.steering != "spin" else BRAKE_DECEL
    return ClassicalController(type(t), params.obs_names, gains, control_dt=params.control_dt,
                               voltage_limit=params.voltage_limit, target_speed=v_star, brake_decel=a_b)


def profile_terrain(terrain: str) -> str:
    """The terrain whose thesis profile and tuned gains a terrain uses: dry sand for deformable soils, else asphalt."""
    if terrain in ("dry_sand", "asphalt"):
        return terrain
    from ..params import load_params  # noqa: PLC0415

    return "dry_sand" if float(load_params(terrain).terrain.deformable) > 0.5 else "asphalt"


def load_gains(task, terrain: str, path: str | Path = GAINS_FILE) -> dict:
    """Tuned gains for ``task`` on ``terrain`` from ``configs/train/classical_gains.yaml``.

    Terrains without an entry use dry sand's gains when deformable, asphalt's otherwise; the defaults
    when the file has neither.
    """
    name = task_class(task).name
    path = Path(path)
    if not path.is_file():
        return dict(DEFAULT_GAINS)
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    table = data.get("gains", {})
    for t in (terrain, profile_terrain(terrain)):
        entry = table.get(f"{name}/{t}")
        if entry:
            return {k: float(entry[k]) for k in DEFAULT_GAINS}
    return dict(DEFAULT_GAINS)


# ----------------------------------------------------------------------------------------------
# open loop


class OpenLoop:
    """The reconstructed thesis profile ``configs/field/<field_profile>_<terrain>.yaml`` as actions.

    Each control step applies the profile's mean voltage over that step (10 samples), then 0 V once the
    profile has ended; other deformable soils use the dry-sand profile, hard ground the asphalt one.
    ``voltage_limit`` [V] is the vehicle's (the unit of normalised actions).
    """

    def __init__(self, task, terrain: str, *, voltage_limit: float, control_dt: float = 0.05,
                 normalize_action: bool = True):
        from ..field_profiles import load_field_profile  # noqa: PLC0415

        self.profile = load_field_profile(f"{task_class(task).field_profile}_{profile_terrain(terrain)}")
        self.dt = float(control_dt)
        self.scale = 1.0 / voltage_limit if normalize_action else 1.0
        self.k = 0

    def reset(self):
        self.k = 0

    def volts(self, k: int) -> np.ndarray:
        t0 = k * self.dt
        if t0 >= self.profile.t_end:
            return np.zeros(2)
        ts = t0 + (np.arange(10) + 0.5) * self.dt / 10.0
        return self.profile.voltages_at(ts).mean(axis=0)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        n = np.atleast_2d(obs).shape[0]
        v = self.volts(self.k)
        self.k += 1
        return np.broadcast_to((v * self.scale).astype(np.float32), (n, 2)).copy()


__all__ = ["ScriptedDriver", "make_driver", "ClassicalController", "classical_for", "OpenLoop", "load_gains",
           "profile_terrain", "DEFAULT_GAINS", "GAIN_GRID", "GAINS_FILE", "FF_SPEED", "FF_YAW", "FF_SPIN",
           "K_HEADING", "K_CROSS", "I_LIMIT"]
