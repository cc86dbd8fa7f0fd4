"""Track-terrain contact: kinematics, z*/z-bar logic, shear-displacement rates and contact forces.

A side is a track (one contact patch) or several wheel patches (docs/model.md §1.1); the same element
laws apply to every patch.

docs/model.md §3; thesis §3.4.2-3.4.6. Shapes follow ``trackenv.physics`` (element arrays (2, N, *b)).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..params import Terrain, Vehicle
from . import terramechanics as tm
from .geometry import belt_radius, contact_area, contact_x, patch_edges, patch_x, per_point, track_y
from .sums import contact_sum

# Smoothing constants of Table C.1 (docs/model.md §2), SI.
LEADING_EDGE_SPEED = 1e-2  # m/s, Delta V_z: below it the leading edge follows the ground speed
MIN_Z_STAR = 1e-6  # m, Delta Z: floor of z* in the decay rate |V_t|/z*
SLIP_SAT_START, SLIP_SAT_END = 1e-3, 1.5e-2  # m/s, saturation of j_z (3.17)
LATERAL_SAT_START, LATERAL_SAT_END = 5e-4, 5e-3  # m/s, saturation of j_x (3.33)
LONG_FORCE_SMOOTHING = 1e-9  # m, sign smoothing of the longitudinal force in j'_z (3.23)
LAT_FORCE_SMOOTHING = 3e-2  # m, sign smoothing of the lateral force in j'_x (3.36)
COMPACTION_SPEED_SMOOTHING = 0.2  # m/s, sign smoothing of R_c in the track's ground speed


class Kinematics(NamedTuple):
    """Contact kinematics of both tracks at one instant (SI)."""

    belt_radius: Float[Array, " *#b"]  # m, r_s' (scalar or (*b))
    belt_speed: Float[Array, " 2 *b"]  # m/s, V_t = r_s' omega, (2, *b)
    ground_speed: Float[Array, " 2 *b"]  # m/s, u - r y_k, (2, *b)
    slip: Float[Array, " 2 *b"]  # m/s, s_k = V_t - (u - r y_k), (2, *b)
    lateral_velocity: Float[Array, " 1 N *b"]  # m/s, v + r x_i, (1, N, *b)
    z_star: Float[Array, " 2 N *b"]  # m, distance from the leading edge of the point's patch, (2, N, *b)
    z_tilde: Float[Array, " 2 N *b"]  # m, distance from that leading edge or from z-bar, (2, N, *b)
    x: Float[Array, " 1 N *#b"]  # m, contact x, (1, N, *b)
    y: Float[Array, " 2 *#b"]  # m, track (wheel) centreline y, (2, *b)
    area: Float[Array, " 1 N *#b"]  # m^2, element areas, (1, N, *b)


def kinematics(
    vehicle: Vehicle, terrain: Terrain, vel: Float[Array, " 3 *b"], omega: Float[Array, " 2 *b"], nb: int
) -> Kinematics:
    """Contact-point velocities, slip, and the z*/z-tilde coordinates (docs/model.md §3, §3.4.2.2, 3.29-3.31)."""
    u, v, r = vel[0], vel[1], vel[2]
    x = contact_x(vehicle, nb)
    y = track_y(vehicle, nb)
    rb = belt_radius(vehicle, terrain)
    belt_speed = rb * omega
    ground_speed = u - r * y
    slip = belt_speed - ground_speed
    vy = v + r * x  # (1, N, *b)

    # Leading edge: where belt material enters the contact patch (§3.4.2.2). On a wheeled side every
    # patch has its own leading edge, all at the same end (docs/model.md §1.1).
    front = leading_edge_is_front(belt_speed, ground_speed)  # (2, *b)
    half = 0.5 * vehicle.contact_length
    local = patch_x(vehicle, nb)  # (1, N, *b), x relative to the point's patch centre
    z_from_front = half - local  # (1, N, *b), from the front edge of the point's patch
    z_from_rear = local + half
    z_star = jnp.where(front[:, None], z_from_front, z_from_rear)

    # z-bar: where the lateral velocity changes sign along each patch (3.29), (3.30), from the lateral
    # velocities at the patch's front and rear edges.
    v_first, v_last = edge_lateral_velocities(vehicle, v, r, front, nb)  # (2, P, *b)
    changes_sign, fraction = _sign_change(v_first, v_last)
    z_bar = per_point(vehicle, jnp.where(changes_sign, fraction * vehicle.contact_length, jnp.inf))
    past = z_star >= z_bar
    z_tilde = jnp.where(past, z_star - z_bar, z_star)  # (3.31)
    return Kinematics(rb, belt_speed, ground_speed, slip, vy, z_star, z_tilde, x, y, contact_area(vehicle, nb))


def leading_edge_is_front(belt_speed: Float[Array, " 2 *b"], ground_speed: Float[Array, " 2 *b"]) -> Bool[Array, " 2 *b"]:
    """(2, *b) True where belt material enters each track's contact patches at their front end (§3.4.2.2):
    V_t > Delta V_z; at |V_t| <= Delta V_z the leading edge follows the ground speed."""
    return jnp.where(
        belt_speed > LEADING_EDGE_SPEED,
        True,
        jnp.where(belt_speed < -LEADING_EDGE_SPEED, False, ground_speed >= 0.0),
    )


def edge_lateral_velocities(
    vehicle: Vehicle, v: Float[Array, " *b"], r: Float[Array, " *b"], front: Bool[Array, " 2 *b"], nb: int
) -> tuple[Float[Array, " 2 P *b"], Float[Array, " 2 P *b"]]:
    """Lateral velocities [m/s] at each patch's leading ("first") and other ("last") edge, (2, P, *b) each."""
    ahead, behind = patch_edges(vehicle, nb)  # m, (1, P, *b); L/2 for a track
    vy_front = v + r * ahead
    vy_rear = v - r * behind
    first = front[:, None]  # (2, 1, *b): the leading edge is at the same end of every patch
    return jnp.where(first, vy_front, vy_rear), jnp.where(first, vy_rear, vy_front)


