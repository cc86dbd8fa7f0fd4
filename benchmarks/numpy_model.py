"""The base vehicle model as a plain numpy right-hand side, for timing against scipy's solvers.

An independent transcription of the base model (docs/model.md §1-5: Janosi shear, z*/z-bar logic, Bekker
compaction, roll load transfer, the two DC motor circuits; no effects) as a function
``rhs(t, y) -> dy/dt`` on the flat 66-number state [X, Y, psi, u, v, r, omega_l, omega_r, i_l, i_r,
j_z (2 x N), j_x (2 x N)], written for ``scipy.integrate.solve_ivp``. :func:`check` compares it with
``trackenv.physics.model.derivative`` at a state so that the benchmark times the same model.
"""

from __future__ import annotations

import numpy as np

G = 9.81
LE_SPEED, MIN_Z = 1e-2, 1e-6
SAT_Z, SAT_X = (1e-3, 1.5e-2), (5e-4, 5e-3)
LONG_SMOOTH, LAT_SMOOTH, COMP_SMOOTH, OMEGA_SMOOTH = 1e-9, 3e-2, 0.2, 0.05


def step5(x, x0, h0, x1, h1):
    s = np.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    return h0 + (h1 - h0) * s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


def make_rhs(params, t_profile, v_profile):
    """numpy RHS of the base model with the voltages (K, 2) linear in time between ``t_profile``."""
    f = lambda a: float(np.asarray(a))  # noqa: E731
    veh, ter, internal = params.vehicle, params.terrain, params.internal
    if ter.shear_law != "janosi" or params.effects:
        raise ValueError("the numpy port covers the Janosi base model without effects")
    m, iz, h_cg, gauge = f(veh.mass), f(veh.yaw_inertia), f(veh.cg_height), f(veh.track_gauge)
    length, width, n = f(veh.contact_length), f(veh.track_width), int(veh.n_contact)
    rb = f(veh.sprocket_radius) + f(veh.grouser_height) * (1.0 - f(ter.deformable))
    alpha, alpha_v = f(veh.alpha), f(veh.alpha_v)
    lm, rm, jd, beff, tst = (f(veh.motor_inductance), f(veh.motor_resistance), f(veh.drive_inertia),
                             f(veh.drive_damping), f(veh.stiction_torque))
    c, tanphi, k_shear = f(ter.cohesion), np.tan(f(ter.friction_angle)), f(ter.shear_modulus)
    n_exp, deform = f(ter.sinkage_exponent), f(ter.deformable)
    k_bekker = f(ter.k_c) / width + f(ter.k_phi)
    b_const, b_visc = f(internal.constant), f(internal.viscous)
    spacing = length / (n - 1)
    x = 0.5 * length - np.arange(n) * spacing
    w = np.ones(n)
    w[0] = w[-1] = 0.5
    area = w * width * spacing
    y = np.array([0.5 * gauge, -0.5 * gauge])
    z_front, z_rear = 0.5 * length - x, x + 0.5 * length
    p0 = m * G / (2.0 * width * length)
    tp = np.asarray(t_profile, float)
    vp = np.asarray(v_profile, float)

    def rhs(t, s):
        psi, u, v, r = s[2], s[3], s[4], s[5]
        om, cur = s[6:8], s[8:10]
        jz, jx = s[10:10 + 2 * n].reshape(2, n), s[10 + 2 * n:10 + 4 * n].reshape(2, n)
        volts = np.array([np.interp(t, tp, vp[:, 0]), np.interp(t, tp, vp[:, 1])])
        vt = rb * om
        gs = u - r * y
        slip = vt - gs
        vy = v + r * x
        front = np.where(vt > LE_SPEED, True, np.where(vt < -LE_SPEED, False, gs >= 0.0))
        z_star = np.where(front[:, None], z_front, z_rear)
        vy_f, vy_r = v + r * 0.5 * length, v - r * 0.5 * length
        v_first, v_last = np.where(front, vy_f, vy_r), np.where(front, vy_r, vy_f)
        sign_change = v_first * v_last < 0.0
        z_bar = np.where(sign_change, v_first / np.where(sign_change, v_first - v_last, 1.0) * length, np.inf)
        z_tilde = np.where(z_star >= z_bar[:, None], z_star - z_bar[:, None], z_star)
        p_y = -2.0 * m * u * r * h_cg / (width * length * gauge**2)
        normal = np.maximum(area * (p0 + p_y * y)[:, None], 0.0)
        jz_s = jz * step5(np.abs(slip), SAT_Z[0], 0.0, SAT_Z[1], 1.0)[:, None]
        jx_s = jx * step5(np.abs(vy), SAT_X[0], 0.0, SAT_X[1], 1.0)
        tau_max = c + normal / area * tanphi
        fz = tau_max * (1.0 - np.exp(-np.abs(jz_s) / k_shear)) * area
        fx = tau_max * (1.0 - np.exp(-np.abs(jx_s) / k_shear)) * area
        f_long = step5(jz_s, -LONG_SMOOTH, -fz, LONG_SMOOTH, fz)
        f_lat = step5(jx_s, -LAT_SMOOTH, fx, LAT_SMOOTH, -fx)
        pe = np.maximum(normal, 0.0) / area
        rc = (area / ((n_exp + 1.0) * length * k_bekker ** (1.0 / n_exp)) * pe ** ((n_exp + 1.0) / n_exp)).sum(1)
        comp = -rc * deform * step5(gs, -COMP_SMOOTH, -1.0, COMP_SMOOTH, 1.0)
        sgn_w = step5(om, -OMEGA_SMOOTH, -1.0, OMEGA_SMOOTH, 1.0)
        tau_int = b_const * sgn_w + b_visc * om
        track_fx = f_long.sum(1) + comp
        fxb, fyb = track_fx.sum(), f_lat.sum()
        mz = (x * f_lat).sum() - (y * track_fx).sum()
        d = np.empty_like(s)
        d[0] = u * np.cos(psi) - v * np.sin(psi)
        d[1] = u * np.sin(psi) + v * np.cos(psi)
        d[2] = r
        d[3], d[4], d[5] = fxb / m + v * r, fyb / m - u * r, mz / iz
        d[6:8] = (alpha * cur - (beff * om + tst * sgn_w) - tau_int - rb * f_long.sum(1)) / jd
        d[8:10] = (volts - alpha_v * om) / lm - rm / lm * cur
        speed = np.abs(vt)[:, None]
        d[10:10 + 2 * n] = (slip[:, None] - speed / np.maximum(z_star, MIN_Z) * jz).ravel()
        d[10 + 2 * n:] = (vy - speed / np.maximum(z_tilde, MIN_Z) * jx).ravel()
        return d

    return rhs


