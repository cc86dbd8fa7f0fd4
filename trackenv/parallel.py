"""Both cores for batches: the vehicle axis split across XLA host devices.

XLA's CPU backend runs one computation on one core. With ``--xla_force_host_platform_device_count=n``
it exposes n CPU devices, and a batch whose vehicle axis is sharded over them (``jax.sharding``) is
partitioned by XLA into n per-core programs that run in parallel: one substep loop per core, no
communication until the results are gathered.

That flag is read once, when JAX initialises its backends. :func:`configure_host_devices` (called
when ``trackenv`` is imported) therefore sets it only if the backends are not yet initialised and
``XLA_FLAGS`` does not set it already; importing trackenv *after* a first JAX computation leaves one
device, and batches then run on one core (nothing else changes). ``TRACKENV_HOST_DEVICES=1`` opts out.
Single vehicles stay on the default device (one core). A simulation batch is split from
:data:`MIN_PER_DEVICE` vehicles per core (:func:`trackenv.simulate.simulate_on_cores`, which serves
``simulate`` and the diagnosis's fits and gathers its outputs back onto the default device); the vector
env's batched program, whose state stays split from one step to the next, from
:data:`MIN_ENVS_PER_DEVICE` environments per core.

A program that must compute every vehicle exactly as it computes one (the vector env's row loop,
:mod:`trackenv.envs.rows`) is not partitioned by XLA but run as the same single-device program on each
device's share of the rows (:func:`run_split`, from :data:`MIN_ROWS_PER_DEVICE` rows per device).

**Small loops as one kernel.** XLA's CPU runtime runs each fused kernel of a loop body as a separate
task, and a single vehicle's substep is about 50 small kernels, so the task overhead is a large part of
its cost. XLA can instead emit a small while loop (by the bytes its body accesses) with everything in
it as one function (its small-while-loop hoisting pass, 1 kB by default). :func:`configure_small_loops`
(called with :func:`configure_host_devices`) raises that limit to :data:`SMALL_LOOP_BYTES`, through
``--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold``, under the same conditions (JAX not
started, the option not already in ``XLA_FLAGS``); ``TRACKENV_SMALL_LOOP_BYTES=0`` opts out. The limit
takes one vehicle's simulation (one trajectory ran 1.6x faster with it), the single env's whole step, row
loop included, on every task (0.03-0.30 MB by XLA's cost analysis; the path tasks' reference polylines
make theirs the largest), and every batch whose contact-point sums are unrolled (up to 159 vehicles per
device; from 160 they are a library reduce, :mod:`trackenv.physics.sums`, that the pass does not take).
At 8 MB, against the former 0.4 MB (which took batches of up to about 12 vehicles): ``simulate`` on
batches of 32-128 vehicles ran 1.3-1.5x faster and the 256-environment vector env (the training
configuration) 1.3-1.6x; the batched vector env with 64 or 128 environments on one device ran 0.85-0.97x
as fast (its row loop, the default, did not change) (docs/performance.md).
"""

from __future__ import annotations

import os
import re