def _sign_change(a: Float[Array, " ..."], b: Float[Array, " ..."]) -> tuple[Bool[Array, " ..."], Float[Array, " ..."]]:
    """Where a linear a -> b changes sign: the flag, and the fraction a/(a - b) of the way from a to b
    (1 where it does not change sign)."""
    changes = a * b < 0.0
    return changes, jnp.where(changes, a / jnp.where(changes, a - b, 1.0), 1.0)


# m/s: floor of the speeds the substep mean divides by, far below any physical one; small enough to be exact,
# large enough that gradients through the unselected branches stay finite in float32.
_TINY_SPEED = 1e-9


def _log_ramp(w: Float[Array, " ..."], eps: Float[Array, " ..."]) -> Float[Array, " ..."]:
    """An antiderivative of 1/max(|w|, eps): w/eps for |w| <= eps, sign(w) (1 + ln(|w|/eps)) beyond."""
    a = jnp.abs(w)
    return jnp.where(a <= eps, w / eps, jnp.sign(w) * (1.0 + jnp.log(jnp.maximum(a, eps) / eps)))


def mean_inverse_z_tilde(
    vehicle: Vehicle, kin: Kinematics, vel_end: Float[Array, " 3 *b"], vel_start: Float[Array, " 3 *b"], nb: int
) -> Float[Array, " 2 N *b"]:
    """Mean over a substep of 1/max(z-tilde*, Delta Z) [1/m] (3.31), with v and r linear in time between
    ``vel_start`` and ``vel_end`` and the leading edge of ``kin`` (the substep's start).

    Past z-bar, z-tilde* = z* - z-bar is the distance to where v_y changes sign, |v_y,i|/|r|, so
    1/max(z-tilde*, Delta Z) = min(|r/v_y,i|, 1/Delta Z): singular (up to the floor) where the element's own
    v_y,i changes sign while it is past z-bar. Short of z-bar it is 1/z*. An element is past z-bar while v_y,i
    and the leading edge's lateral velocity have opposite signs; both are linear in time, so each changes
    sign at most once, and the substep falls into at most three pieces on which the element's side is
    constant. On a piece past z-bar where |v_y,i| changes by more than 20 %, r/v_y = beta + alpha/v_y
    (beta = dr/dv_y, alpha = r where v_y = 0) is integrated in closed form (:func:`_log_ramp`, floored at
    |alpha| Delta Z); elsewhere by the midpoint rule. A fixed step that samples z-tilde* at the substep's
    start instead misses the reset of j_x (3.32) whenever z-bar sweeps past an element within one substep.
    """
    front = leading_edge_is_front(kin.belt_speed, kin.ground_speed)
    v0, r0, v1, r1 = vel_start[1], vel_start[2], vel_end[1], vel_end[2]
    w0, w1 = v0 + r0 * kin.x, v1 + r1 * kin.x  # v_y,i at both ends, (1, N, *b)
    f0 = per_point(vehicle, edge_lateral_velocities(vehicle, v0, r0, front, nb)[0])  # leading edge's, (2, N, *b)
    f1 = per_point(vehicle, edge_lateral_velocities(vehicle, v1, r1, front, nb)[0])
    dw, dr = w1 - w0, r1 - r0  # changes over the substep [m/s], [rad/s]
    per = jnp.where(jnp.abs(dw) > _TINY_SPEED, dw, 1.0)  # dw as a divisor (an unchanging v_y,i takes the midpoint rule)
    beta = dr / per  # r = alpha + beta v_y,i along the substep
    alpha = r0 - beta * w0  # [rad/s]
    eps = jnp.maximum(jnp.abs(alpha) * MIN_Z_STAR, _TINY_SPEED)  # |v_y| below which z-tilde* is at its floor [m/s]

    w_changes, sa = _sign_change(w0, w1)
    f_changes, sb = _sign_change(f0, f1)
    g1 = _log_ramp(w1, eps)
    ga = jnp.where(w_changes, 0.0, g1)  # G where v_y,i = 0, or at the end
    gb = jnp.where(f_changes, _log_ramp(w0 + dw * sb, eps), g1)  # G where the leading edge's v_y changes sign
    a_first = sa <= sb
    cuts = (jnp.zeros_like(sb), jnp.minimum(sa, sb), jnp.maximum(sa, sb), jnp.ones_like(sb))
    gs = (_log_ramp(w0, eps), jnp.where(a_first, ga, gb), jnp.where(a_first, gb, ga), g1)
    z_star = floored_z_star(kin)
    # Each piece adds one quotient of a selected numerator and a selected denominator, so that the selections
    # end in a division: XLA copies cheap element-wise work into every kernel that reads its result, but not a
    # division. Selecting among finished quotients instead had the substep's stages each recompute the
    # selections: 47.4 kFLOP per vehicle-substep in XLA's count against 34.6 k (docs/performance.md).
    total = 0.0
    for lo, hi, g_lo, g_hi in zip(cuts[:-1], cuts[1:], gs[:-1], gs[1:], strict=True):
        length, mid = hi - lo, 0.5 * (lo + hi)
        w_lo, w_mid, w_hi = w0 + dw * lo, w0 + dw * mid, w0 + dw * hi
        r_mid = r0 + dr * mid
        past = w_mid * (f0 + (f1 - f0) * mid) < 0.0
        near_zero = jnp.minimum(jnp.abs(w_lo), jnp.abs(w_hi)) < 0.8 * jnp.maximum(jnp.abs(w_lo), jnp.abs(w_hi))
        # closed form: sign(r v_y) (beta (hi - lo) + alpha sign(v_y) (G(hi) - G(lo)) / dw)
        closed = jnp.sign(r_mid * w_mid) * (beta * length * per + alpha * jnp.sign(w_mid) * (g_hi - g_lo))
        # midpoint rule: (hi - lo) |r| / max(|v_y,i|, |r| Delta Z)
        floor = jnp.maximum(jnp.abs(w_mid), jnp.maximum(jnp.abs(r_mid) * MIN_Z_STAR, _TINY_SPEED))
        numerator = jnp.where(past, jnp.where(near_zero, closed, length * jnp.abs(r_mid)), length)
        denominator = jnp.where(past, jnp.where(near_zero, per, floor), z_star)  # short of z-bar: (hi - lo)/z*
        total = total + numerator / denominator
    return total


