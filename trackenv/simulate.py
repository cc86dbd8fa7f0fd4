"""``simulate``: drive the model with a voltage profile and record the trajectory and instruments.

    >>> import trackenv as te
    >>> params = te.load_params("dry_sand")
    >>> profile = te.VoltageProfile.from_breakpoints([[0, 0, 0], [0.3, 11.8, 11.8], [8, 11.8, 11.8]])
    >>> traj = te.simulate(params, profile, t_end=8.0)
    >>> traj.channels["speed_ideal"][-1]   # ~1.108 m/s

One compiled program per (shape, dtype, dt, substeps, effects); the core is a pure function
(:func:`simulate_core`) that works under ``jax.jit``, ``jax.vmap`` and ``jax.grad``. Batches can
also be laid out with the vehicle index on the last axis of the profile and the parameters
(docs/model.md §6), which needs no ``vmap``; :func:`simulate_batch` is the compiled core for such a
batch without ``simulate``'s checks (what the diagnosis calls, also under ``jax.jacfwd``).

Precision: float32 by default; pass parameters loaded with ``dtype=jnp.float64`` (and enable
``jax_enable_x64``) for float64. Both agree to well under 1% on the thesis maneuvers (tests).

Voltage limits: profiles beyond the vehicle's ``voltage_limit`` (±24 V) are *rejected* with an
error, not clipped: a replayed log that exceeds the bus voltage is a broken log. (The environments
clip actions to their action space, as Gymnasium users expect.)
"""

from __future__ import annotations

import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import instruments, parallel
from .integrate import advance, is_physical, physical_bounds
from .parallel import cpu_devices, shard, split_count
from .params import Params, is_positive
from .physics import sums
from .physics.model import State, drive_voltage, initial_state, prescribed_speed_current

DEFAULT_DT = 0.05  # s, control / output interval
DEFAULT_SUBSTEP = 0.0005  # s, chosen by the convergence study (tests/test_convergence.py, README)
# Largest substep accepted by simulate and the environments [s]: the stability sweep of
# benchmarks/stability.py (README, Numerics) stays bounded on every thesis maneuver up to MAX_SUBSTEP
# and blows up beyond it. Accuracy needs far less (DEFAULT_SUBSTEP).
MAX_SUBSTEP = 0.01


class SimulationDiverged(RuntimeError):
    """A simulation's state became non-finite or left the physical bounds (``integrate.is_physical``);
    the message gives the time of divergence."""


def check_substep(substep, interval: float, interval_name: str = "dt") -> None:
    """Raise ``ValueError`` naming the parameter if ``substep`` is not in (0, min(MAX_SUBSTEP, interval)]."""
    if not is_positive(substep):
        raise ValueError(f"substep must be a positive number of seconds, got {substep!r}")
    if substep > MAX_SUBSTEP * (1 + 1e-9):
        raise ValueError(
            f"substep = {substep:g} s exceeds the stable limit MAX_SUBSTEP = {MAX_SUBSTEP:g} s of the integrator "
            f"(the verified default is {DEFAULT_SUBSTEP:g} s)")
    if substep > interval * (1 + 1e-9):
        raise ValueError(f"substep = {substep:g} s exceeds {interval_name} = {interval:g} s; use a substep <= {interval_name}")


def _float_array(values, what: str, source: str) -> np.ndarray:
    """``values`` as a float64 array, or a ``ValueError`` naming ``source`` and ``what`` (not numpy's)."""
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{source}: the {what} must be numbers in a regular array, got {values!r}") from None


