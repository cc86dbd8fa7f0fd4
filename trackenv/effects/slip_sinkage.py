"""``slip_sinkage``: slip-induced sinkage and the bulldozing resistance of the displaced soil (docs/model.md §8).

Evidence (thesis §5.3.4): in the zero-radius turn on dry sand the simulated yaw rate was ≈ 11× the
measured one; the vehicle dug itself 2-3 in into the sand and could not turn after ~20 s. Sliding
tracks excavate soil (slip sinkage, Lyasko 2010, "Slip sinkage effect in soil-vehicle mechanics",
J. Terramechanics 47: sinkage grows with slip on top of the static Bekker sinkage) and the sunken track
must then push the displaced soil aside (bulldozing, thesis §2.4.2 eq. 2.17; Bekker 1960; Wong,
"Theory of Ground Vehicles", §2.4 / §7.1 bulldozing resistance from passive earth pressure).

State: the slip sinkage z_s of each track [m], shape (2, *b), zero at rest::

    dz_s/dt = k_s · S_k · (1 − z_s / z_max) · deformable,
    S_k = sqrt(s_k² + ⟨|v_y,k,i|⟩² + ε²) − ε                 (total slip speed [m/s])

where s_k is the longitudinal slip velocity and ⟨|v_y|⟩ the mean lateral sliding speed of the track's
elements (a zero-radius turn slides the tracks sideways and spins them: it digs in); ε = 1e-3 m/s
keeps it smooth. k_s [1/m] is the sinkage per metre slid (relative to z_max); z_max bounds it.

Bulldozing (Rankine passive earth pressure on a vertical wall of depth z, per unit wall length,
eq. 2.17 with α = 90°, K_γ = N_φ, K_c = √N_φ, N_φ = tan²(45° + φ/2))::

    q(z) = k_b · (γ z² N_φ / 2 + 2 c z √N_φ)                  [N/m]

- front (longitudinal) bulldozing per track, on the track's width b, opposing its ground speed:
  R_b,k = −b q(z_s) smoothsign(u − r y_k; 0.05 m/s)          (added to the per-track ``compaction``);
- side bulldozing on each element's side wall of length D = L/(N−1) (trapezoid weights A_i/b),
  opposing the element's lateral velocity:  F_side,i = −(A_i/b) q(z_s) smoothsign(v_y,i; v_s)
  (added to ``lateral``); for a turn v_y = r x_i changes sign along the track, so the side walls
  resist yaw with a moment ≈ 2 q L²/4.

All of it is multiplied by ``terrain.deformable`` (nothing on hard ground). c and φ come from
``ctx.params.terrain``; the soil unit weight γ [N/m³] is a parameter (dry sand ≈ 15-17 kN/m³).
k_b (dimensionless) scales the 2-D Rankine wall to the 3-D soil wedges of a narrow sunken track (Bekker's
K_c, K_γ exceed the Rankine values by 2-5× for φ ≈ 28°); it is the calibration factor.

Default calibration (dry sand, ZRT at ±12 V, profile 0→±12 V over 0.3 s then hold; base model
yaw rate −5.00 rad/s): see ``tests/effects/test_slip_sinkage.py`` and the report: k_s, z_max, k_b
chosen so the yaw rate falls to ≈ 1/11 of the base model's after a few seconds, z_s reaches 2-3 in and
the turn stalls. Defaults k_s = 0.3 1/m, z_max = 0.07 m, γ = 15.7 kN/m³, k_b = 0.8, v_s = 0.01 m/s give
(yaw rate / sinkage): 1 s −4.44 rad/s / 10 mm; 3 s −1.38 / 28 mm; 4 s −0.65 / 37 mm (≈ 1/8 of the base
−5.00); 5 s −0.26 / 44 mm (≈ 1/19); from ~8 s on it creeps at |r| ≈ 0.03 rad/s (stalled: < 10% of
base/11) with z_s = 63 mm at 10 s, 69 mm (2.7 in) at 20 s. The model stalls earlier (~8 s) than the
field's ~20 s: the Coulomb-like side resistance makes the yaw rate drop steeply once q(z_s) reaches the
available turning moment; a larger v_s gives a gentler decline but a residual creep of 0.1-0.15 rad/s.
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..physics.sums import contact_sum
from ..physics.terramechanics import smoothsign
from .base import Effect

SLIP_EPS = 1e-3  # m/s, smoothing of the total slip speed
FRONT_SPEED_SMOOTHING = 0.05  # m/s


def passive_pressure_force(z, cohesion, friction_angle, unit_weight):
    """Rankine passive earth force per unit wall length on a vertical wall of depth z [N/m]."""
    n_phi = jnp.tan(jnp.pi / 4 + friction_angle / 2) ** 2
    z = jnp.maximum(z, 0.0)
    return unit_weight * z * z * n_phi / 2 + 2.0 * cohesion * z * jnp.sqrt(n_phi)


class SlipSinkage(Effect):
    """Slip sinkage state z_s (2, *b) and front + side bulldozing resistance of the displaced soil."""

    id: ClassVar[str] = "slip_sinkage"
    bounds: ClassVar[dict] = {
        "sinkage_rate": (0.0, 10.0),
        "max_sinkage": (0.0, 0.1),
        "unit_weight": (5e3, 25e3),
        "bulldozing_factor": (0.0, 20.0),
        "side_speed_smoothing": (1e-4, 0.2),
    }

    sinkage_rate: jax.Array  # 1/m, k_s: sinkage (relative to z_max) per metre of sliding
    max_sinkage: jax.Array  # m, z_max
    unit_weight: jax.Array  # N/m^3, soil unit weight γ
    bulldozing_factor: jax.Array  # -, k_b
    side_speed_smoothing: jax.Array  # m/s, v_s of smoothsign(v_y)

    @classmethod
    def default(cls, dtype=jnp.float32):
        f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return cls(sinkage_rate=f(0.3), max_sinkage=f(0.07), unit_weight=f(15.7e3),
                   bulldozing_factor=f(0.8), side_speed_smoothing=f(0.01))

    def initial_state(self, params, batch_shape):
        return jnp.zeros((2,) + tuple(batch_shape), params.dtype)

    def slip_speed(self, kin):
        """Total slip speed S_k [m/s], (2, *b)."""
        speed = jnp.sqrt(kin.lateral_velocity**2 + SLIP_EPS**2)  # (1, N, *b)
        lat = contact_sum(speed, 1, speed.ndim - 2) / speed.shape[1]  # (1, *b), the mean over the points
        return jnp.sqrt(kin.slip**2 + lat**2 + SLIP_EPS**2) - jnp.sqrt(2.0) * SLIP_EPS

    def state_rate(self, ctx, forces):
        z = ctx.state.extra[self.id]
        rate = self.sinkage_rate * self.slip_speed(ctx.kin) * (self.max_sinkage - z)
        return rate * ctx.params.terrain.deformable

    def wall_force(self, ctx, z):
        """q(z_s) [N/m] per unit wall length, times deformable, (2, *b)."""
        ter = ctx.params.terrain
        q = passive_pressure_force(z, ter.cohesion, ter.friction_angle, self.unit_weight)
        return self.bulldozing_factor * q * ter.deformable

    def forces(self, ctx, forces, tau_int):
        z = ctx.state.extra[self.id]
        q = self.wall_force(ctx, z)  # (2, *b)
        b = ctx.params.vehicle.track_width
        kin = ctx.kin
        front = -b * q * smoothsign(kin.ground_speed, FRONT_SPEED_SMOOTHING)
        side_len = kin.area / b  # (1, N, *b) wall length of each element (trapezoid weights)
        side = -side_len * q[:, None] * smoothsign(kin.lateral_velocity, self.side_speed_smoothing)
        return forces._replace(compaction=forces.compaction + front, lateral=forces.lateral + side), tau_int
