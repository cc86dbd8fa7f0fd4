"""Fixed-step exponential RK4 (Cox-Matthews ETDRK4) with substeps, for the vehicle model.

The model has two stiff *linear* decay terms (docs/model.md §6): the motor circuit, di/dt = -(R_m/L_m) i
+ ..., with R_m/L_m = 3950 1/s, and the shear displacements, dj/dt = -(|V_t|/z*) j + ..., with rates
up to 1e6 1/s at the leading edge. ETDRK4 integrates dx/dt = -lambda x + N(x) exactly in its linear
part, so these terms cost nothing in step size; every other state is advanced by classical RK4 (ETDRK4
with lambda = 0 *is* classical RK4).

The shear decay rate lambda = |V_t|/z* depends on the sprocket speed. It is frozen over each substep at
the belt speed predicted for the substep's midpoint (omega + h/2 domega/dt), which keeps the frozen-rate
error second order while a voltage ramp changes V_t; z* and the leading edge are taken at the start of
the substep. z-tilde* (3.31) is not: when the steering reverses, z-bar sweeps along the track within a few
milliseconds and each element it passes has its j_x reset (the rate |V_t|/z-tilde* is singular there), so
j_x's rate is |V_t| times the mean of 1/max(z-tilde*, Delta Z) over the substep, integrated in closed form
with v and r linear in time (:func:`trackenv.physics.contact.mean_inverse_z_tilde`). The rates of the motor
circuit are constant and computed once per call.

Reference: S. M. Cox, P. C. Matthews, "Exponential time differencing for stiff systems",
J. Comput. Phys. 176 (2002) 430-455; phi-function form after Hochbruck & Ostermann, Acta Numerica 2010.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .params import Params
from .physics import contact
from .physics.model import Evaluation, State, evaluate
from .physics.motor import current_decay_rate, resistance_slope
from .physics.sums import contact_sum, divide_by_parameter

_TAYLOR_CUTOFF = 1.0  # |z| below which the phi-functions use their Taylor series


def _taylor_terms(dtype) -> int:
    """Terms of phi_3's series for |z| < 1: the truncation, |z|^n/(n+3)!, under the dtype's epsilon."""
    return 10 if jnp.finfo(dtype).bits <= 32 else 17


def _series(z: Float[Array, " *s"], k: int, terms: int) -> Float[Array, " *s"]:
    """phi_k(z) = sum_{j < terms} z^j / (j + k)! by Horner's rule."""
    acc = jnp.full_like(z, 1.0 / math.factorial(terms - 1 + k))
    for j in range(terms - 2, -1, -1):
        acc = acc * z + 1.0 / math.factorial(j + k)
    return acc


def phi_functions(
    z: Float[Array, " *s"], e: Float[Array, " *s"] | None = None
) -> tuple[Float[Array, " *s"], Float[Array, " *s"], Float[Array, " *s"]]:
    """phi_1, phi_2, phi_3 of z = -h lambda <= 0, accurate for every z (Taylor series near 0).

    phi_k(z) = sum_j z^j / (j + k)!, and phi_k(z) = 1/k! + z phi_{k+1}(z). For |z| < 1, phi_3 by its
    series and phi_2, phi_1 by that recurrence (multiplying by |z| < 1 does not amplify errors); for
    |z| >= 1, phi_1 = (e^z - 1)/z and phi_{k+1} = (phi_k - 1/k!)/z (dividing by |z| >= 1 does not either).
    ``e``: e^z if already computed. At |z| >= 1, e^z - 1 loses nothing to cancellation, so ``expm1`` is not
    needed: XLA's CPU ``expm1`` is not vectorised, and on the 61 exponential states of a substep it cost
    as much as all the rest of the substep.
    """
    small = jnp.abs(z) < _TAYLOR_CUTOFF
    zs = jnp.where(small, z, 0.0)
    s3 = _series(zs, 3, _taylor_terms(z.dtype))
    s2 = 0.5 + zs * s3
    s1 = 1.0 + zs * s2
    inv = 1.0 / jnp.where(small, -1.0, z)
    d1 = ((jnp.exp(z) if e is None else e) - 1.0) * inv
    d2 = (d1 - 1.0) * inv
    d3 = (d2 - 0.5) * inv
    return jnp.where(small, s1, d1), jnp.where(small, s2, d2), jnp.where(small, s3, d3)


class Coeffs(NamedTuple):
    """ETDRK4 coefficients for one state component (scalars for plain RK4)."""

    E: object  # e^{z}
    E2: object  # e^{z/2}
    Q: object  # (h/2) phi_1(z/2)
    f1: object  # h (phi1 - 3 phi2 + 4 phi3)
    f2: object  # h (phi2 - 2 phi3)
    f3: object  # h (4 phi3 - phi2)