class VoltageProfile(eqx.Module):
    """Motor voltages, piecewise linear in time and held constant beyond the ends.

    t: (K,) strictly increasing times [s]; volts: (K, 2, *b) left/right voltages [V]
    (``*b`` is an optional trailing batch shape, one profile per vehicle).
    """

    t: jax.Array
    volts: jax.Array

    @classmethod
    def from_breakpoints(cls, rows, dtype=jnp.float32, source: str = "breakpoints") -> VoltageProfile:
        """From rows ``[t, v_left, v_right]``."""
        arr = _float_array(rows, "rows [t, v_left, v_right]", source)
        if arr.ndim != 2 or arr.shape[1] != 3:
            raise ValueError(f"{source}: expected rows [t, v_left, v_right], got an array of shape {arr.shape}")
        return cls.from_arrays(arr[:, 0], arr[:, 1:], dtype=dtype, source=source)

    @classmethod
    def from_arrays(cls, t, volts, dtype=jnp.float32, source: str = "profile") -> VoltageProfile:
        """From times (K,) and voltages (K, 2[, *b]); validated (see :func:`validate_profile`)."""
        t = _float_array(t, "times", source)
        volts = _float_array(volts, "voltages", source)
        validate_profile(t, volts, source=source)
        t, volts = _hold_single_sample(t, volts)
        return cls(jnp.asarray(t, dtype), jnp.asarray(volts, dtype))

    @classmethod
    def constant(cls, v_left: float, v_right: float, dtype=jnp.float32) -> VoltageProfile:
        """Constant voltages from t = 0."""
        return cls.from_arrays([0.0, 1.0], [[v_left, v_right], [v_left, v_right]], dtype=dtype, source="constant")

    def __call__(self, t):
        """Voltages at times ``t`` (any shape S): returns (*S, 2, *b)."""
        return interpolate(self.t, self.volts, t)


class SpeedProfile(eqx.Module):
    """Prescribed sprocket (or wheel) speeds, piecewise linear in time and held beyond the ends.

    t: (K,) strictly increasing times [s]; omega: (K, 2, *b) left/right sprocket speeds [rad/s].
    Driving :func:`simulate` with a ``SpeedProfile`` instead of a :class:`VoltageProfile` replays a
    speed-controlled vehicle: omega follows the profile exactly, the body follows from the contact
    forces, and the motor current comes from the drive's torque balance
    (:func:`trackenv.physics.model.prescribed_speed_current`); the trajectory's ``voltage`` is then
    the voltage the drive must apply (``drive_voltage``).
    """

    t: jax.Array
    omega: jax.Array

    @classmethod
    def from_arrays(cls, t, omega, dtype=jnp.float32, source: str = "speed profile") -> SpeedProfile:
        """From times (K,) and sprocket speeds (K, 2[, *b]) [rad/s]; validated (finite, increasing times)."""
        t = _float_array(t, "times", source)
        omega = _float_array(omega, "sprocket speeds", source)
        validate_speeds(t, omega, source=source)
        t, omega = _hold_single_sample(t, omega)
        return cls(jnp.asarray(t, dtype), jnp.asarray(omega, dtype))

    def __call__(self, t):
        """Sprocket speeds at times ``t`` (any shape S): returns (*S, 2, *b) [rad/s]."""
        return interpolate(self.t, self.omega, t)


def _check_times(t, values, what: str, source: str) -> None:
    """Shapes of a profile (``values`` (K, 2[, batch]) for K times) and its times: finite, strictly increasing."""
    if t.ndim != 1 or t.shape[0] < 1:
        raise ValueError(f"{source}: time must be a 1-D array with at least one sample, got shape {t.shape}")
    if values.ndim < 2 or values.shape[0] != t.shape[0] or values.shape[1] != 2:
        raise ValueError(
            f"{source}: {what} must have shape (K, 2[, batch]) with K = {t.shape[0]} samples, got {values.shape}"
        )
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise ValueError(f"{source}: time is not finite at sample {k} (t = {t[k]})")
    bad = np.diff(t) <= 0
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0]) + 1
        raise ValueError(f"{source}: time is not strictly increasing at sample {k} (t = {t[k - 1]} then {t[k]})")


def _hold_single_sample(t, values):
    """A one-sample profile held: a second sample 1 s later with the same values."""
    if t.shape[0] == 1:
        return np.concatenate([t, t + 1.0]), np.concatenate([values, values])
    return t, values


