"""Steady thrust of one track vs slip: the model's 14-point discrete sum vs Wong's closed form (2.25).

Under steady conditions the shear displacement grows linearly from the leading edge, j = i z (2.23),
and for a uniform pressure p = W/(b L) Janosi's law integrates to (thesis 2.25, Wong)

    F = (A c + W tan phi) [1 - K/(i L) (1 - exp(-i L / K))],   A = b L.

The model replaces the integral by the trapezoid rule on N = 14 contact points (docs/model.md §1), using
its own force function (``contact.forces_from_saturated``) here. The closed form is the reference;
the discretisation error must be small at N = 14 and shrink at second order as N grows.

Also checked: the simulator's own shear-displacement states at steady state are j_i = s z*_i / V_t,
with z* measured from the front when driving forward and from the rear in reverse ((3.14), §3.4.2.2).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.physics import contact, geometry

G = 9.81
SLIPS = np.array([0.05, 0.1, 0.2, 0.4, 0.6, 0.8])


def wong_thrust(slip, c, phi, K, b, L, W):
    """(2.25): single-track thrust for uniform pressure and Janosi's law [N]."""
    return (b * L * c + W * math.tan(phi)) * (1.0 - K / (slip * L) * (1.0 - np.exp(-slip * L / K)))


def discrete_thrust(params, slip, n_contact):
    """Sum of the model's element forces at the steady displacement j_i = slip * z*_i."""
    veh = dataclasses.replace(params.vehicle, n_contact=n_contact)
    area = geometry.contact_area(veh, 0)[0]  # (N,)
    x = geometry.contact_x(veh, 0)[0]
    z_star = 0.5 * veh.contact_length - x  # from the front
    weight = veh.mass * G / 2.0
    pressure = weight / (veh.track_width * veh.contact_length)
    j = slip * z_star
    longitudinal, lateral = contact.forces_from_saturated(params.terrain, area, pressure * area, j, jnp.zeros_like(j))
    assert float(jnp.max(jnp.abs(lateral))) == 0.0
    return float(jnp.sum(longitudinal))


def closed_form(params, slip):
    v, t = params.vehicle, params.terrain
    return wong_thrust(slip, float(t.cohesion), float(t.friction_angle), float(t.shear_modulus),
                       float(v.track_width), float(v.contact_length), float(v.mass) * G / 2.0)


def rel_errors(params, n_contact):
    return np.array([discrete_thrust(params, s, n_contact) / closed_form(params, s) - 1.0 for s in SLIPS])


@pytest.mark.parametrize("terrain,tol", [("dry_sand", 0.01), ("asphalt", 0.02)])
def test_14_points_match_wong_closed_form(terrain, tol):
    # Measured: dry sand -0.09 % (i = 0.05) .. -0.82 % (i = 0.8); asphalt (K = 9 mm) -0.2 % .. -1.9 %:
    # at high slip on asphalt the shear stress saturates within K/i ~ 1 cm, less than one element.
    err = rel_errors(te.load_params(terrain), 14)
    assert np.all(np.abs(err) < tol), err
    # the trapezoid rule under-estimates a concave integrand: the error is one-signed
    assert np.all(err < 0.0), err


@pytest.mark.parametrize("terrain", ["dry_sand", "asphalt"])
def test_discrete_thrust_converges_at_second_order(terrain):
    p = te.load_params(terrain)
    e14, e28, e56 = (np.abs(rel_errors(p, n)) for n in (14, 28, 56))
    assert np.all(e28 < e14) and np.all(e56 < e28)
    # trapezoid rule: error ~ spacing^2; (27/13)^2 = 4.3, (55/27)^2 = 4.1
    assert np.all(e14 / e28 > 3.0), e14 / e28
    assert np.all(e28 / e56 > 3.0), e28 / e56
    assert np.max(e56) < 2e-3


def test_thrust_is_odd_in_slip_and_vanishes_at_zero():
    p = te.load_params("dry_sand")
    for s in (0.1, 0.5):
        assert discrete_thrust(p, -s, 14) == pytest.approx(-discrete_thrust(p, s, 14), rel=1e-6)
    assert discrete_thrust(p, 0.0, 14) == 0.0
    # high-slip limit: the full shear strength A c + W tan(phi) (2.25 as i -> inf), minus the first
    # element's half share which never shears
    big = discrete_thrust(p, 1e3, 14)
    v, t = p.vehicle, p.terrain
    full = float(v.track_width * v.contact_length * t.cohesion + v.mass * G / 2 * jnp.tan(t.friction_angle))
    assert big == pytest.approx(full * (1.0 - 0.5 / 13.0), rel=1e-4)


@pytest.mark.parametrize("volts", [11.8, -11.8])
def test_simulated_shear_displacement_is_linear_from_the_leading_edge(volts):
    """The simulator's steady j_z states vs (2.22)/(3.14): j_i = s z*_i / V_t, leading edge = front
    when driving forward, rear in reverse."""
    p = te.load_params("dry_sand")
    prof = te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [0.3, volts, volts], [8.0, volts, volts]])
    traj = te.simulate(p, prof, 8.0, dt=0.05, substep=0.001)
    omega = float(traj.state.omega[-1, 0])
    u = float(traj.state.vel[-1, 0])
    r_s = float(p.vehicle.sprocket_radius)
    v_t = r_s * omega
    slip = v_t - u
    L, n = float(p.vehicle.contact_length), p.vehicle.n_contact
    z_front = np.arange(n) * L / (n - 1)
    z_star = z_front if volts > 0 else z_front[::-1]
    ref = slip * z_star / abs(v_t)
    jz = np.asarray(traj.state.jz[-1], np.float64)  # (2, N)
    assert np.sign(slip) == np.sign(volts) and abs(slip) > 2e-3
    for k in range(2):
        np.testing.assert_allclose(jz[k], ref, rtol=1e-3, atol=1e-3 * np.max(np.abs(ref)))
    # the (rear) trailing point in forward motion carries the largest displacement: s L / V_t
    assert np.abs(jz[0]).max() == pytest.approx(abs(slip) * L / abs(v_t), rel=1e-3)
