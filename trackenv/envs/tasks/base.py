"""Shared pieces of the tasks: the task interface, reward parameters, and small pure helpers.

A task is an :class:`equinox.Module` whose array leaves are its parameters (targets, tolerances,
reward weights; jit/vmap-able) and whose methods are pure ``jnp`` functions of a single (unbatched)
vehicle. The environment core (:mod:`trackenv.envs.core`) calls them in this order::

    tstate = task.init(key, sim_params)                      # at reset: sample targets, build paths
    obs    = task.observe(tstate, physics_state, sim_params) # task-relative part of the observation
    tstate, ev = task.evaluate(tstate, physics_state, sim_params)   # after every control step

Targets given as a range ``(low, high)`` are sampled uniformly per episode; a single number fixes them.

Each task class also owns its facts outside the simulation (class variables, see :class:`Task`): the
Gymnasium env name and id, the primary tracking error with its unit and kernel scale, the host-side
reference laws the scripted and PI controllers use (:mod:`trackenv.envs.controllers`), the id prefix
of its reconstructed thesis voltage profiles (``configs/field``) and its default options
(``DEFAULTS``). The registry :data:`trackenv.envs.tasks.TASK_CLASSES` lists the tasks once; the
environment registration, the env classes and the training and evaluation names derive from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

F32 = jnp.float32

# Overall PackBot footprint for gates and drawings: 27 in x 16 in (the box of docs/model.md §2's yaw inertia).
FOOTPRINT_LENGTH = 0.6858  # m, 27 in
FOOTPRINT_WIDTH = 0.4064  # m, 16 in


class TaskEval(NamedTuple):
    """What a task reports after a control step (all scalars)."""

    tracking: jax.Array  # [0, 1]: weighted Gaussian-kernel score of the tracking errors
    error: jax.Array  # the task's primary tracking error (for the RMSE metric), SI
    success: jax.Array  # bool
    off_course: jax.Array  # bool
    completion: jax.Array  # [0, 1] progress through the maneuver


class PrimaryError(NamedTuple):
    """A task's primary tracking error: the quantity of :attr:`TaskEval.error` and of the tracking-RMSE metric."""

    obs_name: str  # the observation entry that carries it
    unit: str  # its SI unit
    quantity: str  # what it measures, in words
    scale: float  # the scale of its tracking kernel in the reward [unit]

    @property
    def label(self) -> str:
        """``unit (quantity)``, e.g. ``m/s (speed)``: the unit of the tracking RMSE in tables."""
        return f"{self.unit} ({self.quantity})"


# The tracking kernels of the path-following tasks (J-turn, lane change): m/s, m, rad, rad/s; their primary
# error is the cross-track error.
PATH_KERNEL_SCALES = {"speed_error": 0.2, "cross_track": 0.15, "heading_error": 0.25, "yaw_rate_error": 0.5}
PATH_PRIMARY_ERROR = PrimaryError("cross_track", "m", "cross-track", PATH_KERNEL_SCALES["cross_track"])


class RewardParams(eqx.Module):
    """Reward terms shared by all tasks (see each task's docstring for its tracking terms).

    r_t = tracking_t - w_energy * E_t - w_smooth * sum_k ((V_k,t - V_k,t-1) / V_max)^2
          + [success] (success_bonus + hold_credit * steps_left) - [off course] failure_penalty
    """

    w_energy: jax.Array  # 1/J, per joule of electrical energy drawn in the step
    w_smooth: jax.Array  # -, on the squared voltage change normalised by the voltage limit
    success_bonus: jax.Array  # -, once on success
    hold_credit: jax.Array  # -, per remaining step on success (the best tracking reward per step)
    failure_penalty: jax.Array  # -, once when the vehicle leaves the course


def reward_params(w_energy=0.002, w_smooth=0.05, success_bonus=10.0, hold_credit=1.0,
                  failure_penalty=10.0) -> RewardParams:
    f = lambda v: jnp.asarray(float(v), F32)  # noqa: E731
    return RewardParams(f(w_energy), f(w_smooth), f(success_bonus), f(hold_credit), f(failure_penalty))