def validate_speeds(t, omega, limit: float | None = None, source: str = "speed profile") -> None:
    """Raise ``ValueError`` naming the sample and channel for a bad speed profile; ``limit``: largest
    |omega| [rad/s] accepted (default: none)."""
    _check_times(t, omega, "speeds", source)
    for ch, name in enumerate(("omega_left", "omega_right")):
        w = omega[:, ch]
        bad = ~np.isfinite(w) if limit is None else ~(np.abs(w) <= limit)
        if np.any(bad):
            k = int(np.argwhere(bad)[0][0])
            what = "is not finite" if limit is None or not np.isfinite(np.ravel(w[k])[0]) else \
                f"exceeds the physical bound {limit:.1f} rad/s"
            raise ValueError(f"{source}: speed '{name}' {what} at sample {k} (t = {t[k]} s)")


def validate_profile(t, volts, limit: float | None = None, source: str = "profile") -> None:
    """Raise ``ValueError`` naming the sample and channel for a bad profile; ``limit`` [V]: the bus voltage
    (default: the PackBot's ``voltage_limit``, configs/vehicle/packbot.yaml)."""
    if limit is None:
        from .params import vehicle_voltage_limit  # noqa: PLC0415

        limit = vehicle_voltage_limit("packbot")
    _check_times(t, volts, "voltages", source)
    for ch, name in enumerate(("v_left", "v_right")):
        v = volts[:, ch]
        nonfinite = ~np.isfinite(v)
        if np.any(nonfinite):
            k = int(np.argwhere(nonfinite)[0][0])
            raise ValueError(f"{source}: voltage '{name}' is not finite at sample {k} (t = {t[k]} s)")
        over = np.abs(v) > limit + 1e-9
        if np.any(over):
            k = int(np.argwhere(over)[0][0])
            raise ValueError(
                f"{source}: voltage '{name}' = {float(np.ravel(v[k])[0]):.3f} V at sample {k} (t = {t[k]} s) exceeds "
                f"the ±{limit:g} V bus limit (profiles are rejected, not clipped; clip them yourself if intended)"
            )


def interpolate(tp, vp, t):
    """Linear interpolation of ``vp`` (K, ...) at times ``t`` (any shape S) -> (*S, ...); held at the ends."""
    k = tp.shape[0]
    idx = jnp.clip(jnp.searchsorted(tp, t, side="right") - 1, 0, k - 2)
    t0, t1 = tp[idx], tp[idx + 1]
    w = jnp.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    w = w.reshape(w.shape + (1,) * (vp.ndim - 1))
    return vp[idx] * (1.0 - w) + vp[idx + 1] * w


class Trajectory(eqx.Module):
    """Result of :func:`simulate`. Time is the leading axis of every array (n_steps + 1 samples).

    t: (T,) [s]; state: :class:`State` with leading T axis; channels: instrument channels
    (``trackenv.instruments.CHANNELS``), each (T, *b), SI; voltage: (T, 2, *b) [V];
    diverged: (*b) bool; t_diverged: (*b) time of the first non-finite or non-physical state
    (``integrate.is_physical``) [s] (NaN if none). After divergence the state is frozen at its last
    physical value and ``diverged`` is set.
    """

    t: jax.Array
    state: State
    channels: dict
    voltage: jax.Array
    diverged: jax.Array
    t_diverged: jax.Array


def n_substeps(dt: float, substep: float) -> int:
    """Substeps per control step so that the substep is at most ``substep``."""
    return max(1, int(math.ceil(dt / substep - 1e-9)))