def floored_z_star(kin: Kinematics) -> Float[Array, " 2 N *b"]:
    """max(z*, Delta Z) [m]: each element's distance from the leading edge, floored (3.14)."""
    return jnp.maximum(kin.z_star, MIN_Z_STAR)


def longitudinal_decay_rate(belt_speed: Float[Array, " 2 *b"], kin: Kinematics) -> Float[Array, " 2 N *b"]:
    """Linear decay rate |V_t|/max(z*, Delta Z) of j_z (3.14) [1/s], (2, N, *b)."""
    return jnp.abs(belt_speed)[:, None] / floored_z_star(kin)


def shear_decay_rates(
    belt_speed: Float[Array, " 2 *b"],
    kin: Kinematics,
) -> tuple[Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """Linear decay rates |V_t|/max(z*, Delta Z) of j_z (3.14) and |V_t|/max(z-tilde*, Delta Z) of j_x (3.32)
    [1/s], each (2, N, *b), at one instant (the integrator takes j_x's as a substep mean instead:
    :func:`mean_inverse_z_tilde`)."""
    return (longitudinal_decay_rate(belt_speed, kin),
            jnp.abs(belt_speed)[:, None] / jnp.maximum(kin.z_tilde, MIN_Z_STAR))


def shear_drive(kin: Kinematics) -> tuple[Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """Non-stiff parts of the shear-displacement ODEs: d j_z/dt <- s_k (3.14), d j_x/dt <- v_y (3.32) [m/s]."""
    jz_drive = jnp.broadcast_to(kin.slip[:, None], kin.z_star.shape)
    jx_drive = jnp.broadcast_to(kin.lateral_velocity, kin.z_star.shape)
    return jz_drive, jx_drive


class ContactForces(NamedTuple):
    """Forces of the ground on the vehicle (SI). Effects may replace or add to any field."""

    normal: Float[Array, " 2 N *b"]  # N, F_n,i, (2, N, *b)
    longitudinal: Float[Array, " 2 N *b"]  # N, along body +x at each element, (2, N, *b)
    lateral: Float[Array, " 2 N *b"]  # N, along body +y at each element, (2, N, *b)
    compaction: Float[Array, " 2 *b"]  # N, compaction resistance along body +x per track (signed), (2, *b)
    body_x: Float[Array, " *b"]  # N, extra body force along +x (effects), (*b)
    body_y: Float[Array, " *b"]  # N, extra body force along +y (effects), (*b)
    body_yaw: Float[Array, " *b"]  # N m, extra yaw moment (effects), (*b)
    sprocket: Float[Array, " 2 *b"]  # N m, extra resisting torque at each sprocket (effects), (2, *b)


def saturations(kin: Kinematics) -> tuple[Float[Array, " 2 1 *b"], Float[Array, " 1 N *b"]]:
    """Saturation factors of the shear displacements: j'_z = j_z S_z(|s|) (3.17), j'_x = j_x S_x(|v_y|) (3.33)."""
    sat_z = tm.step5(jnp.abs(kin.slip), SLIP_SAT_START, 0.0, SLIP_SAT_END, 1.0)[:, None]
    sat_x = tm.step5(jnp.abs(kin.lateral_velocity), LATERAL_SAT_START, 0.0, LATERAL_SAT_END, 1.0)
    return sat_z, sat_x


def forces_from_saturated(
    terrain: Terrain,
    area: Float[Array, " 1 N *#b"],
    normal: Float[Array, " 2 N *b"],
    jz_sat: Float[Array, " 2 N *b"],
    jx_sat: Float[Array, " 2 N *b"],
) -> tuple[Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """Longitudinal and lateral element forces [N] from saturated displacements (3.19, 3.23, 3.35-3.36)."""
    pressure = normal / area
    fz = tm.shear_stress(jz_sat, pressure, terrain) * area  # (3.19)
    fx = tm.shear_stress(jx_sat, pressure, terrain) * area  # (3.35)
    longitudinal = tm.step5(jz_sat, -LONG_FORCE_SMOOTHING, -fz, LONG_FORCE_SMOOTHING, fz)  # (3.23)
    lateral = tm.step5(jx_sat, -LAT_FORCE_SMOOTHING, fx, LAT_FORCE_SMOOTHING, -fx)  # (3.36)
    return longitudinal, lateral


def saturation_slopes(kin: Kinematics) -> tuple[Float[Array, " 2 1 *b"], Float[Array, " 1 N *b"]]:
    """dS_z/ds (2, 1, *b) and dS_x/dv_y (1, N, *b) of :func:`saturations` (closed form of 3.17, 3.33)."""
    dz = tm.step5_slope(jnp.abs(kin.slip), SLIP_SAT_START, 0.0, SLIP_SAT_END, 1.0) * jnp.sign(kin.slip)
    dx = tm.step5_slope(jnp.abs(kin.lateral_velocity), LATERAL_SAT_START, 0.0, LATERAL_SAT_END, 1.0) \
        * jnp.sign(kin.lateral_velocity)
    return dz[:, None], dx


def force_slopes(
    terrain: Terrain,
    area: Float[Array, " 1 N *#b"],
    normal: Float[Array, " 2 N *b"],
    jz_sat: Float[Array, " 2 N *b"],
    jx_sat: Float[Array, " 2 N *b"],
) -> tuple[Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """d F_long / d j'_z and d F_lat / d j'_x [N/m] of :func:`forces_from_saturated`, elementwise.

    F_long = f_z(|j'_z|) g_a(j'_z) with g_a = smoothsign of width a (3.23), so
    dF/dj' = A dtau/d|j| sgn(j') g_a + f_z g_a'; likewise F_lat = -f_x g_b(j'_x) (3.36).
    """
    pressure = normal / area
    fz = tm.shear_stress(jz_sat, pressure, terrain) * area
    fx = tm.shear_stress(jx_sat, pressure, terrain) * area
    dfz = tm.shear_stress_slope(jz_sat, pressure, terrain) * area * jnp.sign(jz_sat)
    dfx = tm.shear_stress_slope(jx_sat, pressure, terrain) * area * jnp.sign(jx_sat)
    a, b = LONG_FORCE_SMOOTHING, LAT_FORCE_SMOOTHING
    d_long = dfz * tm.smoothsign(jz_sat, a) + fz * tm.step5_slope(jz_sat, -a, -1.0, a, 1.0)
    d_lat = -(dfx * tm.smoothsign(jx_sat, b) + fx * tm.step5_slope(jx_sat, -b, -1.0, b, 1.0))
    return d_long, d_lat


def shear_forces(
    terrain: Terrain,
    kin: Kinematics,
    normal: Float[Array, " 2 N *b"],
    jz: Float[Array, " 2 N *b"],
    jx: Float[Array, " 2 N *b"],
) -> tuple[Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """Longitudinal and lateral shear forces at each element [N] (3.17, 3.19, 3.23, 3.33, 3.35-3.36)."""
    sat_z, sat_x = saturations(kin)
    return forces_from_saturated(terrain, kin.area, normal, jz * sat_z, jx * sat_x)


def compaction_force(
    vehicle: Vehicle,
    terrain: Terrain,
    kin: Kinematics,
    normal: Float[Array, " 2 N *b"],
) -> Float[Array, " 2 *b"]:
    """Signed compaction resistance per side along +x [N] (3.40), summed over its patches; zero on hard ground.

    Each patch compacts like a plate of its length L and width b: sum_i A_i/((n+1) L k^(1/n)) p_i^((n+1)/n)
    over the points of one patch is Bekker's b k z^(n+1)/(n+1) for a uniform pressure. A tyre patch is
    thus modelled as a short rigid track segment (docs/model.md §1.1), not by Bekker's rigid-wheel formula;
    every patch compacts fresh ground (a rear tyre running in the front tyre's rut is not modelled).
    """
    k = tm.bekker_modulus(terrain.k_c, terrain.k_phi, vehicle.track_width)
    per_element = tm.compaction_resistance(
        normal, kin.area, vehicle.contact_length, k, terrain.sinkage_exponent, normal.ndim - 2
    )
    resistance = contact_sum(per_element, 1, normal.ndim - 2) * terrain.deformable
    return -resistance * tm.smoothsign(kin.ground_speed, COMPACTION_SPEED_SMOOTHING)
