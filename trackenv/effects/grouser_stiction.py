"""``grouser_stiction``: breakaway resistance of grousers on the asperities of hard ground (docs/model.md §8).

Evidence (thesis §5.3.4): in the zero-radius turn on asphalt the start of the turn was hindered,
the simulated transient too fast. Grousers resting against asperities of a hard surface must be lifted
over or broken free before the track slides: a static ("stiction") resistance that fades once the
track slides (Coulomb/Stribeck friction with a breakaway peak; Wong, "Theory of Ground Vehicles",
§7.1 on lateral resistance of tracks on hard ground; Armstrong-Hélouvry's Stribeck form).

Force law (on hard ground only, × (1 − deformable)), added as body yaw moment and body x force::

    M = −M0 · smoothsign(r; r_s) · exp(−|r| / r_fade)              [N m]
    F = −F0 · smoothsign(u; u_s) · exp(−|u| / u_fade)              [N]

and, per contact element, a Stribeck amplification of the shear law's lateral force that fades with the
element's own sideways sliding speed v_y,i = v + r x_i (Armstrong-Hélouvry's exponential Stribeck curve,
μ(v) = μ_c + (μ_s − μ_c) exp(−|v|/v_s))::

    F_lat,i ← F_lat,i · (1 + β · exp(−|v_y,i| / v_e))               [N]

The body terms describe the breakaway as a whole; the element term puts it where the grousers slide, so
that in a steady turn the elements near the turning centre (slow) keep more resistance than the ends.
β = 0 (the default) leaves the lateral forces unchanged; the diagnosis fits both forms together.

Peak resistance M0 (F0) just above |r| = r_s, fading to ~0 for |r| ≫ r_fade, so steady turns
are hardly changed while the breakaway is slowed.

Default (calibration, asphalt ZRT ±12 V, 0.3 s ramp): M0 = 18 N m, r_s = 0.05 rad/s,
r_fade = 1.5 rad/s, F0 = 0 (no straight-line evidence), u_s = 0.02 m/s, u_fade = 0.2 m/s; the time to
reach 90% of the steady yaw rate grows from 0.85 s to 1.35 s (1.6x) while the steady yaw rate changes by 0.7%; M0 >~
21 N m blocks the turn (the breakaway exceeds the drive moment)
(see tests/effects/test_grouser_stiction.py and the report).
"""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..physics.terramechanics import smoothsign
from .base import Effect


class GrouserStiction(Effect):
    """Breakaway yaw moment and longitudinal force opposing motion on hard ground, fading with speed."""

    id: ClassVar[str] = "grouser_stiction"
    bounds: ClassVar[dict] = {
        "yaw_moment": (0.0, 100.0),
        "yaw_smoothing": (1e-4, 1.0),
        "yaw_fade": (1e-2, 20.0),
        "force": (0.0, 500.0),
        "speed_smoothing": (1e-4, 1.0),
        "speed_fade": (1e-2, 10.0),
        "lateral_gain": (0.0, 5.0),
        "lateral_slide_speed": (1e-3, 2.0),
    }

    yaw_moment: jax.Array  # N m, M0
    yaw_smoothing: jax.Array  # rad/s, r_s
    yaw_fade: jax.Array  # rad/s, r_fade
    force: jax.Array  # N, F0
    speed_smoothing: jax.Array  # m/s, u_s
    speed_fade: jax.Array  # m/s, u_fade
    lateral_gain: jax.Array  # -, β: peak amplification of the elements' lateral force
    lateral_slide_speed: jax.Array  # m/s, v_e: sliding speed over which the amplification fades

    @classmethod
    def default(cls, dtype=jnp.float32):
        f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return cls(yaw_moment=f(18.0), yaw_smoothing=f(0.05), yaw_fade=f(1.5), force=f(0.0),
                   speed_smoothing=f(0.02), speed_fade=f(0.2), lateral_gain=f(0.0), lateral_slide_speed=f(0.1))

    def moment(self, r):
        return -self.yaw_moment * smoothsign(r, self.yaw_smoothing) * jnp.exp(-jnp.abs(r) / self.yaw_fade)

    def longitudinal(self, u):
        return -self.force * smoothsign(u, self.speed_smoothing) * jnp.exp(-jnp.abs(u) / self.speed_fade)

    def lateral_factor(self, lateral_velocity):
        """Stribeck factor 1 + β exp(−|v_y,i| / v_e) on an element's lateral force (v_y,i in m/s)."""
        return 1.0 + self.lateral_gain * jnp.exp(-jnp.abs(lateral_velocity) / self.lateral_slide_speed)

    def forces(self, ctx, forces, tau_int):
        hard = 1.0 - ctx.params.terrain.deformable
        u, r = ctx.state.vel[0], ctx.state.vel[2]
        lateral = forces.lateral * (1.0 + hard * (self.lateral_factor(ctx.kin.lateral_velocity) - 1.0))
        return forces._replace(body_yaw=forces.body_yaw + hard * self.moment(r),
                               body_x=forces.body_x + hard * self.longitudinal(u), lateral=lateral), tau_int