def simulate_core(params, profile: VoltageProfile, state0: State, n_steps: int, dt: float, substeps: int,
                  t0: float = 0.0, unroll: int = 1) -> Trajectory:
    """Pure simulation core (no validation): jit/vmap/grad-able. See :func:`simulate`."""
    dtype = params.dtype
    h = dt / substeps
    nb = state0.vel.ndim - 1
    speed_mode = isinstance(profile, SpeedProfile)
    # Inputs (voltages or prescribed speeds) at every half substep, grouped as (start, middle, end).
    half = t0 + jnp.arange(2 * n_steps * substeps + 1, dtype=dtype) * (0.5 * h)
    v_half = profile(half)  # (M, 2, *b)
    idx = (2 * jnp.arange(n_steps * substeps))[:, None] + jnp.arange(3)[None]
    v3 = v_half[idx].reshape((n_steps, substeps, 3) + v_half.shape[1:])
    if speed_mode:
        state0 = eqx.tree_at(lambda s: s.omega, state0, v_half[0])

    def control_step(carry, v_sub):
        state, diverged, t_div, k = carry
        new = advance(state, v_sub, params, h, unroll=unroll, speed_prescribed=speed_mode)
        ok = is_physical(new, params, nb)
        newly = (~ok) & (~diverged)
        t_now = t0 + (k + 1) * dt
        t_div = jnp.where(newly, t_now, t_div)
        diverged = diverged | ~ok
        keep = lambda n, o: jnp.where(diverged, o, n)  # noqa: E731  (freeze at the last finite state)
        new = jax.tree.map(keep, new, state)
        return (new, diverged, t_div, k + 1), new

    batch = state0.batch_shape
    carry0 = (state0, jnp.zeros(batch, bool), jnp.full(batch, jnp.nan, dtype), jnp.asarray(0, jnp.int32))
    (_, diverged, t_div, _), states = jax.lax.scan(control_step, carry0, v3)
    states = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), state0, states)
    t = t0 + jnp.arange(n_steps + 1, dtype=dtype) * dt
    if speed_mode:  # the current from the torque balance (4.1), the voltage from (4.2)
        omega_rate = (profile(t + 0.5 * dt) - profile(t - 0.5 * dt)) / dt
        current = jax.vmap(lambda s, w: prescribed_speed_current(s, w, params))(states, omega_rate)
        states = eqx.tree_at(lambda s: s.current, states, current)
        volts = drive_voltage(current, states.omega, params)
    else:
        volts = profile(t)
    chans = jax.vmap(lambda s: instruments.channels(s, params))(states)
    for effect in params.effects:
        chans = effect.instruments(chans, t, params)
    return Trajectory(t, states, chans, volts, diverged, t_div)


def _simulate_in_parts(params, profile, state0: State, n_steps: int, dt: float, substeps: int, t0: float = 0.0,
                       unroll: int = 1, parts: int = 1) -> Trajectory:
    """:func:`simulate_core` traced with the contact sums' form for one of ``parts`` equal device shares
    (:class:`trackenv.physics.sums.Partitioned`; a static argument, so that each form is its own program)."""
    with sums.Partitioned(parts):
        return simulate_core(params, profile, state0, n_steps, dt, substeps, t0, unroll)


_simulate_jit = jax.jit(_simulate_in_parts, static_argnames=("n_steps", "dt", "substeps", "t0", "unroll", "parts"))


def profile_values(profile: VoltageProfile | SpeedProfile) -> jax.Array:
    """The samples of a drive profile: ``volts`` [V] or ``omega`` [rad/s], (K, 2, *b)."""
    return profile.omega if isinstance(profile, SpeedProfile) else profile.volts