def flat_state(state) -> np.ndarray:
    return np.concatenate([np.asarray(a, np.float64).ravel()
                           for a in (state.pose, state.vel, state.omega, state.current, state.jz, state.jx)])


def check(params, seed: int = 0) -> float:
    """Largest |numpy - JAX| derivative at a random moving state, relative to each component's scale."""
    import jax.numpy as jnp

    from trackenv.physics.model import State, derivative

    rng = np.random.default_rng(seed)
    n = int(params.vehicle.n_contact)
    st = State(pose=jnp.asarray([0.1, -0.2, 0.3]), vel=jnp.asarray([0.8, 0.02, 0.4]), omega=jnp.asarray([9.0, 11.0]),
               current=jnp.asarray([2.0, 2.5]), jz=jnp.asarray(rng.uniform(-0.01, 0.03, (2, n))),
               jx=jnp.asarray(rng.uniform(-0.01, 0.01, (2, n))), extra={})
    st = __import__("jax").tree.map(lambda a: jnp.asarray(a, params.dtype), st)
    want = flat_state(derivative(st, jnp.asarray([11.8, 12.5], params.dtype), params))
    got = make_rhs(params, [0.0, 1.0], [[11.8, 12.5], [11.8, 12.5]])(0.0, flat_state(st))
    return float(np.max(np.abs(got - want) / (np.abs(want) + 1e-3 * np.abs(want).max())))