def as_range(name: str, value: Any, lower: float | None = None, upper: float | None = None,
             nonzero: bool = False) -> jax.Array:
    """A target given as a number or a ``(low, high)`` pair -> float32 array (2,), validated."""
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        lo = hi = float(value)
    else:
        try:
            lo, hi = (float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"task parameter '{name}' must be a number or a (low, high) pair, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise ValueError(f"task parameter '{name}' = {value!r}: need finite low <= high")
    if lower is not None and lo < lower:
        raise ValueError(f"task parameter '{name}' = {value!r} is below its minimum {lower}")
    if upper is not None and hi > upper:
        raise ValueError(f"task parameter '{name}' = {value!r} is above its maximum {upper}")
    if nonzero and lo <= 0.0 <= hi:
        raise ValueError(f"task parameter '{name}' = {value!r} must not include 0")
    return jnp.asarray([lo, hi], F32)


def as_scalar(name: str, value: Any, lower: float | None = None) -> jax.Array:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ValueError(f"task parameter '{name}' must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or (lower is not None and value < lower):
        raise ValueError(f"task parameter '{name}' = {value} is invalid (must be finite{'' if lower is None else f' and >= {lower}'})")
    return jnp.asarray(value, F32)


def sample(key, rng):
    """Uniform sample from a (2,) range [low, high] (exactly low when low == high)."""
    return rng[0] + jax.random.uniform(key, (), F32) * (rng[1] - rng[0])


def kernel(error, scale):
    """Gaussian tracking kernel exp(-(e/scale)^2) in (0, 1]."""
    return jnp.exp(-jnp.square(error / scale))


def braking_speed(v_target, distance, decel):
    """Reference speed that holds ``v_target`` and brakes at ``decel`` to stop at ``distance`` ahead."""
    return jnp.minimum(v_target, jnp.sqrt(2.0 * decel * jnp.maximum(distance, 0.0)))


def is_stopped(phys, speed_tol, omega_tol):
    """At rest: |u|, |v| below speed_tol and both sprockets below omega_tol."""
    return (jnp.abs(phys.vel[0]) < speed_tol) & (jnp.abs(phys.vel[1]) < speed_tol) & (jnp.abs(phys.omega) < omega_tol).all()


def split_task_kwargs(defaults: dict, kwargs: dict, task: str) -> dict:
    unknown = sorted(set(kwargs) - set(defaults))
    if unknown:
        raise TypeError(f"{task}: unknown option(s) {unknown}; accepted: {sorted(defaults)}")
    return {**defaults, **kwargs}


# Observation columns -> float64 array: how the host-side reference laws read an observation.
Columns = Callable[[str], np.ndarray]


class Task(eqx.Module):
    """Interface of a task (see the module docstring). Subclasses set the class variables.

    Class variables (the task's facts, read by the environment registration, the controllers, training
    and evaluation):

    ``name``            the task id (``go_stop``)
    ``env_name``        the Gymnasium env name (``GoStop-v0``); ``env_id`` = ``trackenv/<env_name>`` is derived
    ``field_profile``   the id prefix of the task's reconstructed thesis voltage profiles,
                        ``configs/field/<field_profile>_<terrain>.yaml``
    ``kernel_scales``   the scales of the Gaussian tracking kernels of the reward, by error name (SI)
    ``primary_error``   the :class:`PrimaryError` (its scale is the kernel scale of that error)
    ``steering``        how the controllers steer: ``"heading"`` (hold the line on heading and lateral
                        offset, no reference yaw rate), ``"path"`` (yaw-rate loop on the path's
                        reference yaw rate plus heading and cross-track corrections) or ``"spin"``
                        (zero mean voltage, yaw-rate loop only)
    ``DEFAULTS``        the default options of :meth:`create` (targets, tolerances, ``max_time``)
    """

    name: ClassVar[str] = "task"
    env_name: ClassVar[str] = ""
    env_id: ClassVar[str] = ""
    field_profile: ClassVar[str] = ""
    kernel_scales: ClassVar[dict[str, float]] = {}
    primary_error: ClassVar[PrimaryError]
    steering: ClassVar[str] = "path"
    DEFAULTS: ClassVar[dict[str, Any]] = {}
    obs_names: ClassVar[tuple[str, ...]] = ()
    obs_low: ClassVar[np.ndarray] = np.zeros(0, np.float32)
    obs_high: ClassVar[np.ndarray] = np.zeros(0, np.float32)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.env_id = f"trackenv/{cls.env_name}"

    @classmethod
    def default_params(cls) -> dict[str, Any]:
        """The default options of :meth:`create` (a copy of ``DEFAULTS``; gymnax's ``default_params``)."""
        return dict(cls.DEFAULTS)

    @classmethod
    def create(cls, **kwargs) -> tuple[Task, float]:  # pragma: no cover - interface
        """The task from its options (``DEFAULTS`` overridden by ``kwargs``) and the episode's ``max_time`` [s]."""
        raise NotImplementedError

    # -- host-side reference laws (numpy, on observation columns; used by trackenv.envs.controllers) --

    @staticmethod
    def reference_speed(col: Columns, v_star: float, a_b: float) -> np.ndarray | None:  # pragma: no cover
        """The controllers' reference forward speed v_ref [m/s] from the observation columns, the cruise
        speed ``v_star`` [m/s] and the braking deceleration ``a_b`` [m/s^2]; ``None``: no speed loop."""
        raise NotImplementedError

    @staticmethod
    def reference_yaw_rate(col: Columns) -> np.ndarray | float:
        """The controllers' reference yaw rate r_ref [rad/s]: the path's v_ref kappa, recovered from the
        observation as yaw_rate_error + yaw_rate (tasks steering on heading override this with 0)."""
        return col("yaw_rate_error") + col("yaw_rate")

    # -- simulation (pure jnp, jit/vmap-able) --

    def init(self, key, sim) -> dict:  # pragma: no cover - interface
        raise NotImplementedError

    def observe(self, tstate: dict, phys, sim) -> jax.Array:  # pragma: no cover - interface
        raise NotImplementedError

    def evaluate(self, tstate: dict, phys, sim) -> tuple[dict, TaskEval]:  # pragma: no cover - interface
        raise NotImplementedError

    def drawing(self, tstate: dict) -> dict:  # pragma: no cover - interface
        """Host-side description of the reference for the renderer (numpy arrays)."""
        return {}


def obs_bounds(spec: list[tuple[str, float, float]]):
    names = tuple(n for n, _, _ in spec)
    low = np.array([lo for _, lo, _ in spec], np.float32)
    high = np.array([hi for _, _, hi in spec], np.float32)
    return names, low, high