def simulate_on_cores(params, profile: VoltageProfile | SpeedProfile, n_steps: int, dt: float, substeps: int,
                      initial: State | None = None, keep_arrays: frozenset[str] = frozenset()) -> Trajectory:
    """:func:`simulate_batch` of a one-axis vehicle batch, split over the host devices (both cores) when
    :func:`trackenv.parallel.split_count` says so; otherwise exactly :func:`simulate_batch`.

    The batch is padded with copies of its last vehicle to a multiple of the device count, its vehicle axis
    sharded (:func:`trackenv.parallel.shard`), and XLA partitions the simulation into one substep loop per
    core with no communication. The outputs are gathered back onto the default device with the padding
    dropped, so that nothing split reaches later computations: when the diagnosis kept split outputs, the
    jitted operations that followed mixed split and unsplit arrays and XLA's CPU runtime stalled in a
    cross-device all-reduce. The program is traced with the contact-point sums' form for one core's share
    (:class:`trackenv.physics.sums.Partitioned`), and a share of at least ``4 * SHARE_ALIGN`` vehicles is padded
    to a multiple of ``SHARE_ALIGN``: a share of 63 vehicles ran 1.4-1.7x slower per vehicle than one of 64,
    189 1.16x slower than 192. Traced parameters (``jax.jit``,
    ``jax.jacfwd``) run unsplit. The results equal the unsplit batch's to float rounding
    (tests/test_parallel.py); a batch of 378 vehicles ran 2.5x faster split (docs/performance.md). A batch of
    more than ``MAX_PER_DEVICE`` vehicles per core runs as equal chunks, one after the other (:func:`_in_chunks`; on
    a CPU only: :func:`trackenv.parallel.chunk_limit`).

    ``keep_arrays``: leaf paths (``"terrain.cohesion"``) that stay per-vehicle arrays even where every vehicle
    holds the same value (:func:`shared_leaves_as_scalars`), so that batches whose values differ only in that
    share one compiled program.
    """
    batch = profile_values(profile).shape[2:]
    params = shared_leaves_as_scalars(params, tuple(batch), keep_arrays)
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves((params, profile, initial)))
    B = batch[0] if len(batch) == 1 else 0
    size = parallel.chunk_size(B)
    if not traced and size < B:
        return _in_chunks(params, profile, n_steps, dt, substeps, initial, size)
    return _split(params, profile, n_steps, dt, substeps, initial, traced)


def _pad_vehicles(x, B: int, pad: int):
    """A leaf with ``B`` vehicles on its last axis, padded with ``pad`` copies of its last vehicle (a numpy array
    for a concrete leaf, to be placed on the cores by :func:`trackenv.parallel.shard`); other leaves (and ``pad``
    0) unchanged."""
    if not (pad and eqx.is_array(x) and x.ndim and x.shape[-1] == B):
        return x
    if not parallel.host_movable(x):
        return jnp.concatenate([x, jnp.repeat(x[..., -1:], pad, axis=-1)], axis=-1)
    x = np.asarray(x)
    return np.concatenate([x, np.repeat(x[..., -1:], pad, axis=-1)], axis=-1)


