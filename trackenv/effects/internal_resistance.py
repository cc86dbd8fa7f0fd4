"""``internal_resistance``: the form of the internal track resistance (docs/model.md §8).

Force law (replaces the base model's tau_int of docs/model.md §5 through the ``forces`` hook)::

    tau_int(omega) = b0 * smoothsign(omega; 0.05 rad/s) + b1 * omega + b2 * omega |omega|     [N m]

The family contains the thesis's two models as special cases: the *constant* model (5.10,
Table 5.4: b0 = b*_int = 0.78 N m on dry sand, b1 = 0) and the *viscous* model (3.41, Table 5.3:
b0 = 0, b1 = b_int = 0.076 N m s/rad), and in between the *speed-linear* law (Wong, "Theory of Ground
Vehicles", §6 internal resistance of tracks, which grows roughly linearly with speed: rolling
resistance of road wheels plus a speed term from belt flexing/friction in the track's joints). The
quadratic term b2 (default 0) covers resistances that grow faster than linearly with speed (hysteresis
of the belt and churning of soil carried round the sprockets; Wong's empirical internal-resistance
fits carry a speed-squared term for high-speed tracked vehicles).

At steady straight driving the sprocket balance (4.1) gives the current

    i = (b0 + b1 omega + b_eff omega + tau_stick + tau_back) / alpha,

with tau_back = r_s' * (compaction resistance)/1 per track (the small traction term).

Default (calibration): least squares to the two field anchors of thesis §5.4.1 (docs/model.md §8):
1.98 A at 1.1 m/s (11.8 V) and 2.23 A at 2 m/s (21 V) on dry sand, with b1 >= 0. The measured
current rises *less* with speed than b_eff alone predicts, so the fit lands on b1 = 0 (a constant law)
with a larger constant b0 = 0.88 N m than Table 5.4's 0.78 N m; the viscous law (≈3.1 A at 2 m/s)
is rejected by the data. Pass ``b0``/``b1`` (``get_effect``) to test other forms.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..physics.motor import OMEGA_SMOOTHING
from ..physics.terramechanics import smoothsign
from .base import Effect


class InternalResistance(Effect):
    """tau_int = b0 smoothsign(omega; 0.05) + b1 omega + b2 omega|omega|, replacing the base model's tau_int."""

    id: ClassVar[str] = "internal_resistance"
    bounds: ClassVar[dict] = {"b0": (0.0, 5.0), "b1": (0.0, 1.0), "b2": (0.0, 0.1)}

    b0: jax.Array  # N m, constant (Coulomb) part
    b1: jax.Array  # N m s/rad, speed-linear (viscous) part
    b2: jax.Array | float = 0.0  # N m s^2/rad^2, quadratic part

    @classmethod
    def default(cls, dtype=jnp.float32):
        return cls(b0=jnp.asarray(0.88, dtype), b1=jnp.asarray(0.0, dtype), b2=jnp.asarray(0.0, dtype))

    def torque(self, omega):
        """tau_int [N m] at sprocket speeds ``omega`` [rad/s]."""
        return self.b0 * smoothsign(omega, OMEGA_SMOOTHING) + self.b1 * omega + self.b2 * omega * jnp.abs(omega)

    def forces(self, ctx, forces, tau_int):
        return forces, self.torque(ctx.state.omega)
