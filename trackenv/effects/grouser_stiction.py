"""``grouser_stiction``: breakaway resistance of grousers on the asperities of hard ground (docs/model.md §8).

Evidence (thesis §5.3.4): in the zero-radius turn on asphalt the start of the turn was hindered,
the simulated transient too fast. Grousers resting against asperities of a hard surface must be lifted
over or broken free before the track slides: a static ("stiction") resistance that fades once the
track slides (Coulomb/Stribeck friction with a breakaway peak; Wong, "Theory of Ground Vehicles",
§7.1 on lateral resistance of tracks on hard ground; Armstrong-Hélouvry's Stribeck form).

Force law (on hard ground only, × (1 − deformable)), added as body yaw moment and body x force::

    M = −M0 · smoothsign(r; r_s) · exp(−|r| / r_fade)              [N m]
    F = −F0 · smoothsign(u; u_s) · exp(−|u| / u_fade)              [N]

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
    }

    yaw_moment: jax.Array  # N m, M0
    yaw_smoothing: jax.Array  # rad/s, r_s
    yaw_fade: jax.Array  # rad/s, r_fade
    force: jax.Array  # N, F0
    speed_smoothing: jax.Array  # m/s, u_s
    speed_fade: jax.Array  # m/s, u_fade

    @classmethod
    def default(cls, dtype=jnp.float32):
        f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return cls(yaw_moment=f(18.0), yaw_smoothing=f(0.05), yaw_fade=f(1.5), force=f(0.0),
                   speed_smoothing=f(0.02), speed_fade=f(0.2))

    def moment(self, r):
        return -self.yaw_moment * smoothsign(r, self.yaw_smoothing) * jnp.exp(-jnp.abs(r) / self.yaw_fade)

    def longitudinal(self, u):
        return -self.force * smoothsign(u, self.speed_smoothing) * jnp.exp(-jnp.abs(u) / self.speed_fade)

    def forces(self, ctx, forces, tau_int):
        hard = 1.0 - ctx.params.terrain.deformable
        u, r = ctx.state.vel[0], ctx.state.vel[2]
        return forces._replace(body_yaw=forces.body_yaw + hard * self.moment(r),
                               body_x=forces.body_x + hard * self.longitudinal(u)), tau_int