def _split(params, profile, n_steps: int, dt: float, substeps: int, initial: State | None, traced: bool) -> Trajectory:
    """The body of :func:`simulate_on_cores` after its shared leaves became scalars: split or not."""
    kind = type(profile)
    batch = profile_values(profile).shape[2:]
    n_dev = len(cpu_devices())
    B = batch[0] if len(batch) == 1 else 0
    if traced or len(batch) != 1 or split_count(B + (-B) % n_dev) == 1:
        return _run_batch(params, profile, n_steps, dt, substeps, initial)
    per = -(-B // n_dev)
    if per >= 4 * parallel.SHARE_ALIGN:  # each core's share vectorised without a remainder (1.2-1.7x, docs/performance.md)
        per += (-per) % parallel.SHARE_ALIGN
    pad = n_dev * per - B
    if initial is None:
        initial = initial_state(params, batch)
    if pad:
        def widen(x):
            return _pad_vehicles(x, B, pad)
        params, initial = jax.tree.map(widen, (params, initial))
        profile = kind(profile.t, widen(profile_values(profile)))
    params, values, initial = shard((params, profile_values(profile), initial), B + pad, axis=-1)
    t = jax.device_put(profile.t, jax.sharding.NamedSharding(values.sharding.mesh, jax.sharding.PartitionSpec()))
    traj = _run_batch(params, kind(t, values), n_steps, dt, substeps, initial, parts=n_dev)
    gather = lambda x: jnp.asarray(np.asarray(x)[..., :B])  # noqa: E731  (to the host, back onto the default device)
    return Trajectory(jnp.asarray(np.asarray(traj.t)), jax.tree.map(gather, traj.state),
                      {k: gather(v) for k, v in traj.channels.items()}, gather(traj.voltage), gather(traj.diverged),
                      gather(traj.t_diverged))


def _in_chunks(params, profile, n_steps: int, dt: float, substeps: int, initial: State | None,
               size: int) -> Trajectory:
    """:func:`simulate_on_cores` of a large one-axis batch as equal chunks of at most ``MAX_PER_DEVICE``
    vehicles per core, one after the other, each split over the cores; the outputs joined on the host.

    A core's share of the vehicles is then about as large as the one that runs fastest: per vehicle, a
    batch of 4 096 vehicles (2 048 per core) ran 1.3x slower than chunks of 512, whose working set stays
    in the core's cache (docs/performance.md, "Large batches in chunks"). The batch is padded with copies
    of its last vehicle to equal chunks, each core's share a multiple of ``SHARE_ALIGN``, so that one compiled
    program serves them all; the results equal the unchunked batch's to float rounding (tests/test_parallel.py).
    """
    kind = type(profile)
    values = profile_values(profile)
    B = values.shape[-1]
    if initial is None:
        initial = initial_state(params, (B,))
    k = -(-B // size)  # chunks of trackenv.parallel.chunk_size(B) vehicles
    pad = k * size - B

    def padded(x):
        return _pad_vehicles(x, B, pad)

    def chunk(tree, i):
        """Chunk ``i`` of every vehicle leaf of a padded tree."""
        return jax.tree.map(lambda x: x[..., i * size:(i + 1) * size] if eqx.is_array(x) and x.ndim
                            and x.shape[-1] == k * size else x, tree)

    params, values, initial = jax.tree.map(padded, (params, values, initial))
    parts = [_split(chunk(params, i), kind(profile.t, chunk(values, i)), n_steps, dt, substeps, chunk(initial, i),
                    False) for i in range(k)]
    join = lambda *xs: jnp.asarray(np.concatenate([np.asarray(x) for x in xs], axis=-1)[..., :B])  # noqa: E731
    return Trajectory(parts[0].t, jax.tree.map(join, *[p.state for p in parts]),
                      {c: join(*[p.channels[c] for p in parts]) for c in parts[0].channels},
                      join(*[p.voltage for p in parts]), join(*[p.diverged for p in parts]),
                      join(*[p.t_diverged for p in parts]))


def shared_leaves_as_scalars(params, batch: tuple[int, ...], keep: frozenset[str] = frozenset()):
    """``params`` with every concrete floating leaf of shape ``batch`` whose values are all equal replaced by
    that one value (a scalar of the same dtype); other leaves, traced ones and those whose path is in ``keep``
    (``"terrain.cohesion"``), unchanged.

    A leaf's form is part of the compiled program. The diagnosis keeps the leaves its fits scale as arrays
    (:attr:`trackenv.diagnose.candidates.Candidate.varied_leaves`): on asphalt the cohesion is zero, so a
    scaled cohesion was equal across the batch and became a scalar, where on sand it stayed an array, and
    each terrain compiled its own programs. Kept as arrays, the programs are shared; a zero leaf gives the
    same numbers in either form to the last bit (tests/test_batch_forms.py), while a kept leaf whose values
    are equal and non-zero can round differently from its scalar form (by an ulp in a test batch).

    The model broadcasts a scalar parameter over the vehicles exactly as a constant (*b) array, so the
    simulation is the same. It was introduced when a (*b) ``drive_inertia`` or ``track_gauge`` made the
    substep 1.8-2.6x slower per vehicle (64 vehicles); the cause, XLA rewriting the division by J_eff as a
    multiplication and copying it into every contact point's fusion, is now avoided in the model itself
    (:func:`trackenv.physics.sums.divide_by_parameter`), and the gain left from scalars has not been
    measured since (docs/performance.md). Batches built by stacking per-test parameters
    (:func:`trackenv.compare.stack_trees`) share most leaves.
    """
    def one(path, x):
        if (isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and x.shape == batch and x.size > 1
                and jnp.issubdtype(x.dtype, jnp.floating)
                and not (keep and jax.tree_util.keystr(path, simple=True, separator=".") in keep)):
            values = np.asarray(x)
            if (values == values.flat[0]).all():
                return jnp.asarray(values.flat[0], x.dtype)
        return x
    return jax.tree_util.tree_map_with_path(one, params)


def simulate_batch(params, profile: VoltageProfile | SpeedProfile, n_steps: int, dt: float, substeps: int,
                   initial: State | None = None, *, t0: float = 0.0, unroll: int = 1) -> Trajectory:
    """The compiled simulation core on a batch of vehicles, without :func:`simulate`'s checks.

    One compiled program per (shapes, dtype, ``n_steps``, ``dt``, ``substeps``, ``t0``, ``unroll``, effects),
    cached by JAX; usable inside ``jax.jit``, ``jax.jacfwd``, ``jax.grad`` (traced parameters). Nothing is
    validated and nothing is raised: a diverged vehicle is only flagged (``diverged``/``t_diverged``).

    Args:
        params: :class:`trackenv.params.Params` whose floating leaves are scalars or (*b) arrays, the
            vehicles on the last axis (:func:`trackenv.compare.stack_trees` stacks per-vehicle parameters);
            its dtype sets the precision.
        profile: :class:`VoltageProfile` with ``t`` (K,) and ``volts`` (K, 2, *b) in ``params``'s dtype, or a
            :class:`SpeedProfile` (``omega`` (K, 2, *b)) for a speed-prescribed drive.
        n_steps: number of output steps (static).
        dt: output interval [s] (static).
        substeps: integration substeps per output step (static; :func:`n_substeps` from a largest substep).
        initial: initial :class:`State` with batch shape *b (default: at rest at the origin, heading 0,
            batch shape ``profile_values(profile).shape[2:]``).
        t0: time of the first sample [s] (static).
        unroll: scan unrolling of the substeps (static).

    Returns:
        :class:`Trajectory` with T = ``n_steps + 1`` samples: ``t`` (T,), each channel (T, *b), ``voltage``
        (T, 2, *b), ``diverged`` and ``t_diverged`` (*b).
    """
    params = shared_leaves_as_scalars(params, tuple(profile_values(profile).shape[2:]))
    return _run_batch(params, profile, n_steps, dt, substeps, initial, t0=t0, unroll=unroll)


def _run_batch(params, profile: VoltageProfile | SpeedProfile, n_steps: int, dt: float, substeps: int,
               initial: State | None = None, *, t0: float = 0.0, unroll: int = 1, parts: int = 1) -> Trajectory:
    """:func:`simulate_batch` on parameters whose shared leaves are already scalars (or are to stay arrays);
    ``parts``: the devices the batch is split over (the contact sums take the form of one device's share)."""
    if initial is None:
        initial = initial_state(params, tuple(profile_values(profile).shape[2:]))
    return _simulate_jit(params, profile, initial, n_steps=n_steps, dt=float(dt), substeps=substeps, t0=t0,
                         unroll=unroll, parts=parts)


def simulate(
    params,
    profile: VoltageProfile | SpeedProfile,
    t_end: float,
    *,
    dt: float = DEFAULT_DT,
    substep: float = DEFAULT_SUBSTEP,
    initial: State | None = None,
    on_divergence: Literal["raise", "flag"] = "raise",
) -> Trajectory:
    """Simulate the vehicle driven by ``profile`` from rest (or ``initial``) for ``t_end`` seconds.

    Args:
        params: :class:`trackenv.params.Params` (``load_params``); its dtype sets the precision.
        profile: a :class:`VoltageProfile` (voltages linear between samples, evaluated at every RK stage), or
            a :class:`SpeedProfile` (sprocket speeds prescribed; current and voltage follow, see there).
        t_end: simulated duration [s]; a multiple of ``dt``.
        dt: output interval [s] (default 0.05 s, the environments' control step).
        substep: largest integration substep [s] (default 0.5 ms, from the convergence study); at most
            ``dt`` and ``MAX_SUBSTEP``, otherwise ``ValueError``.
        initial: initial :class:`State` (default: at rest at the origin, heading 0).
        on_divergence: ``"raise"`` raises :class:`SimulationDiverged` naming the time of divergence;
            ``"flag"`` returns the trajectory with ``diverged``/``t_diverged`` set (also what happens
            under ``jax.vmap``/``jax.jit`` tracing, where nothing can be raised).

    Returns:
        :class:`Trajectory` with the state, the instrument channels and the voltages at each ``dt``.
    """
    if not isinstance(params, Params):
        raise TypeError(f"params must be a trackenv.Params (trackenv.load_params), got {type(params).__name__}")
    if initial is not None and not isinstance(initial, State):
        raise TypeError(f"initial must be a trackenv.State (trackenv.initial_state) or None, got {type(initial).__name__}")
    if not is_positive(t_end):
        raise ValueError(f"t_end must be a positive finite number of seconds, got {t_end!r}")
    if not is_positive(dt):
        raise ValueError(f"dt must be a positive finite number of seconds, got {dt!r}")
    check_substep(substep, dt, "dt")
    n_steps = int(round(t_end / dt))
    if abs(n_steps * dt - t_end) > 1e-9 * max(1.0, t_end) or n_steps < 1:
        raise ValueError(f"t_end = {t_end} s is not a whole number of output steps dt = {dt} s")
    if on_divergence not in ("raise", "flag"):
        raise ValueError(f"on_divergence must be 'raise' or 'flag', got {on_divergence!r}")
    if not isinstance(profile, (VoltageProfile, SpeedProfile)):
        raise TypeError(f"profile must be a trackenv.VoltageProfile or SpeedProfile, got {type(profile).__name__}")
    kind = type(profile)
    if not isinstance(profile.t, jax.core.Tracer):
        t_np, x_np = np.asarray(profile.t, np.float64), np.asarray(profile_values(profile), np.float64)
        if kind is VoltageProfile:
            validate_profile(t_np, x_np, float(np.max(np.asarray(params.vehicle.voltage_limit))))
        else:
            validate_speeds(t_np, x_np, float(np.min(np.asarray(physical_bounds(params)[1]))))
    dtype = params.dtype
    profile = kind(jnp.asarray(profile.t, dtype), jnp.asarray(profile_values(profile), dtype))
    batch = profile_values(profile).shape[2:]
    if initial is None:
        initial = initial_state(params, batch)
    substeps = n_substeps(dt, substep)
    traj = simulate_on_cores(params, profile, n_steps, dt, substeps, initial)
    if on_divergence == "raise" and not isinstance(traj.diverged, jax.core.Tracer):
        div = np.asarray(traj.diverged)
        if div.any():
            where = np.argwhere(div)
            td = np.asarray(traj.t_diverged)[tuple(where[0])] if div.ndim else float(traj.t_diverged)
            who = "" if div.ndim == 0 else f" (vehicle {tuple(int(i) for i in where[0])}, {int(div.sum())} of {div.size})"
            raise SimulationDiverged(
                f"simulation diverged: the state became non-finite or left the physical bounds (|i| > 10x stall "
                f"current, |omega| > 10x no-load speed) at t = {float(td):.3f} s{who}; "
                "pass on_divergence='flag' to get the trajectory up to that time"
            )
    return traj