def etd_coeffs(rate: Float[Array, " *s"], h: Float[ArrayLike, ""]) -> Coeffs:
    """ETDRK4 coefficients for decay ``rate`` (lambda >= 0) over a step ``h``."""
    z = jnp.asarray(-h * rate)
    e2 = jnp.exp(0.5 * z)  # the one exponential of the substep per state: e^z = (e^{z/2})^2
    e = e2 * e2
    p1, p2, p3 = phi_functions(z, e)
    half = p1 / (1.0 + e2)  # (1/2) phi_1(z/2), from phi_1(z) = phi_1(z/2) (e^{z/2} + 1)/2
    return Coeffs(e, e2, h * half, h * (p1 - 3.0 * p2 + 4.0 * p3), h * (p2 - 2.0 * p3), h * (4.0 * p3 - p2))


def rk4_coeffs(h: Float[ArrayLike, ""]) -> Coeffs:
    """Classical RK4 as the lambda = 0 limit of ETDRK4."""
    return Coeffs(1.0, 1.0, 0.5 * h, h / 6.0, h / 6.0, h / 6.0)


def _is_coeffs(x) -> bool:
    return isinstance(x, Coeffs)


def _tree_coeffs(state: State, current: Coeffs, jz: Coeffs, jx: Coeffs, omega: Coeffs, vel: Coeffs, h) -> State:
    rk = rk4_coeffs(h)
    return State(rk, vel, omega, current, jz, jx, jax.tree.map(lambda _: rk, state.extra))


def _map(fn, coeffs: State, *trees: State) -> State:
    return jax.tree.map(fn, coeffs, *trees, is_leaf=_is_coeffs)


def diagonal_damping(
    params: Params, state: State, ev: Evaluation
) -> tuple[Float[Array, " 2 *b"], Float[Array, " 3 *b"]]:
    """Frozen diagonal Jacobian -df/dx of the sprocket speeds and body velocities (clamped >= 0).

    Near zero slip the saturation of j_z (3.17) and j_x (3.33) makes the contact forces very steep
    in the slip s and the lateral velocity v_y: dF/ds = (dF/dj') j_z dS/d|s|, with dS/d|s| up to
    1.875/(1.4e-2 m/s). Through the small sprocket inertia this is a decay rate r_s'^2 dF/ds / J_eff
    of order 1e3-1e4 1/s, which explicit RK4 cannot take at millisecond steps. These diagonal rates are
    integrated exponentially and the rest, f + lambda (x - x0), by RK4: an exact reformulation.

    """
    veh, kin = params.vehicle, ev.kin
    # Closed forms of the slopes (terramechanics/contact/motor *_slope), equal to forward-mode JVPs of
    # the force laws (tests/test_damping.py) without re-tracing them.
    sat_z, sat_x = contact.saturations(kin)
    ds_z, ds_x = contact.saturation_slopes(kin)
    dfl_dj, dflat_dj = contact.force_slopes(params.terrain, kin.area, ev.forces.normal,
                                            state.jz * sat_z, state.jx * sat_x)
    dfl_ds = dfl_dj * state.jz * ds_z  # dF/ds = dF/dj' * j_z * dS/ds (chain rule through 3.17)
    dflat_dvy = dflat_dj * state.jx * ds_x
    dtau_dw = resistance_slope(veh, params.internal, state.omega)
    nb = state.vel.ndim - 1
    traction = contact_sum(dfl_ds, 1, nb)  # (2, *b) dF_x,k/ds_k
    lam_w = divide_by_parameter(dtau_dw + kin.belt_radius**2 * traction, veh.drive_inertia)
    lam_u = divide_by_parameter(contact_sum(traction, 0, nb), veh.mass)
    lam_v = -divide_by_parameter(contact_sum(dflat_dvy, (0, 1), nb), veh.mass)
    lam_r = divide_by_parameter(contact_sum(kin.y**2 * traction, 0, nb) - contact_sum(kin.x**2 * dflat_dvy, (0, 1), nb),
                                veh.yaw_inertia)
    lam_vel = jnp.stack([lam_u, lam_v, lam_r])
    return jnp.maximum(lam_w, 0.0), jnp.maximum(lam_vel, 0.0)


def _with_omega(state: State, omega: Float[Array, " 2 *b"]) -> State:
    return eqx.tree_at(lambda s: s.omega, state, omega)


