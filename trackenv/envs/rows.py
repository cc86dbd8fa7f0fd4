"""One environment's compiled program, run row by row: the program the single env and the vector env share.

Why: XLA compiles a batched program (``jax.vmap`` over N environments) differently from the program of
one environment, and the float32 arithmetic of an environment then depends on the batch it is in: the
operations are fused, vectorised and simplified per shape (a batch of one compiles differently from a
batch of two), LLVM contracts a multiply and an add into one FMA or not depending on the code around
them, and the last elements of a vectorised loop can run through a differently compiled remainder.
Measured on the go-stop task: the single env and vmapped batches of 1, of 2-8 (which agree with one
another), of 64 and of 512 split over 2 devices round differently (~1e-7 after one step, up to 1-3 % of
a channel's range within 1.5 s, through the stick-slip of the contact model); already the Janosi factor
1-exp(-|j|/K) of the same inputs differs in the last bit between the single and the batched program,
with or without FMA; and within one batch of 64 two of the last eight environments differ from the same
episode run in a leading position (not without FMA).

What: every environment is advanced by the **same compiled loop body**, one environment's reset or step
on its row of the flat state (:mod:`.flat`), inside a ``jax.lax.fori_loop`` over the rows whose trip
count is a runtime argument (so that XLA can neither unroll nor remove the loop for one row). The body
always computes the same thing: the step with the autoreset mode as a runtime value
(:func:`~trackenv.envs.core.step_autoreset`), and the full packed row (physics and final result
included; the caller drops what it does not need). The single env runs it on one row, the vector env on
its N rows, and a vector env split over the host devices runs the same single-device program on each
device's share (:func:`trackenv.parallel.run_split`). An environment's arithmetic is then that body's,
whatever the batch: the same seed and actions give bit-identical observations, rewards, flags and
physical state in ``gym.make`` and in any sub-environment of ``TrackVectorEnv``.

Cost: the rows are stepped one after another, so a vector env of N costs about N single-env steps (the
batched programs of ``physics_batching="vmap"/"native"`` are faster, docs/performance.md). Everything a
row needs, the parameters' derived quantities included, is computed inside the loop body, so that a loop
XLA emits as one kernel leaves only a handful of kernels around it per call.

Shapes: ``sf`` (rows, n_float) float32 and ``si`` (rows, n_int) int32 (the state codec's vectors);
``packed`` (rows, K) float32 in the layout of :func:`trackenv.envs.core.pack` with physics and final
result (``gym_env.Layout(params, state, with_physics=True, final_obs=True)``); ``actions`` (rows, 2)
float32 in action units; ``seeds`` (rows,) uint32; ``mask`` (rows,) bool; ``count`` int32 scalar
(rows 0 .. count-1 are computed); ``mode`` int32 scalar, an index of ``core.AUTORESET_MODES``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import core
from .flat import FlatCodec


def mode_index(mode: str) -> np.ndarray:
    """The int32 runtime value of an autoreset mode of :data:`core.AUTORESET_MODES`."""
    return np.int32(core.AUTORESET_MODES.index(mode))


def _over_rows(one, count, rows: int, *row_args):
    """``one(*row_k)`` -> (f, i, packed) for rows k < ``count``, written into copies of ``row_args[:2]``.

    The state and the packed output are carried as flat vectors and each row is a ``dynamic_slice`` of
    them: XLA's cost analysis, which decides whether the loop is emitted as one kernel, then counts the
    bytes of the row each kernel reads, not of the whole (rows, n) array (for the lane change 0.30 MB
    against 1.5 MB per step).
    """
    sf, si = row_args[0], row_args[1]
    n_f, n_i = sf.shape[1], si.shape[1]
    width = jax.eval_shape(one, *(x[0] for x in row_args))[2].shape[0]
    carry = (sf.reshape(-1), si.reshape(-1), jnp.zeros((rows * width,), jnp.float32))

    def body(k, carry):
        f_all, i_all, p_all = carry
        f = jax.lax.dynamic_slice(f_all, (k * n_f,), (n_f,))
        i = jax.lax.dynamic_slice(i_all, (k * n_i,), (n_i,))
        f, i, p = one(f, i, *(jax.lax.dynamic_index_in_dim(x, k, keepdims=False) for x in row_args[2:]))
        return (jax.lax.dynamic_update_slice(f_all, f, (k * n_f,)), jax.lax.dynamic_update_slice(i_all, i, (k * n_i,)),
                jax.lax.dynamic_update_slice(p_all, p, (k * width,)))

    f_all, i_all, p_all = jax.lax.fori_loop(0, count, body, carry)
    return f_all.reshape(rows, n_f), i_all.reshape(rows, n_i), p_all.reshape(rows, width)


_FNS: dict = {}


def jitted(scodec: FlatCodec, pcodec: FlatCodec):
    """The jitted ``(reset_rows, step_rows)`` of one env structure; cached by structure (see the module docstring).

    ``reset_rows(sf, si, seeds, mask, count, pf, pi)``: rows with ``mask`` start an episode from their
    seed (``core.reset(PRNGKey(seed))``), the others keep their state; returns (sf, si, packed).
    ``step_rows(sf, si, actions, mode, count, pf, pi)``: one :func:`core.step_autoreset` per row;
    returns (sf, si, packed).
    """
    key = (scodec, pcodec)
    if key in _FNS:
        return _FNS[key]

    def _row_params(f, i, pf, pi):
        # The parameters are unravelled inside the row loop, tied to the row's state by an optimisation
        # barrier. Without it, XLA's loop-invariant code motion lifts everything computed from the parameters
        # alone out of the row loop, into ~50 separate kernels per call (each a task of XLA's CPU runtime),
        # whereas the loop itself is emitted as one kernel (``parallel.configure_small_loops``). Same
        # arithmetic: the trajectories are bit-identical (docs/performance.md).
        f, i, pf, pi = jax.lax.optimization_barrier((f, i, pf, pi))
        return f, i, pcodec.unravel(pf, pi)

    def reset_rows(sf, si, seeds, mask, count, pf, pi):
        def one(f, i, seed, reset_it):
            f, i, params = _row_params(f, i, pf, pi)
            state, out = core.reset(jax.random.PRNGKey(seed), params)
            nf, ni = scodec.ravel(state)
            return jnp.where(reset_it, nf, f), jnp.where(reset_it, ni, i), core.pack(state, out, params, final=out)

        return _over_rows(one, count, sf.shape[0], sf, si, seeds, mask)

    def step_rows(sf, si, actions, mode, count, pf, pi):
        def one(f, i, a):
            f, i, params = _row_params(f, i, pf, pi)
            state, out, final = core.step_autoreset(scodec.unravel(f, i), a, params, mode)
            nf, ni = scodec.ravel(state)
            return nf, ni, core.pack(state, out, params, final=final)

        return _over_rows(one, count, sf.shape[0], sf, si, actions)

    _FNS[key] = (jax.jit(reset_rows), jax.jit(step_rows))
    return _FNS[key]
