"""Flatten pytrees to two arrays (float32 and int32) for cheap jitted calls from Python.

Passing an :class:`~trackenv.envs.core.EnvState` and :class:`~trackenv.envs.core.EnvParams` (about
90 leaves, many in equinox modules whose flattening runs in Python) to a jitted function costs
~150 us per call on this machine, more than a coarse physics step. The wrappers therefore keep the
state and the parameters as one float32 and one int32 vector each (bool and uint32 leaves are
bit-cast to int32), and unflatten them *inside* the jitted function, where it is free.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np


class FlatCodec:
    """Static description of a pytree's leaves: ``ravel`` and ``unravel`` (jnp, or numpy on the host)."""

    def __init__(self, example):
        leaves, self.treedef = jax.tree.flatten(example)
        self.shapes = tuple(tuple(x.shape) if hasattr(x, "shape") else tuple(np.shape(x)) for x in leaves)
        self.dtypes = tuple(np.dtype(getattr(x, "dtype", np.asarray(x).dtype)) for x in leaves)
        self.is_float = tuple(bool(np.issubdtype(d, np.floating)) for d in self.dtypes)
        for d in self.dtypes:
            if d.itemsize > 4 or not (np.issubdtype(d, np.floating) or np.issubdtype(d, np.integer) or d == np.bool_):
                raise TypeError(f"FlatCodec supports 32-bit float/int and bool leaves, got {d}")
        self.sizes = tuple(int(math.prod(s)) for s in self.shapes)
        f_off = i_off = 0
        self.offsets = []
        for n, fl in zip(self.sizes, self.is_float):
            if fl:
                self.offsets.append(f_off)
                f_off += n
            else:
                self.offsets.append(i_off)
                i_off += n
        self.n_float, self.n_int = f_off, i_off
        self.key = (self.treedef, self.shapes, self.dtypes)

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, FlatCodec) and self.key == other.key

    # -- inside jit ------------------------------------------------------------------------------

    def ravel(self, tree):
        leaves = self.treedef.flatten_up_to(tree)
        fl = [jnp.asarray(x, jnp.float32).ravel() for x, f in zip(leaves, self.is_float) if f]
        it = [_to_int32(jnp.asarray(x)).ravel() for x, f in zip(leaves, self.is_float) if not f]
        fvec = jnp.concatenate(fl) if fl else jnp.zeros((0,), jnp.float32)
        ivec = jnp.concatenate(it) if it else jnp.zeros((0,), jnp.int32)
        return fvec, ivec

    def unravel(self, fvec, ivec):
        leaves = []
        for shape, dtype, n, off, fl in zip(self.shapes, self.dtypes, self.sizes, self.offsets, self.is_float):
            if fl:
                leaves.append(fvec[off:off + n].reshape(shape).astype(dtype))
            else:
                raw = ivec[off:off + n].reshape(shape)
                leaves.append(_from_int32(raw, dtype))
        return self.treedef.unflatten(leaves)

    # -- on the host (numpy, no compilation) -------------------------------------------------------

    def ravel_host(self, tree):
        leaves = self.treedef.flatten_up_to(tree)
        fl = [np.asarray(x, np.float32).ravel() for x, f in zip(leaves, self.is_float) if f]
        it = [_to_int32_np(np.asarray(x)).ravel() for x, f in zip(leaves, self.is_float) if not f]
        fvec = np.concatenate(fl) if fl else np.zeros((0,), np.float32)
        ivec = np.concatenate(it) if it else np.zeros((0,), np.int32)
        return fvec, ivec

    def unravel_host(self, fvec, ivec, batch: tuple = ()):
        """Numpy leaves; ``batch`` leading axes allowed (fvec (*batch, n_float))."""
        fvec, ivec = np.asarray(fvec), np.asarray(ivec)
        leaves = []
        for shape, dtype, n, off, fl in zip(self.shapes, self.dtypes, self.sizes, self.offsets, self.is_float):
            src = fvec if fl else ivec
            raw = src[..., off:off + n].reshape(tuple(batch) + shape)
            leaves.append(raw.astype(dtype) if fl else _from_int32_np(raw, dtype))
        return self.treedef.unflatten(leaves)


def _to_int32(x):
    if x.dtype == jnp.bool_:
        return x.astype(jnp.int32)
    if x.dtype == jnp.uint32:
        return jax.lax.bitcast_convert_type(x, jnp.int32)
    return x.astype(jnp.int32)


def _from_int32(x, dtype):
    if dtype == np.bool_:
        return x != 0
    if dtype == np.uint32:
        return jax.lax.bitcast_convert_type(x, jnp.uint32)
    return x.astype(dtype)


def _to_int32_np(x):
    if x.dtype == np.uint32:
        return x.view(np.int32)
    return x.astype(np.int32)


def _from_int32_np(x, dtype):
    if dtype == np.bool_:
        return x != 0
    if dtype == np.uint32:
        return np.ascontiguousarray(x).view(np.uint32)
    return x.astype(dtype)


_CACHE: dict = {}


def codecs(params):
    """(state codec, params codec) for ``params`` (an EnvParams); cached by structure."""
    from . import core  # noqa: PLC0415

    pc = FlatCodec(params)
    key = ("codecs", pc)
    if key not in _CACHE:
        st, _ = jax.eval_shape(core.reset, jax.ShapeDtypeStruct((2,), jnp.uint32), params)
        _CACHE[key] = (FlatCodec(st), pc)
    return _CACHE[key]
