"""Shared pieces of the tasks: the task interface, reward parameters, and small pure helpers.

A task is an :class:`equinox.Module` whose array leaves are its parameters (targets, tolerances,
reward weights; jit/vmap-able) and whose methods are pure ``jnp`` functions of a single (unbatched)
vehicle. The environment core (:mod:`trackenv.envs.core`) calls them in this order::

    tstate = task.init(key, sim_params)                      # at reset: sample targets, build paths
    obs    = task.observe(tstate, physics_state, sim_params) # task-relative part of the observation
    tstate, ev = task.evaluate(tstate, physics_state, sim_params)   # after every control step

Targets given as a range ``(low, high)`` are sampled uniformly per episode; a single number fixes them.
"""

from __future__ import annotations

import math
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


class Task(eqx.Module):
    """Interface of a task (see the module docstring). Subclasses set the class variables."""

    name: ClassVar[str] = "task"
    obs_names: ClassVar[tuple[str, ...]] = ()
    obs_low: ClassVar[np.ndarray] = np.zeros(0, np.float32)
    obs_high: ClassVar[np.ndarray] = np.zeros(0, np.float32)

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