def etdrk4_substep(
    state: State, volts3: Float[Array, " 3 2 *b"], params: Params, h: Float[ArrayLike, ""], current: Coeffs,
    omega3: Float[Array, " 3 2 *b"] | None = None,
) -> State:
    """One ETDRK4 substep of length ``h`` [s]; ``volts3`` (3, 2, *b) holds V at t, t+h/2, t+h.

    With ``omega3`` (3, 2, *b), the sprocket speeds at t, t+h/2, t+h [rad/s], the drive is *speed
    prescribed*: omega is set to those values at every stage instead of being integrated from (4.1),
    ``volts3`` is ignored, and the motor current is left unchanged (it follows algebraically from the
    torque balance, :func:`trackenv.physics.model.prescribed_speed_current`).
    """
    if omega3 is not None:
        state = _with_omega(state, omega3[0])
    ev = evaluate(state, volts3[0], params)
    omega_mid = state.omega + 0.5 * h * ev.drive.omega if omega3 is None else omega3[1]
    speed = ev.kin.belt_radius * omega_mid  # V_t at the substep's midpoint [m/s]
    lam_z = contact.longitudinal_decay_rate(speed, ev.kin)  # (3.14), at the midpoint belt speed
    lam_w, lam_vel = jax.lax.stop_gradient(diagonal_damping(params, state, ev))
    # j_x's rate: |V_t| times the mean of 1/max(z-tilde*, Delta Z) over the substep, with v and r linear between
    # the start and a prediction at its end (Euler, damped by the diagonal rates: the (1,1) Pade form of
    # exponential Euler), so that z-bar sweeping past an element within the substep resets that element's j_x
    # (3.32) as the continuous model does.
    vel_end = state.vel + h * ev.drive.vel / (1.0 + 0.5 * h * lam_vel)
    lam_x = jnp.abs(speed)[:, None] * contact.mean_inverse_z_tilde(params.vehicle, ev.kin, vel_end, state.vel,
                                                                   state.vel.ndim - 1)
    c = _tree_coeffs(state, current, etd_coeffs(lam_z, h), etd_coeffs(lam_x, h),
                     etd_coeffs(lam_w, h), etd_coeffs(lam_vel, h), h)

    # omega and vel are integrated as deviations y = x - x0 with N = f(x) + lambda (x - x0).
    zero = jax.tree.map(jnp.zeros_like, state)
    shift = State(zero.pose, state.vel, state.omega, zero.current, zero.jz, zero.jx, zero.extra)

    def drive(x, ev_x):
        d = ev_x.drive
        return State(d.pose, d.vel + lam_vel * (x.vel - state.vel), d.omega + lam_w * (x.omega - state.omega),
                     d.current, d.jz, d.jx, d.extra)

    y0 = _map(lambda k, u, s: u - s, c, state, shift)
    n_u = drive(state, ev)
    pin = (lambda x, i: x) if omega3 is None else (lambda x, i: _with_omega(x, omega3[i]))  # noqa: E731
    a = pin(_map(lambda k, s, y, n: s + k.E2 * y + k.Q * n, c, shift, y0, n_u), 1)
    n_a = drive(a, evaluate(a, volts3[1], params))
    b = pin(_map(lambda k, s, y, n: s + k.E2 * y + k.Q * n, c, shift, y0, n_a), 1)
    n_b = drive(b, evaluate(b, volts3[1], params))
    cc = pin(_map(lambda k, s, x, nb, nu: s + k.E2 * (x - s) + k.Q * (2.0 * nb - nu), c, shift, a, n_b, n_u), 2)
    n_c = drive(cc, evaluate(cc, volts3[2], params))
    out = _map(
        lambda k, s, y, nu, na, nb, nc: s + k.E * y + k.f1 * nu + 2.0 * k.f2 * (na + nb) + k.f3 * nc,
        c, shift, y0, n_u, n_a, n_b, n_c,
    )
    if omega3 is None:
        return out
    return eqx.tree_at(lambda s: (s.omega, s.current), out, (omega3[2], state.current))


def current_coeffs(params: Params, h: Float[ArrayLike, ""]) -> Coeffs:
    """ETDRK4 coefficients of the motor circuit (constant rate R_m/L_m), once per call."""
    return etd_coeffs(current_decay_rate(params.vehicle), h)


