"""``lateral_friction_radius``: lateral resistance from a turning-radius-dependent coefficient (docs/model.md §8).

Thesis §3.4.4 (3.24) and §6.1.2: F_Lat,i = μ_t(ρ) F_n,i, the lateral coefficient falling with the turning
radius (Kar 1987, "Prediction of track forces in skid-steering of military tracked vehicles",
J. Terramechanics 24; Wong & Chiang 2001, "A general theory for skid steering of tracked vehicles on
firm ground", Proc. IMechE D 215, who fit μ_t = μ_max / (0.925 + 0.15 R), R in m).

Force law (replaces the shear-law lateral forces)::

    R = |u| / max(|r|, r_eps)                    turning radius of the CG [m]
    μ_t(R) = μ_min + μ_max / (a + b R)
    F_lat,i = −μ_t(R) F_n,i smoothsign(v_y,i; v_s)      [N]

``blend`` (default 1: the law alone) mixes the law with the shear law's lateral forces,
F_lat,i = blend · F_lat,i(μ_t) + (1 − blend) · F_lat,i(shear), so that a family of fitted models that
includes ``blend`` = 0 contains the base model exactly (the diagnosis's candidate, docs/model.md §8). A
partial blend reads as a track whose lateral resistance is part shearing (Janosi) and part sliding
friction.

μ_min (default 0) is a floor of the coefficient at large radii (the residual lateral friction of a
track sliding sideways in a wide turn; Kitano & Jyozaki's and Steeds's fits of μ_t(R) level off
rather than vanish).

Defaults: a = 0.925, b = 0.15 1/m (Wong & Chiang), μ_max = 0.53 = tan 28° (dry sand's friction angle
as the friction coefficient; PackBot's tracks are short, so R stays small in its turns), v_s = 0.05 m/s,
r_eps = 1e-3 rad/s (R ≤ |u|/r_eps; a straight run has R → large and μ_t → 0).
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..physics.terramechanics import smoothsign
from .base import Effect


class LateralFrictionRadius(Effect):
    """Lateral forces μ_t(R) F_n opposing v_y with μ_t(R) = μ_max / (a + b R)."""

    id: ClassVar[str] = "lateral_friction_radius"
    bounds: ClassVar[dict] = {
        "mu_max": (0.0, 2.0),
        "mu_min": (0.0, 2.0),
        "a": (0.1, 10.0),
        "b": (0.0, 10.0),
        "lateral_smoothing": (1e-4, 1.0),
        "yaw_eps": (1e-6, 1.0),
        "blend": (0.0, 1.0),
    }

    mu_max: jax.Array  # -, μ_max
    a: jax.Array  # -, constant of the denominator
    b: jax.Array  # 1/m, radius coefficient
    lateral_smoothing: jax.Array  # m/s, v_s
    yaw_eps: jax.Array  # rad/s, r_eps
    mu_min: jax.Array | float = 0.0  # -, floor of μ_t at large radius
    blend: jax.Array | float = 1.0  # -, share of μ_t(R) in the lateral forces (the rest: the shear law)

    @classmethod
    def default(cls, dtype=jnp.float32):
        f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return cls(mu_max=f(0.53), a=f(0.925), b=f(0.15), lateral_smoothing=f(0.05), yaw_eps=f(1e-3), mu_min=f(0.0),
                   blend=f(1.0))

    def turning_radius(self, u, r):
        return jnp.abs(u) / jnp.maximum(jnp.abs(r), self.yaw_eps)

    def coefficient(self, radius):
        return self.mu_min + self.mu_max / (self.a + self.b * radius)

    def forces(self, ctx, forces, tau_int):
        u, r = ctx.state.vel[0], ctx.state.vel[2]
        mu = self.coefficient(self.turning_radius(u, r))  # (*b)
        law = -mu * forces.normal * smoothsign(ctx.kin.lateral_velocity, self.lateral_smoothing)
        # exact at both ends: blend = 1 gives the law, blend = 0 the shear law's forces, to the last bit
        lateral = self.blend * law + (1.0 - self.blend) * forces.lateral
        return forces._replace(lateral=lateral), tau_int
