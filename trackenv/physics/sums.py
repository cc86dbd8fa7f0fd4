"""Sums over a vehicle's contact points and tracks, and divisions by a vehicle parameter, in the forms
XLA's CPU backend runs fastest (:func:`contact_sum`, :func:`divide_by_parameter`).

The model sums element arrays (2, N, *b) (track, contact point, vehicles last) over their first two
axes: the track forces, the body force and moment (docs/model.md §5), the traction slopes of the
integrator's damping. :func:`contact_sum` computes ``a.sum(axes)`` in one of two forms:

- ``jnp.sum``: XLA's ``reduce``. For batches of :data:`UNROLL_MAX` vehicles and more, XLA's CPU
  backend hands these reductions to YNNPACK kernels, and this is the fastest form; for a single
  vehicle it is the form with the fewest kernels.
- unrolled additions of the axis's slices, first to last: elementwise work that XLA fuses with the
  arithmetic around it and vectorises along the vehicle axis. Between :data:`UNROLL_MIN` and
  :data:`UNROLL_MAX` vehicles XLA emits the ``reduce`` inside its loop fusions, and the fusions that
  hold it are the slowest of the substep (a profile per fusion, docs/performance.md); there the unrolled
  form is 1.3-2.9x faster per vehicle (``benchmarks/bench_simulate.py --sums``). For one and two
  vehicles it is slower (measured the same way).

The two forms add in different orders, so they agree to rounding (float32: ~1e-7 relative), not bit
for bit; the form depends only on the batch size (and the split, below), so one batch shape always computes the
same way.

A program that XLA partitions over the host devices (the vector env's batched program, split by
:func:`trackenv.parallel.shard`) is traced with the whole batch's shape, but each device computes its own
share. Traced inside :class:`Partitioned` ``(n)``, :func:`contact_sum` picks the form for ``batch / n``
vehicles, the size each device runs (docs/performance.md, "Both cores").
"""

from __future__ import annotations

import contextvars
import math

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float

UNROLL_MIN = 3  # vehicles: from here the unrolled form is the faster (measured, module docstring)
UNROLL_MAX = 160  # vehicles: from here XLA's CPU backend runs the reductions as YNNPACK kernels


_PARTS = contextvars.ContextVar("contact_sum_parts", default=1)


class Partitioned:
    """Context manager: while a program is traced inside ``with Partitioned(parts):``, :func:`contact_sum`
    chooses its form for a batch split into ``parts`` equal shares (one per device), not for the whole
    batch. Nested contexts: the innermost holds."""

    def __init__(self, parts: int) -> None:
        self.parts = max(1, int(parts))
        self._token = None

    def __enter__(self) -> None:
        self._token = _PARTS.set(self.parts)

    def __exit__(self, *exc) -> None:
        _PARTS.reset(self._token)


def unrolled(batch: int) -> bool:
    """Whether :func:`contact_sum` unrolls its sums for ``batch`` vehicles."""
    return UNROLL_MIN <= batch < UNROLL_MAX


def device_batch(shape: tuple[int, ...], nb: int) -> int:
    """Vehicles one device computes of an array of ``shape`` with ``nb`` trailing vehicle axes: the whole
    batch, or its share inside :class:`Partitioned`; 1 when ``nb`` is 0."""
    return -(-math.prod(shape[len(shape) - nb:]) // _PARTS.get()) if nb else 1


def contact_sum(a: Float[Array, " ..."], axes: int | tuple[int, ...], nb: int) -> Float[Array, " ..."]:
    """``a.sum(axes)`` over small leading axes (tracks, contact points) of an array with ``nb`` trailing
    batch axes (the vehicles), in the faster form for its batch size (module docstring)."""
    axes = (axes,) if isinstance(axes, int) else tuple(axes)
    if not unrolled(device_batch(a.shape, nb)):
        return jnp.sum(a, axis=axes)
    for ax in sorted((ax % a.ndim for ax in axes), reverse=True):  # the highest first: lower indices stay valid
        # static slices: jnp.take added an out-of-bounds select to each (386 selects in a 64-vehicle program)
        total = lax.index_in_dim(a, 0, ax, keepdims=False)
        for i in range(1, a.shape[ax]):
            total = total + lax.index_in_dim(a, i, ax, keepdims=False)
        a = total
    return a


def divide_by_parameter(numerator: Float[Array, " ..."], parameter: Float[Array, " *#b"]) -> Float[Array, " ..."]:
    """``numerator / parameter`` for a vehicle parameter (a scalar, or one value per vehicle on the
    trailing axes), computed as a division in every batch.

    XLA's CPU fusion treats a division as expensive and does not copy it into the fusions that read its
    result once per contact point; a multiplication it does copy. XLA's algebraic simplifier rewrites
    x / broadcast(d) as x * broadcast(1/d) when d is an array, so a batch whose J_eff, mass or yaw
    inertia differed per vehicle lost that boundary: the per-track and body chains that end in these
    divisions (the contact sums, the drive torques, the body forces) were recomputed inside the
    element-level fusions, once for each of the N contact points. The substep ran 2.6x slower per
    vehicle with a per-vehicle J_eff (64 vehicles; docs/performance.md). The divisions by the mass and the
    yaw inertia take the same form for the same reason; no slowdown of their own was measured (a
    per-vehicle mass cost 1.8x at 16 vehicles through XLA's small-loop limit instead,
    :data:`trackenv.parallel.SMALL_LOOP_BYTES`). Adding 0 * numerator gives the divisor the numerator's shape without
    a broadcast, so the division stays one. The value is the same as ``numerator / parameter`` up to the
    rounding of one division; a non-finite numerator still gives a non-finite result.
    """
    return numerator / (parameter + 0.0 * numerator)