MIN_PER_DEVICE = 4  # vehicles per core below which a simulation batch is not split (measured, docs/performance.md)
SHARE_ALIGN = 8  # vehicles: a split batch's share per core is padded to a multiple of this (from 4x it; measured, docs/performance.md)
MAX_PER_DEVICE = 320  # per core: a larger simulation batch, or batched vector env, runs in chunks (cache-sized; docs/performance.md)
MIN_ENVS_PER_DEVICE = 128  # the same for the vector env's batched program, whose state stays split between steps (measured, README)
MIN_ROWS_PER_DEVICE = 16  # the same for run_split's row loops, which gain from far fewer (measured, README)
MAX_HOST_DEVICES = 8
SMALL_LOOP_BYTES = 8_000_000  # XLA's small-while-loop limit [bytes accessed by the loop] (measured, README)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _add_xla_flag(present: str, flag: str, env: str, default: int, unit: str, minimum: int) -> None:
    """Append ``flag`` (formatted with n) to ``XLA_FLAGS``; n from the environment variable ``env`` (an
    integer number of ``unit``), else ``default``. Nothing if ``XLA_FLAGS`` already holds ``present``, if
    n < ``minimum`` or if JAX has started (the flags are read once, when its backends initialise)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if present in flags:
        return
    want = os.environ.get(env)
    try:
        n = int(want) if want else default
    except ValueError:
        raise ValueError(f"{env} must be an integer number of {unit}, got {want!r}") from None
    if n < minimum or _jax_started():
        return
    os.environ["XLA_FLAGS"] = (flags + " " + flag.format(n)).strip()


def _jax_started() -> bool:
    try:
        from jax._src import xla_bridge
        return xla_bridge.backends_are_initialized()
    except (ImportError, AttributeError):  # pragma: no cover - other JAX versions: treat as started
        return True


def configure_host_devices() -> None:
    """Expose one XLA CPU device per core (at most ``MAX_HOST_DEVICES``) if JAX has not started yet."""
    _add_xla_flag("xla_force_host_platform_device_count", "--xla_force_host_platform_device_count={}",
                  "TRACKENV_HOST_DEVICES", min(_cores(), MAX_HOST_DEVICES), "devices", minimum=2)


def configure_small_loops() -> None:
    """Let XLA emit loops of up to ``SMALL_LOOP_BYTES`` as one kernel, if JAX has not started yet."""
    _add_xla_flag("xla_backend_extra_options",
                  "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={}",
                  "TRACKENV_SMALL_LOOP_BYTES", SMALL_LOOP_BYTES, "bytes", minimum=1)


def substep_loop_is_one_kernel(compiled) -> bool:
    """True if a compiled simulation (``jax.stages.Compiled``) emits its substep loop as one kernel: a call
    XLA marks ``xla_cpu_small_call`` that carries per-track element arrays (float (2, N, ...))."""
    return any("xla_cpu_small_call" in line and re.search(r"f(32|64)\[2,\d+", line)
               for line in compiled.as_text().splitlines())


def cpu_devices():
    import jax
    return [d for d in jax.devices() if d.platform == "cpu"] or jax.devices()


def chunk_limit() -> int | None:
    """Vehicles (environments) per device above which a batch runs in chunks: ``MAX_PER_DEVICE`` on a CPU,
    where a core's share should stay in its cache; None (never chunked) on an accelerator, which wants the
    whole batch at once."""
    import jax
    return MAX_PER_DEVICE if jax.default_backend() == "cpu" else None


def chunk_size(batch: int) -> int:
    """Vehicles (environments) per chunk of a batch: the whole batch, or, above :func:`chunk_limit` per device,
    equal chunks of at most that many per device, each device's share a multiple of ``SHARE_ALIGN`` (the last
    chunk padded by the caller). One rule for ``simulate``'s batches and the batched vector env."""
    n_dev, limit = len(cpu_devices()), chunk_limit()
    if limit is None or batch <= n_dev * limit:  # an accelerator takes the whole batch at once
        return batch
    k = -(-batch // (n_dev * limit))
    per = -(-batch // (k * n_dev))
    return n_dev * (per + (-per) % SHARE_ALIGN)


def split_count(batch: int, min_per_device: int | None = None) -> int:
    """How many devices a batch of ``batch`` vehicles is split over (1: not split).

    All host devices when every one gets at least ``min_per_device`` (default ``MIN_PER_DEVICE``)
    vehicles and the batch divides evenly, else 1.
    """
    n = len(cpu_devices())
    per = MIN_PER_DEVICE if min_per_device is None else min_per_device
    if n <= 1 or batch < n * per or batch % n:
        return 1
    return n


def batch_sharding(ndim: int, axis: int, batch: int, min_per_device: int | None = None):
    """A ``NamedSharding`` splitting ``axis`` of an ``ndim``-array over the devices, or None."""
    n = split_count(batch, min_per_device)
    if n == 1 or ndim == 0:
        return None
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec
    mesh = Mesh(np.array(cpu_devices()[:n]), ("vehicles",))
    spec = [None] * ndim
    spec[axis % ndim] = "vehicles"
    return NamedSharding(mesh, PartitionSpec(*spec))


def host_movable(x) -> bool:
    """Whether the array ``x`` can be sliced, padded, repeated and placed on the devices from numpy without
    changing what jax sees: concrete (not traced) and not weakly typed. Done eagerly by ``jax.numpy``, each of
    those operations compiles a small program for every shape it meets."""
    import jax
    import numpy as np
    return (isinstance(x, (jax.Array, np.ndarray)) and not isinstance(x, jax.core.Tracer)
            and not getattr(x, "weak_type", False))


def shard(tree, batch: int, axis: int = -1, min_per_device: int | None = None):
    """Place every array leaf of ``tree`` whose ``axis`` has length ``batch`` split over the devices
    (other leaves replicated); unchanged if the batch is not split (``split_count(batch, min_per_device)``)."""
    import jax
    n = split_count(batch, min_per_device)
    if n == 1:
        return tree
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec
    mesh = Mesh(np.array(cpu_devices()[:n]), ("vehicles",))

    def put(x):
        x = np.asarray(x) if host_movable(x) else jax.numpy.asarray(x)  # placed from the host (host_movable)
        if x.ndim and x.shape[axis] == batch:
            return jax.device_put(x, batch_sharding(x.ndim, axis, batch, min_per_device))
        return jax.device_put(x, NamedSharding(mesh, PartitionSpec()))

    return jax.tree.map(put, tree)


def run_split(fn, rows: tuple, shared: tuple, n: int) -> tuple:
    """``fn(*rows, *shared)`` with the rows split over the first ``n`` host devices.

    Unlike :func:`shard`, XLA does not partition ``fn``: the same single-device program (one jitted
    ``fn``, compiled once per device) runs on each device's share of the rows, asynchronously, so each
    row is computed exactly as in an unsplit call. ``rows``: arrays (numpy, or jax arrays as this
    function returns them) with the same leading row axis, whose length ``n`` divides; ``shared``:
    arguments every device gets whole; ``n``: from ``split_count(rows, MIN_ROWS_PER_DEVICE)`` (1: one
    call on the default device). Returns ``fn``'s outputs (each with a leading row axis), joined into
    arrays split over the devices.
    """
    if n == 1:
        return fn(*rows, *shared)
    import jax
    import numpy as np
    from jax.sharding import Mesh, NamedSharding, PartitionSpec
    devices = cpu_devices()[:n]
    batch = rows[0].shape[0]
    m = batch // n

    def part(x, k, device):
        if isinstance(x, jax.Array) and len(x.sharding.device_set) == n:
            for s in x.addressable_shards:
                if s.device == device:
                    return s.data
        return jax.device_put(np.asarray(x)[k * m:(k + 1) * m], device)

    outs = [fn(*(part(x, k, d) for x in rows), *(jax.device_put(x, d) for x in shared)) for k, d in enumerate(devices)]
    mesh = Mesh(np.array(devices), ("vehicles",))

    def join(parts):
        spec = PartitionSpec("vehicles", *([None] * (parts[0].ndim - 1)))
        return jax.make_array_from_single_device_arrays((batch,) + parts[0].shape[1:], NamedSharding(mesh, spec),
                                                        list(parts))

    return tuple(join(parts) for parts in zip(*outs))
