"""``pitch_load_transfer``: longitudinal load transfer in acceleration and braking (docs/model.md §4, §8).

The planar base model keeps p_x = 0; the thesis's ADAMS body pitched. Here the pressure under the tracks
gets a longitudinal gradient p_x from the pitch-moment balance of the rigid body about its CG (Wong,
"Theory of Ground Vehicles", §3.1 / §6 normal load distribution; Bekker): the ground forces act h below the
CG, so Σ_i,k F_n,i x_i + h Σ F_x = 0, i.e. Σ F_n,i x_i = −m a_x h. With F_n,i = A_i (p0 + p_y y_k + p_x x_i)
and the trapezoid elements symmetric about x = 0 (Σ A_i x_i = 0)::

    p_x · 2 Σ_i A_i x_i² = −m a_x h   ⇒   p_x = −m a_x h / (2 Σ_i A_i x_i²)       [Pa/m]

(for a continuous uniform track Σ A_i x_i² → b L³/12, p_x = −6 m a_x h / (b L³)). Totals Σ F_n = m g and the
roll moment are unchanged (while no element unloads; F_n = max(0, ·) as in the base model).

a_x is the body's longitudinal acceleration du/dt − v r = (Σ F_long + Σ compaction + body_x)/m from the
forces of the previous evaluation, filtered by a first-order lag (the body's pitch response):
d a_f/dt = (a_x − a_f)/τ, state a_f (*b) [m/s²], τ = 0.05 s (default). Applied additively
(``normal + A_i p_x x_i``, clipped at 0), which equals ``loads.normal_loads(..., pitch_gradient=p_x)``
and keeps the changes of effects earlier in the tuple.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..physics.sums import contact_sum, divide_by_parameter
from .base import Effect


def pitch_gradient(mass, cg_height, area, x, accel):
    """p_x [Pa/m] from Σ F_n x = −m a_x h over both tracks; area, x (1, N, *b), accel (*b)."""
    moment = area * x * x
    s2 = contact_sum(moment, (0, 1), moment.ndim - 2)  # (*b) Σ_i A_i x_i^2 of one track
    return -mass * accel * cg_height / (2.0 * s2)


class PitchLoadTransfer(Effect):
    """Filtered longitudinal acceleration state and the resulting longitudinal pressure gradient."""

    id: ClassVar[str] = "pitch_load_transfer"
    bounds: ClassVar[dict] = {"time_constant": (1e-3, 1.0), "height_factor": (0.0, 3.0)}

    time_constant: jax.Array  # s, τ of the acceleration filter
    height_factor: jax.Array  # -, scales the CG height h (1 = vehicle cg_height)

    @classmethod
    def default(cls, dtype=jnp.float32):
        return cls(time_constant=jnp.asarray(0.05, dtype), height_factor=jnp.asarray(1.0, dtype))

    def initial_state(self, params, batch_shape):
        return jnp.zeros(tuple(batch_shape), params.dtype)

    def state_rate(self, ctx, forces):
        long, comp = forces.longitudinal, forces.compaction
        fx = contact_sum(long, (0, 1), long.ndim - 2) + contact_sum(comp, 0, comp.ndim - 1) + forces.body_x
        accel = divide_by_parameter(fx, ctx.params.vehicle.mass)  # a division in every batch
        return (accel - ctx.state.extra[self.id]) / self.time_constant

    def gradient(self, ctx):
        veh = ctx.params.vehicle
        return pitch_gradient(veh.mass, veh.cg_height * self.height_factor, ctx.kin.area, ctx.kin.x,
                              ctx.state.extra[self.id])

    def normal_loads(self, ctx, normal):
        return jnp.maximum(normal + ctx.kin.area * self.gradient(ctx) * ctx.kin.x, 0.0)
