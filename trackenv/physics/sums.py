"""Sums over a vehicle's contact points and tracks, in the form XLA's CPU backend runs fastest.

The model sums element arrays (2, N, *b) (track, contact point, vehicles last) over their first two
axes: the track forces, the body force and moment (docs/model.md §5), the traction slopes of the
integrator's damping. :func:`contact_sum` computes ``a.sum(axes)`` in one of two forms:

- ``jnp.sum``: XLA's ``reduce``. For batches of :data:`UNROLL_MAX` vehicles and more, XLA's CPU
  backend hands these reductions to YNNPACK kernels, and this is the fastest form; for a single
  vehicle it is the form with the fewest kernels.
- unrolled additions of the axis's slices, first to last: elementwise work that XLA fuses with the
  arithmetic around it and vectorises along the vehicle axis. Between :data:`UNROLL_MIN` and
  :data:`UNROLL_MAX` vehicles XLA emits the ``reduce`` inside its loop fusions, and the fusions that
  hold it are the slowest of the substep (a profile per fusion, README Performance); there the unrolled
  form is 1.3-2.9x faster per vehicle (``benchmarks/bench_simulate.py --sums``). For one and two
  vehicles it is slower (measured the same way).

The two forms add in different orders, so they agree to rounding (float32: ~1e-7 relative), not bit
for bit; the form depends only on the batch size (and the split, below), so one batch shape always computes the
same way.

A program that XLA partitions over the host devices (the vector env's batched program, split by
:func:`trackenv.parallel.shard`) is traced with the whole batch's shape, but each device computes its own
share. Traced inside :class:`Partitioned` ``(n)``, :func:`contact_sum` picks the form for ``batch / n``
vehicles, the size each device runs (README Performance, "Both cores").
"""

from __future__ import annotations

import contextvars
import math

import jax.numpy as jnp
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
        total = jnp.take(a, 0, axis=ax)
        for i in range(1, a.shape[ax]):
            total = total + jnp.take(a, i, axis=ax)
        a = total
    return a
