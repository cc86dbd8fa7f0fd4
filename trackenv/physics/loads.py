"""Normal load distribution under the tracks or wheels (docs/model.md §4; replaces ADAMS's contact springs, §3.4.1)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..params import Vehicle
from .geometry import contact_area, contact_x, track_y

GRAVITY = 9.81  # m/s^2


def normal_loads(
    vehicle: Vehicle,
    u: Float[Array, " *b"],
    r: Float[Array, " *b"],
    nb: int,
    pitch_gradient: Float[Array, " *#b"] | None = None,
) -> Float[Array, " 2 N *b"]:
    """Quasi-static normal force F_n,i [N] at each contact point, shape (2, N, *b).

    Rigid body on a Winkler foundation: p(x, y) = p0 + p_x x + p_y y with sum A_i p_i = m g and
    sum A_i p_i y_k = -m a_y h (roll transfer, a_y = u r); p_x = 0 in the base model
    (``pitch_gradient`` lets an effect supply p_x [Pa/m]). F_n,i = max(0, A_i p_i). The contact area of
    one side is b P L (P patches of length L; b L for a track).
    """
    area = contact_area(vehicle, nb)  # (1, N, *b)
    y = track_y(vehicle, nb)  # (2, *b)
    b, gauge = vehicle.track_width, vehicle.track_gauge
    length = vehicle.n_patches * vehicle.contact_length  # m, total contact length of one side, P L
    p0 = vehicle.mass * GRAVITY / (2.0 * b * length)
    lateral_accel = u * r
    p_y = -2.0 * vehicle.mass * lateral_accel * vehicle.cg_height / (b * length * gauge**2)
    pressure = (p0 + p_y * y)[:, None]  # (2, 1, *b)
    if pitch_gradient is not None:
        pressure = pressure + pitch_gradient * contact_x(vehicle, nb)
    return jnp.maximum(area * pressure, 0.0)