def advance(
    state: State, volts: Float[Array, " n 3 2 *b"], params: Params, h: Float[ArrayLike, ""], unroll: int = 1,
    speed_prescribed: bool = False,
) -> State:
    """Advance ``state`` over ``volts.shape[0]`` substeps of length ``h``.

    ``volts``: (n_substeps, 3, 2, *b), the voltages at each substep's start, middle and end.

    **Arguments:**

    - `state`: the vehicle state at the start (SI).
    - `volts`: motor voltages [V], shape (n, 3, 2, *b): substep, (start, middle, end), track.
    - `params`: the model parameters.
    - `h`: the substep length [s].
    - `unroll`: ``jax.lax.scan``'s unroll factor (compile time vs run time; no effect on the result).
    - `speed_prescribed`: if true, ``volts`` holds the prescribed sprocket speeds [rad/s] instead of
      voltages (see :func:`etdrk4_substep`).

    **Returns:**

    The state after n substeps, a time n h [s] later.
    """
    cur = current_coeffs(params, h)

    def body(s, v3):
        if speed_prescribed:
            return etdrk4_substep(s, jnp.zeros_like(v3), params, h, cur, omega3=v3), None
        return etdrk4_substep(s, v3, params, h, cur), None

    state, _ = jax.lax.scan(body, state, volts, unroll=unroll)
    return state


def advance_constant(
    state: State,
    voltage: Float[Array, " 2 *b"],
    params: Params,
    dt: Float[ArrayLike, ""],
    substeps: int,
    unroll: int = 1,
    integrand: Callable[[State], Float[Array, " *s"]] | None = None,
    integrand_start: Float[Array, " *s"] | None = None,
) -> State | tuple[State, Float[Array, " *s"]]:
    """Advance ``state`` by one control step ``dt`` with the voltage (2, *b) held constant.

    If ``integrand`` (a function of the state, e.g. the supply power) is given, also return its
    trapezoid-rule integral over the substeps, starting from ``integrand_start`` (default: its value at
    ``state``): ``(state, integral)``.

    **Arguments:**

    - `state`: the vehicle state at the start (SI).
    - `voltage`: motor voltages, left/right [V], shape (2, *b), held over the step.
    - `params`: the model parameters.
    - `dt`: the control step [s].
    - `substeps`: the number of ETDRK4 substeps, each ``dt / substeps`` long.
    - `unroll`: ``jax.lax.fori_loop``'s unroll factor (no effect on the result).
    - `integrand`: optional function of the state (e.g. the supply power [W]).
    - `integrand_start`: its value at the start; default ``integrand(state)``.

    **Returns:**

    The state a time ``dt`` later; with ``integrand``, ``(state, integral)``, the integral in the
    integrand's unit times seconds (e.g. J for a power).
    """
    h = dt / substeps
    cur = current_coeffs(params, h)
    v3 = jnp.broadcast_to(voltage[None], (3,) + voltage.shape)
    if integrand is None:
        return jax.lax.fori_loop(0, substeps, lambda _, s: etdrk4_substep(s, v3, params, h, cur), state,
                                 unroll=unroll)

    def body(_, carry):
        s, f_prev, total = carry
        s = etdrk4_substep(s, v3, params, h, cur)
        f = integrand(s)
        return s, f, total + 0.5 * h * (f_prev + f)

    f0 = integrand(state) if integrand_start is None else integrand_start
    out, _, total = jax.lax.fori_loop(0, substeps, body, (state, f0, jnp.zeros_like(f0)), unroll=unroll)
    return out, total


# A state beyond these multiples of the drive's stall current and no-load speed (at the bus voltage)
# is not a physical state of the vehicle but the start of a numerical blow-up: flag it at once rather
# than after the numbers overflow.
BOUND_FACTOR = 10.0


def physical_bounds(params: Params) -> tuple[Float[Array, " *#b"], Float[Array, " *#b"]]:
    """Largest physical |current| [A] and |omega| [rad/s]: ``BOUND_FACTOR`` x the stall current
    V_lim/R_m (4.2 at omega = 0) and the no-load speed V_lim/alpha_v (4.2 at i = 0)."""
    veh = params.vehicle
    return (BOUND_FACTOR * veh.voltage_limit / veh.motor_resistance,
            BOUND_FACTOR * veh.voltage_limit / veh.alpha_v)


def is_physical(state: State, params: Params, nb: int) -> Bool[Array, " *b"]:
    """Per-vehicle flag, shape (*b): every component is finite and the motor currents and sprocket
    speeds are within :func:`physical_bounds`."""
    i_max, w_max = physical_bounds(params)
    axes = tuple(range(state.current.ndim - nb))
    bounded = (jnp.abs(state.current) <= i_max).all(axis=axes) & (jnp.abs(state.omega) <= w_max).all(axis=axes)
    return is_finite(state, nb) & bounded


def is_finite(state: State, nb: int) -> Bool[Array, " *b"]:
    """Per-vehicle flag: every state component is finite; shape (*b)."""
    leaves = jax.tree.leaves(state)
    flags = [jnp.isfinite(x).all(axis=tuple(range(x.ndim - nb))) for x in leaves]
    out = flags[0]
    for f in flags[1:]:
        out = out & f
    return out
