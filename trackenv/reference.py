"""Tight-tolerance adaptive reference solutions with diffrax (for verification, not for speed).

Integrates the *full* state derivative (``physics.model.derivative``) with an implicit adaptive
solver (Kvaerno5, L-stable ESDIRK) under a PID step-size controller, stepping exactly onto the
voltage profile's breakpoints. Use float64 parameters.
"""

from __future__ import annotations

import diffrax
import jax.numpy as jnp
import numpy as np

from .physics.model import State, derivative, initial_state
from .simulate import VoltageProfile


def reference_solution(params, profile: VoltageProfile, t_end: float, dt: float = 0.05,
                       rtol: float = 1e-8, atol: float = 1e-10, max_steps: int = 2_000_000,
                       initial: State | None = None):
    """Return (t, states) sampled every ``dt`` from a Kvaerno5 solve at tolerance ``rtol``/``atol``."""
    n = int(round(t_end / dt))
    ts = jnp.arange(n + 1, dtype=params.dtype) * dt
    y0 = initial if initial is not None else initial_state(params)
    jumps = jnp.asarray(np.asarray(profile.t), params.dtype)

    def field(t, y, args):
        return derivative(y, profile(t), params)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Kvaerno5(),
        t0=0.0,
        t1=float(ts[-1]),
        dt0=1e-6,
        y0=y0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=jumps),
        max_steps=max_steps,
    )
    return ts, sol.ys, sol.stats
