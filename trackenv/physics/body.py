"""Planar rigid-body dynamics of the vehicle (docs/model.md §5). SI units."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..params import Vehicle
from .sums import divide_by_parameter


def pose_rate(pose: Float[Array, " 3 *b"], vel: Float[Array, " 3 *b"]) -> Float[Array, " 3 *b"]:
    """World-frame kinematics: dX/dt = u cos psi - v sin psi, dY/dt = u sin psi + v cos psi, dpsi/dt = r."""
    psi = pose[2]
    u, v, r = vel[0], vel[1], vel[2]
    c, s = jnp.cos(psi), jnp.sin(psi)
    return jnp.stack([u * c - v * s, u * s + v * c, r])


def velocity_rate(
    vehicle: Vehicle,
    vel: Float[Array, " 3 *b"],
    force_x: Float[Array, " *b"],
    force_y: Float[Array, " *b"],
    moment_z: Float[Array, " *b"],
) -> Float[Array, " 3 *b"]:
    """Body-frame Newton-Euler: m(du/dt - v r) = F_x, m(dv/dt + u r) = F_y, I_z dr/dt = M_z."""
    u, v, r = vel[0], vel[1], vel[2]
    return jnp.stack(
        [divide_by_parameter(force_x, vehicle.mass) + v * r, divide_by_parameter(force_y, vehicle.mass) - u * r,
         divide_by_parameter(moment_z, vehicle.yaw_inertia)]  # divisions in every batch (sums.divide_by_parameter)
    )


def kinetic_energy(vehicle: Vehicle, vel: Float[Array, " 3 *b"]) -> Float[Array, " *b"]:
    """Translational + yaw kinetic energy of the body [J]."""
    u, v, r = vel[0], vel[1], vel[2]
    return 0.5 * vehicle.mass * (u * u + v * v) + 0.5 * vehicle.yaw_inertia * r * r
