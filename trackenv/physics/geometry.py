"""Contact-point geometry of the two tracks (docs/model.md §1, App. C.2). SI units."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Shaped

from ..params import Terrain, Vehicle


def trailing(a: Shaped[ArrayLike, " ..."], nb: int) -> Shaped[Array, " ..."]:
    """Append ``nb`` singleton axes so ``a`` broadcasts against arrays with ``nb`` batch axes."""
    a = jnp.asarray(a)
    return a.reshape(a.shape + (1,) * nb)


def contact_x(vehicle: Vehicle, nb: int) -> Float[Array, " 1 N *#b"]:
    """Body-frame x of the contact points, front to rear: x_i = L/2 - (i-1) L/(N-1) [m], shape (1, N, *b)."""
    n = vehicle.n_contact
    idx = trailing(np.arange(n).astype(jnp.result_type(vehicle.contact_length)), nb)[None]
    spacing = vehicle.contact_length / (n - 1)
    return 0.5 * vehicle.contact_length - idx * spacing


def contact_area(vehicle: Vehicle, nb: int) -> Float[Array, " 1 N *#b"]:
    """Element areas by the trapezoid rule: A_1 = A_N = b D/2, else b D [m^2], shape (1, N, *b)."""
    n = vehicle.n_contact
    weights = np.ones(n)
    weights[0] = weights[-1] = 0.5
    spacing = vehicle.contact_length / (n - 1)
    return trailing(weights.astype(jnp.result_type(spacing)), nb)[None] * (vehicle.track_width * spacing)


def track_y(vehicle: Vehicle, nb: int) -> Float[Array, " 2 *#b"]:
    """Body-frame y of the track centrelines, left +B/2, right -B/2 [m], shape (2, *b)."""
    side = trailing(np.array([1.0, -1.0], dtype=jnp.result_type(vehicle.track_gauge)), nb)
    return side * (0.5 * vehicle.track_gauge)


def belt_radius(vehicle: Vehicle, terrain: Terrain) -> Float[Array, " *#b"]:
    """Belt-to-ground radius r_s' [m]: r_s on deformable ground, r_s + h_g on hard ground (§5.3.1)."""
    return vehicle.sprocket_radius + vehicle.grouser_height * (1.0 - terrain.deformable)
