"""Contact-point geometry of the two sides: tracks or wheel patches (docs/model.md §1, §1.1, App. C.2). SI units."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Shaped

from ..params import Terrain, Vehicle


def trailing(a: Shaped[ArrayLike, " ..."], nb: int) -> Shaped[Array, " ..."]:
    """Append ``nb`` singleton axes so ``a`` broadcasts against arrays with ``nb`` batch axes."""
    a = jnp.asarray(a)
    return a.reshape(a.shape + (1,) * nb)


def _layout(vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray, int]:
    """Patch index k and index j within the patch of each contact point (numpy constants), points per patch."""
    per_patch = vehicle.n_contact // vehicle.n_patches
    i = np.arange(vehicle.n_contact)
    return i // per_patch, i % per_patch, per_patch


def patch_centres(vehicle: Vehicle, nb: int) -> Float[Array, " 1 P *#b"]:
    """Body-frame x of the patch centres, front to rear [m], shape (1, P, *b).

    c_k = W/2 - (k-1) W/(P-1), k = 1 (front) ... P (rear), W the wheelbase; c = 0 for a track (P = 1).
    """
    patches = vehicle.n_patches
    k = trailing(np.arange(patches).astype(jnp.result_type(vehicle.wheelbase)), nb)[None]
    pitch = vehicle.wheelbase / (patches - 1) if patches > 1 else 0.0 * vehicle.wheelbase  # m
    return 0.5 * vehicle.wheelbase - k * pitch


def per_point(
    vehicle: Vehicle, a: Shaped[Array, " 1 P *#b"] | Shaped[Array, " 2 P *#b"]
) -> Shaped[Array, " 1 N *#b"] | Shaped[Array, " 2 N *#b"]:
    """A per-patch array (axis 1: patch) repeated to the contact points (axis 1: point), N/P per patch.

    For a track (P = 1) ``a`` is returned as it is: its patch axis of length 1 broadcasts over the points.
    """
    _, _, per_patch = _layout(vehicle)
    return a if vehicle.n_patches == 1 else jnp.repeat(a, per_patch, axis=1, total_repeat_length=vehicle.n_contact)


def patch_spacing(vehicle: Vehicle) -> Float[Array, " *#b"]:
    """Spacing of the contact points within one patch, Delta = L/(N/P - 1) [m] (App. C.2 for P = 1)."""
    _, _, per_patch = _layout(vehicle)
    return vehicle.contact_length / (per_patch - 1)


def patch_x(vehicle: Vehicle, nb: int) -> Float[Array, " 1 N *#b"]:
    """x of the contact points relative to their patch centre, L/2 - (j-1) Delta [m], shape (1, N, *b).

    Point j = 1 (front) ... N/P of each patch, Delta from :func:`patch_spacing`.
    """
    _, j, _ = _layout(vehicle)
    idx = trailing(j.astype(jnp.result_type(vehicle.contact_length)), nb)[None]
    return 0.5 * vehicle.contact_length - idx * patch_spacing(vehicle)


def contact_x(vehicle: Vehicle, nb: int) -> Float[Array, " 1 N *#b"]:
    """Body-frame x of the contact points, front to rear [m], shape (1, N, *b).

    x_i = c_k + (L/2 - (j-1) Delta), point j = 1 ... N/P of patch k (:func:`patch_centres`,
    :func:`patch_x`); for a track (c = 0, P = 1) this is x_i = L/2 - (i-1) L/(N-1).
    """
    local = patch_x(vehicle, nb)
    if vehicle.n_patches == 1:  # a track: c = 0
        return local
    return per_point(vehicle, patch_centres(vehicle, nb)) + local


def patch_edges(
    vehicle: Vehicle, nb: int
) -> tuple[Float[Array, " 1 P *#b"] | Float[Array, " *#b"], Float[Array, " 1 P *#b"] | Float[Array, " *#b"]]:
    """Distances of each patch's front edge ahead of and rear edge behind the CG, c + L/2 and L/2 - c [m].

    Shapes (1, P, *b); for a track (P = 1, c = 0) both are L/2, of shape (*b).
    """
    half = 0.5 * vehicle.contact_length
    if vehicle.n_patches == 1:  # a track: c = 0
        return half, half
    centre = patch_centres(vehicle, nb)
    return centre + half, half - centre


def contact_area(vehicle: Vehicle, nb: int) -> Float[Array, " 1 N *#b"]:
    """Element areas by the trapezoid rule over each patch [m^2], shape (1, N, *b).

    A = b Delta/2 at the first and last point of every patch, b Delta in between; each patch sums to b L.
    """
    _, j, per_patch = _layout(vehicle)
    weights = np.where((j == 0) | (j == per_patch - 1), 0.5, 1.0)
    spacing = patch_spacing(vehicle)
    return trailing(weights.astype(jnp.result_type(spacing)), nb)[None] * (vehicle.track_width * spacing)


def track_y(vehicle: Vehicle, nb: int) -> Float[Array, " 2 *#b"]:
    """Body-frame y of the track (or wheel) centrelines, left +B/2, right -B/2 [m], shape (2, *b)."""
    side = trailing(np.array([1.0, -1.0], dtype=jnp.result_type(vehicle.track_gauge)), nb)
    return side * (0.5 * vehicle.track_gauge)


def belt_radius(vehicle: Vehicle, terrain: Terrain) -> Float[Array, " *#b"]:
    """Belt-to-ground radius r_s' [m]: r_s on deformable ground, r_s + h_g on hard ground (§5.3.1)."""
    return vehicle.sprocket_radius + vehicle.grouser_height * (1.0 - terrain.deformable)
