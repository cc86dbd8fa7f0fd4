"""Functional environment core: pure ``reset(key, params)`` / ``step(state, action, params)``.

In the style of gymnax/Brax: the environment is a pair of pure functions on pytrees, so that
``jax.jit`` compiles one step, ``jax.vmap`` batches any number of environments, and the Gymnasium
classes (:mod:`trackenv.envs.gym_env`, :mod:`trackenv.envs.vector`) are thin wrappers::

    params = make_params("go_stop", terrain="dry_sand")
    state, out = reset(jax.random.PRNGKey(0), params)
    state, out = step(state, jnp.array([11.8, 11.8]), params)   # out.obs, out.reward, out.terminated ...

One control step holds the two motor voltages constant for ``control_dt`` (default 0.05 s) and
integrates the model with the ETDRK4 substeps of ``trackenv.integrate.advance_constant``, in substeps
(default ``ENV_DEFAULT_SUBSTEP``, simulate's verified ``DEFAULT_SUBSTEP``).

Actions: the two motor voltages [V_left, V_right] in volts, clipped to +-voltage_limit (24 V); with
``normalize_action=True`` an action in [-1, 1] is clipped and scaled by the voltage limit.

Observation = task part (see each task's docstring) followed by this common part, all float32 and
clipped to the stated bounds (the bounds are far outside normal operation; saturation only happens in
abnormal runs):

==================  ==================  =============================================
omega_left/right    [-40, 40] rad/s     sprocket speeds (encoders)
current_left/right  [-100, 100] A       motor currents (signed)
yaw_rate            [-15, 15] rad/s     gyro
prev_voltage_l/r    [-V_max, V_max] V   the previous (clipped) action, in volts
time_fraction       [0, 1]              t / max_time
==================  ==================  =============================================

Divergence: if the integrated state is non-finite or leaves the physical bounds after a step (|i| >
10x the stall current, |omega| > 10x the no-load speed: ``integrate.is_physical``), the physical state
is frozen at its last physical value, the reward is 0 and the episode is *truncated* with
``info["diverged"] = True``. A substep above ``control_dt`` or the integrator's stable limit
(``simulate.MAX_SUBSTEP``) is rejected when the environment is built.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..effects import resolve_effects
from ..integrate import advance_constant, is_physical
from ..params import ConfigError, Params, is_positive, load_params
from ..physics.model import State, initial_state
from ..simulate import DEFAULT_SUBSTEP, check_substep, n_substeps
from . import randomization
from .tasks import TASKS, Task

# Environments default to simulate's verified substep (the convergence study, README Numerics):
# no faster default that is off the reference. Pass substep= to trade accuracy for speed.
ENV_DEFAULT_SUBSTEP = DEFAULT_SUBSTEP  # s

F32 = jnp.float32

COMMON_OBS = [
    ("omega_left", -40.0, 40.0),
    ("omega_right", -40.0, 40.0),
    ("current_left", -100.0, 100.0),
    ("current_right", -100.0, 100.0),
    ("yaw_rate", -15.0, 15.0),
    ("prev_voltage_left", None, None),  # +-voltage limit
    ("prev_voltage_right", None, None),
    ("time_fraction", 0.0, 1.0),
]

INFO_KEYS = ("success", "off_course", "diverged", "timeout", "time", "completion", "tracking_rmse", "energy",
             "episode_return")
BOOL_INFO = ("success", "off_course", "diverged", "timeout")


class EnvParams(eqx.Module):
    """Everything a (batch of) environment(s) needs; array leaves may be changed without recompiling.

    sim: nominal simulation parameters (terrain, vehicle, internal resistance, effects).
    task: the task module (targets, tolerances, reward weights).
    dr_low/dr_high: per-episode sampling ranges of the parameters named by ``dr_paths``; for a ground
    mixture, one row per terrain of ``dr_grounds`` (its terrains' Params stacked on a leading axis).
    obs_low/obs_high: observation bounds (float32).
    """

    sim: Params
    task: Task
    dr_low: jax.Array
    dr_high: jax.Array
    obs_low: jax.Array
    obs_high: jax.Array
    max_steps: jax.Array  # int32, episode length in control steps (a leaf: changing it does not recompile)
    action_scale: jax.Array  # V per action unit: 1 (actions in volts) or the voltage limit (normalised actions)
    dr_paths: tuple = eqx.field(static=True)
    control_dt: float = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    voltage_limit: float = eqx.field(static=True)
    physics_batching: str = eqx.field(static=True)
    dr_grounds: Params | None = None

    @property
    def obs_names(self) -> tuple[str, ...]:
        return tuple(self.task.obs_names) + tuple(n for n, _, _ in COMMON_OBS)

    @property
    def normalize_action(self) -> bool:
        """Actions in [-1, 1] (scaled by the voltage limit) rather than in volts (host-side)."""
        return float(self.action_scale) != 1.0

    @property
    def max_time(self) -> float:
        return int(self.max_steps) * self.control_dt


class EnvState(eqx.Module):
    """State of one environment (add a leading axis for a batch)."""

    physics: State  # vehicle state (docs/model.md §1)
    sim: Params  # this episode's (possibly randomised) simulation parameters
    task: dict  # task state: targets, reference path
    dr_values: jax.Array  # (n_dr,) the sampled parameter values
    prev_action: jax.Array  # (2,) V, the last applied (clipped) voltages
    steps: jax.Array  # int32, control steps taken in this episode
    energy: jax.Array  # J, electrical energy drawn so far
    sq_error: jax.Array  # sum of squared primary tracking errors
    episode_return: jax.Array
    done: jax.Array  # bool, the episode has ended (used by next-step autoreset)
    key: jax.Array  # PRNG key (uint32 (2,)) for the next reset


class StepResult(NamedTuple):
    obs: jax.Array  # (n_obs,) float32
    reward: jax.Array  # float32
    terminated: jax.Array  # bool
    truncated: jax.Array  # bool
    info: dict  # INFO_KEYS -> scalars


# ----------------------------------------------------------------------------------------------
# construction


def make_params(
    task: str,
    *,
    terrain: str = "dry_sand",
    vehicle: str = "packbot",
    internal_resistance: str = "constant",
    effects=(),
    control_dt: float = 0.05,
    substep: float = ENV_DEFAULT_SUBSTEP,
    domain_randomization: Any = False,
    normalize_action: bool = False,
    physics_batching: str = "vmap",
    sim_params: Params | None = None,
    **task_kwargs,
) -> EnvParams:
    """Build :class:`EnvParams` for ``task``, a task id of :data:`trackenv.envs.tasks.TASKS` (``go_stop`` ...).

    ``task_kwargs`` are the task's options (targets as numbers or (low, high) ranges, tolerances,
    ``max_time``, ``reward`` = dict of :class:`RewardParams` fields); see each task class.
    ``sim_params`` overrides terrain/vehicle/internal_resistance/effects with a ready ``Params``.
    ``physics_batching``: 'vmap' (default) lets ``jax.vmap`` batch the integrator; 'native' puts the
    batch on the last axis of the physics arrays inside a vmapped step (docs/model.md §6), which can be
    faster for large batches.
    """
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; known: {', '.join(TASKS)}")
    if not is_positive(control_dt):
        raise ValueError(f"control_dt must be a positive number of seconds, got {control_dt!r}")
    check_substep(substep, control_dt, "control_dt")
    if not isinstance(normalize_action, (bool, np.bool_)):
        raise ValueError(f"normalize_action must be True or False, got {normalize_action!r}")
    if physics_batching not in ("vmap", "native"):
        raise ValueError(f"physics_batching must be 'vmap' or 'native', got {physics_batching!r}")
    from_names = sim_params is None
    if sim_params is None:
        sim_params = load_params(terrain, vehicle, internal_resistance, resolve_effects(effects))
    task_mod, max_time = TASKS[task].create(**task_kwargs)
    if not (math.isfinite(max_time) and max_time > 0):
        raise ValueError(f"max_time must be positive, got {max_time}")
    max_steps = max(1, int(round(max_time / control_dt)))
    grounds = None
    if isinstance(domain_randomization, dict) and "grounds" in domain_randomization:
        if not from_names:
            raise ConfigError("domain randomisation: a ground mixture loads its terrains by name, so it needs "
                              "terrain/vehicle/internal_resistance/effects, not sim_params")
        paths, lo, hi, grounds = randomization.resolve_grounds(
            domain_randomization, lambda name: load_params(name, vehicle, internal_resistance, resolve_effects(effects)))
    else:
        paths, lo, hi = randomization.resolve(sim_params, domain_randomization)
    vlim = float(sim_params.vehicle.voltage_limit)
    names = tuple(task_mod.obs_names) + tuple(n for n, _, _ in COMMON_OBS)
    common_lo = [(-vlim if a is None else a) for _, a, _ in COMMON_OBS]
    common_hi = [(vlim if b is None else b) for _, _, b in COMMON_OBS]
    obs_low = np.concatenate([task_mod.obs_low, np.asarray(common_lo, np.float32)]).astype(np.float32)
    obs_high = np.concatenate([task_mod.obs_high, np.asarray(common_hi, np.float32)]).astype(np.float32)
    assert len(names) == obs_low.shape[0]
    return EnvParams(
        sim=sim_params, task=task_mod,
        dr_low=jnp.asarray(lo, F32), dr_high=jnp.asarray(hi, F32),
        obs_low=jnp.asarray(obs_low), obs_high=jnp.asarray(obs_high),
        max_steps=jnp.asarray(max_steps, jnp.int32),
        action_scale=jnp.asarray(vlim if normalize_action else 1.0, F32),
        dr_paths=paths, control_dt=float(control_dt), substeps=n_substeps(control_dt, substep),
        voltage_limit=vlim,
        physics_batching=physics_batching, dr_grounds=grounds,
    )


# ----------------------------------------------------------------------------------------------
# physics


def supply_power(volts, current):
    """Electrical power drawn from the supply, sum_k max(V_k i_k, 0) [W] (regeneration not credited)."""
    return jnp.maximum(volts * current, 0.0).sum(axis=0)


def advance_with_energy(physics: State, volts, sim: Params, dt: float, substeps: int):
    """``trackenv.integrate.advance_constant`` plus the electrical energy drawn during the step [J].

    ``advance_constant`` with its trapezoid quadrature of the supply power; it is integrated by the
    trapezoid rule over the substeps. At the start of the step the current is taken as the
    quasi-steady (V - alpha_v omega)/R_m that the motor reaches within ~1 ms (L_m/R_m = 0.25 ms) after
    the voltage changes, so a voltage step's in-rush is counted. Works for any trailing batch shape.
    """
    veh = sim.vehicle
    p0 = supply_power(volts, (volts - veh.alpha_v * physics.omega) / veh.motor_resistance)
    return advance_constant(physics, volts, sim, dt, substeps,
                            integrand=lambda s: supply_power(volts, s.current), integrand_start=p0)


def _native_rule(dt, substeps, axis_size, in_batched, physics, volts, sim):
    """vmap rule: run the integrator natively with the batch on the last axis (docs/model.md §6)."""
    pb, vb, sb = in_batched

    def last(x, batched, broadcast):
        if batched:
            return jnp.moveaxis(x, 0, -1)
        return jnp.broadcast_to(x[..., None], x.shape + (axis_size,)) if broadcast else x

    physics = jax.tree.map(lambda x, b: last(x, b, True), physics, pb)
    volts = last(volts, vb, True)
    sim = jax.tree.map(lambda x, b: last(x, b, False), sim, sb)
    out = advance_with_energy(physics, volts, sim, dt, substeps)
    out = jax.tree.map(lambda x: jnp.moveaxis(x, -1, 0), out)
    return out, jax.tree.map(lambda _: True, out)


_NATIVE_CACHE: dict = {}


def _advance_native(dt: float, substeps: int):
    key = (dt, substeps)
    if key not in _NATIVE_CACHE:
        from jax.custom_batching import custom_vmap  # noqa: PLC0415

        @custom_vmap
        def f(physics, volts, sim):
            return advance_with_energy(physics, volts, sim, dt, substeps)

        f.def_vmap(lambda n, b, p, v, s: _native_rule(dt, substeps, n, b, p, v, s))
        _NATIVE_CACHE[key] = f
    return _NATIVE_CACHE[key]


def physics_step(physics: State, volts, sim: Params, params: EnvParams):
    """One control step of the vehicle: (new physics state, electrical energy drawn [J])."""
    if params.physics_batching == "native":
        return _advance_native(params.control_dt, params.substeps)(physics, volts, sim)
    return advance_with_energy(physics, volts, sim, params.control_dt, params.substeps)


# ----------------------------------------------------------------------------------------------
# reset / step


def _tree_where(cond, a, b):
    return jax.tree.map(lambda x, y: jnp.where(cond, x, y), a, b)


def _strong(tree):
    """Drop weak types so that reset's and step's outputs have identical avals (no recompiles)."""
    return jax.tree.map(lambda x: jax.lax.convert_element_type(x, x.dtype) if isinstance(x, jax.Array) else x, tree)


def observe(state: EnvState, params: EnvParams) -> jax.Array:
    """The observation of ``state`` (task part then common part), float32, clipped to its bounds."""
    phys = state.physics
    task_obs = params.task.observe(state.task, phys, state.sim)
    common = jnp.stack([
        phys.omega[0], phys.omega[1], phys.current[0], phys.current[1], phys.vel[2],
        state.prev_action[0], state.prev_action[1],
        state.steps.astype(F32) / params.max_steps.astype(F32),
    ])
    obs = jnp.concatenate([task_obs.astype(F32), common.astype(F32)])
    return jnp.clip(obs, params.obs_low, params.obs_high)


def _info(state: EnvState, params: EnvParams, success, off, diverged, timeout, completion) -> dict:
    n = jnp.maximum(state.steps, 1).astype(F32)
    return {
        "success": success, "off_course": off, "diverged": diverged, "timeout": timeout,
        "time": state.steps.astype(F32) * params.control_dt,
        "completion": completion.astype(F32),
        "tracking_rmse": jnp.sqrt(state.sq_error / n),
        "energy": state.energy,
        "episode_return": state.episode_return,
    }


def reset(key, params: EnvParams) -> tuple[EnvState, StepResult]:
    """Start an episode: sample the domain-randomised parameters and task targets, vehicle at rest.

    Returns the state and a :class:`StepResult` with the first observation (reward 0, flags False).
    """
    k_dr, k_task, k_next = jax.random.split(key, 3)
    sim, values = randomization.sample(params.sim, k_dr, params.dr_paths, params.dr_low, params.dr_high,
                                       params.dr_grounds)
    phys = initial_state(sim)
    tstate = params.task.init(k_task, sim)
    z = jnp.zeros((), F32)
    state = EnvState(
        physics=phys, sim=sim, task=tstate, dr_values=values.astype(F32), prev_action=jnp.zeros((2,), F32),
        steps=jnp.zeros((), jnp.int32), energy=z, sq_error=z, episode_return=z,
        done=jnp.zeros((), bool), key=k_next,
    )
    state = _strong(state)
    false = jnp.zeros((), bool)
    _, ev = params.task.evaluate(tstate, phys, sim)
    info = _info(state, params, false, false, false, false, ev.completion)
    out = StepResult(observe(state, params), z, false, false, info)
    return state, _strong(out)


def clip_action(action, params: EnvParams):
    """Clip an action to the action space and convert it to volts (2,)."""
    a = jnp.asarray(action, F32) * params.action_scale
    return jnp.clip(a, -params.voltage_limit, params.voltage_limit)


def step(state: EnvState, action, params: EnvParams) -> tuple[EnvState, StepResult]:
    """Advance one control step with the voltages ``action`` held constant (see the module docstring)."""
    volts = clip_action(action, params)
    sim = state.sim
    new, energy = physics_step(state.physics, volts, sim, params)
    finite = is_physical(new, sim, 0) & jnp.isfinite(energy)
    phys = _tree_where(finite, new, state.physics)
    diverged = ~finite
    energy = jnp.where(finite, energy, 0.0)
    tstate, ev = params.task.evaluate(state.task, phys, sim)
    steps = state.steps + 1
    timeout = steps >= params.max_steps
    success = ev.success & finite
    off = ev.off_course & finite & ~success
    terminated = success | off
    truncated = (~terminated) & (timeout | diverged)

    rp = params.task.reward
    smooth = jnp.square((volts - state.prev_action) / params.voltage_limit).sum()
    steps_left = (params.max_steps - steps).astype(F32)
    reward = (ev.tracking - rp.w_energy * energy - rp.w_smooth * smooth
              + jnp.where(success, rp.success_bonus + rp.hold_credit * steps_left, 0.0)
              - jnp.where(off, rp.failure_penalty, 0.0))
    reward = jnp.where(diverged, 0.0, reward).astype(F32)
    err = jnp.where(finite, ev.error, 0.0)

    new_state = EnvState(
        physics=phys, sim=sim, task=tstate, dr_values=state.dr_values, prev_action=volts,
        steps=steps, energy=state.energy + energy, sq_error=state.sq_error + err * err,
        episode_return=state.episode_return + reward, done=terminated | truncated, key=state.key,
    )
    new_state = _strong(new_state)
    info = _info(new_state, params, success, off, diverged, timeout & ~terminated, ev.completion)
    out = StepResult(observe(new_state, params), reward, terminated, truncated, info)
    return new_state, _strong(out)


# ----------------------------------------------------------------------------------------------
# autoreset (for batched use)

AUTORESET_MODES = ("next_step", "same_step", "disabled")


def step_autoreset(state: EnvState, action, params: EnvParams, mode) -> tuple[EnvState, StepResult, StepResult]:
    """One step with Gymnasium's autoreset semantics for one environment (vmap it for a batch).

    - ``same_step``: an episode that ends is reset in the same call; the returned result carries the
      new episode's first observation and reset info (but the step's reward and flags), and the third
      value is the ended episode's final result (final observation and final info).
    - ``next_step``: a step taken after an episode ended resets instead (the action is ignored,
      reward 0, flags False).
    - ``disabled``: plain :func:`step`; the caller resets.

    ``mode`` is one of :data:`AUTORESET_MODES`, or its index there as an int32 scalar array: then the
    mode is a runtime value and one compiled program serves all three (the reset is computed every
    step and selected).

    Returns (state, result, final); ``final`` is ``result`` except in same-step mode.
    """
    if isinstance(mode, str):
        if mode not in AUTORESET_MODES:
            raise ValueError(f"autoreset mode must be one of {AUTORESET_MODES}, got {mode!r}")
        if mode == "disabled":
            new, out = step(state, action, params)
            return new, out, out
        mode = AUTORESET_MODES.index(mode)
    same = mode == AUTORESET_MODES.index("same_step")
    nxt = mode == AUTORESET_MODES.index("next_step")
    key, sub = jax.random.split(state.key)
    new, out = step(state, action, params)
    reset_same = same & (out.terminated | out.truncated)  # same_step: the episode that just ended
    reset_next = nxt & state.done  # next_step: the episode ended at the previous step
    kept = eqx.tree_at(lambda s: s.key, new, jnp.where(same, key, new.key))  # same_step draws a key every step

    def fresh_episode():
        fresh, first = reset(sub, params)
        return eqx.tree_at(lambda s: s.key, fresh, key), first

    # computed only when needed (under vmap both branches run and are selected, as jnp.where would)
    fresh, first = jax.lax.cond(reset_same | reset_next, fresh_episode, lambda: (kept, out))
    merged = _tree_where(reset_same | reset_next, fresh, kept)
    result = _tree_where(reset_next, first, out)
    result = result._replace(obs=jnp.where(reset_same, first.obs, result.obs),
                             info=_tree_where(reset_same, first.info, result.info))
    final = _tree_where(same, out, result)
    return merged, result, final


# ----------------------------------------------------------------------------------------------
# packing for one host transfer per step


def physics_layout(state: EnvState) -> list[tuple[tuple, tuple]]:
    """(key path, shape) of every physics leaf, in ``pack`` order (for unpacking on the host)."""
    leaves, _ = jax.tree_util.tree_flatten_with_path(state.physics)
    return [(tuple(str(getattr(k, "name", getattr(k, "key", k))) for k in path), tuple(x.shape)) for path, x in leaves]


def pack(state: EnvState, out: StepResult, params: EnvParams, *, with_physics: bool = True,
         final: StepResult | None = None) -> jax.Array:
    """Everything the host needs after a step as one float32 vector (one device-to-host transfer).

    Layout: obs | reward | INFO_KEYS | terminated, truncated | dr values | [final obs | final INFO_KEYS]
    | [physics leaves, raveled in ``physics_layout`` order].
    """
    parts = [out.obs, out.reward[None]]
    parts += [jnp.asarray(out.info[k], F32)[None] for k in INFO_KEYS]
    parts += [out.terminated.astype(F32)[None], out.truncated.astype(F32)[None], state.dr_values.astype(F32)]
    if final is not None:
        parts.append(final.obs.astype(F32))
        parts += [jnp.asarray(final.info[k], F32)[None] for k in INFO_KEYS]
    if with_physics:
        parts += [x.astype(F32).ravel() for x in jax.tree.leaves(state.physics)]
    return jnp.concatenate(parts)
