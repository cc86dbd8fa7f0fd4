"""Energy balance of the whole model (float64, 1 ms output):

    int V i dt = int (R i^2 + friction + internal + shear slip + compaction - conversion + external) dt
                 + Delta(kinetic energy of body and drives + magnetic energy of the motors)

The power flows come from ``physics.model.power_balance``; the balance is *not* an identity of that
function: it holds only if the forces on the body, the back torque on the sprockets (r_s' sum F),
the slip velocities (r_s' omega - (u - r y_k)) and the motor equations are mutually consistent and
the integrator solves them. Each loss term is written out here from the state as well and compared
with ``power_balance`` where it is simple (copper, electrical, stored energy).

Negative control: dropping one sizeable loss term breaks the balance by more than 1 %.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.physics.model import power_balance

T_END = 4.0
GO_STOP = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [2.0, 12.0, 12.0], [2.3, 0.0, 0.0], [4.0, 0.0, 0.0]]
TURN = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [1.5, 12.0, 12.0], [1.8, 16.0, -6.0], [4.0, 16.0, -6.0]]
LOSSES = ("copper", "friction", "internal", "shear_slip", "compaction", "external")


@pytest.fixture(scope="module", autouse=True)
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module", params=[(t, m) for t in ("dry_sand", "asphalt") for m in ("go_stop", "turn")],
                ids=lambda tm: f"{tm[0]}-{tm[1]}")
def energies(request, x64):
    terrain, maneuver = request.param
    p = te.load_params(terrain, dtype=jnp.float64)
    rows = GO_STOP if maneuver == "go_stop" else TURN
    traj = te.simulate(p, te.VoltageProfile.from_breakpoints(rows, dtype=jnp.float64), T_END, dt=0.001, substep=0.001)
    assert traj.t.dtype == jnp.float64 and traj.state.vel.dtype == jnp.float64
    pb = jax.vmap(lambda s, v: power_balance(s, v, p))(traj.state, traj.voltage)
    pb = {k: np.asarray(v, np.float64) for k, v in pb._asdict().items()}
    t = np.asarray(traj.t, np.float64)
    integral = {k: np.trapezoid(v, t) for k, v in pb.items() if k != "stored"}
    integral["delta_stored"] = pb["stored"][-1] - pb["stored"][0]
    return p, traj, pb, integral


def imbalance(e, drop=()):
    rhs = sum(e[k] for k in LOSSES if k not in drop) - e["conversion"] + e["delta_stored"]
    return (e["electrical"] - rhs) / e["electrical"]


def test_energy_balance_closes(energies):
    _, _, _, e = energies
    assert e["electrical"] > 50.0  # J: a real maneuver
    err = imbalance(e)
    assert abs(err) < 1e-2, err
    assert abs(err) < 1e-3, err  # measured ~2e-5..6e-5 at 1 ms
    # every loss dissipates (net over the maneuver)
    for k in ("copper", "friction", "internal", "shear_slip", "compaction"):
        assert e[k] >= 0.0, (k, e[k])


def test_negative_control_dropping_a_loss_breaks_the_balance(energies):
    _, _, _, e = energies
    assert abs(imbalance(e, drop=("shear_slip",))) > 1e-2
    # and so does every other loss term that carries more than 2 % of the input energy
    for k in LOSSES:
        if abs(e[k]) > 0.02 * e["electrical"]:
            assert abs(imbalance(e, drop=(k,))) > 1e-2, k


def test_power_terms_match_hand_formulas(energies):
    """The simple flows, recomputed here from the state and the raw parameters."""
    p, traj, pb, _ = energies
    v = p.vehicle
    i = np.asarray(traj.state.current, np.float64)
    w = np.asarray(traj.state.omega, np.float64)
    vel = np.asarray(traj.state.vel, np.float64)
    volts = np.asarray(traj.voltage, np.float64)
    R, L, J, m, Iz = (float(x) for x in (v.motor_resistance, v.motor_inductance, v.drive_inertia, v.mass, v.yaw_inertia))
    np.testing.assert_allclose(pb["electrical"], (volts * i).sum(axis=1), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(pb["copper"], (R * i * i).sum(axis=1), rtol=1e-10, atol=1e-9)
    stored = (0.5 * m * (vel[:, 0] ** 2 + vel[:, 1] ** 2) + 0.5 * Iz * vel[:, 2] ** 2
              + (0.5 * J * w * w + 0.5 * L * i * i).sum(axis=1))
    np.testing.assert_allclose(pb["stored"], stored, rtol=1e-10, atol=1e-9)
    # drive-train friction (4.1): (b_eff |omega| + tau_stick) |omega| away from omega = 0
    b, tau = float(v.drive_damping), float(v.stiction_torque)
    moving = np.abs(w) > 0.05
    np.testing.assert_allclose(pb["friction"][moving.all(axis=1)],
                               ((b * w + tau * np.sign(w)) * w).sum(axis=1)[moving.all(axis=1)], rtol=1e-9)


@pytest.mark.parametrize("terrain", ["asphalt", "sandy_loam_1"])
def test_energy_balance_closes_on_the_wheeled_husky(terrain):
    """Two tyre patches per side and a gear efficiency of 0.7: the balance still closes, and the gear loss
    shows as a negative conversion term ((alpha - alpha_v) i omega with alpha = eta K_t G_r < alpha_v)."""
    p = te.load_params(terrain, vehicle="husky", dtype=jnp.float64)
    traj = te.simulate(p, te.VoltageProfile.from_breakpoints(TURN, dtype=jnp.float64), T_END, dt=0.001, substep=0.001)
    pb = jax.vmap(lambda s, v: power_balance(s, v, p))(traj.state, traj.voltage)
    pb = {k: np.asarray(v, np.float64) for k, v in pb._asdict().items()}
    t = np.asarray(traj.t, np.float64)
    e = {k: np.trapezoid(v, t) for k, v in pb.items() if k != "stored"}
    e["delta_stored"] = pb["stored"][-1] - pb["stored"][0]
    assert e["electrical"] > 50.0
    assert abs(imbalance(e)) < 1e-3, imbalance(e)
    assert e["conversion"] < -0.05 * e["electrical"]  # the gear loses a sizeable share
    without_gear_loss = dict(e, conversion=0.0)
    assert abs(imbalance(without_gear_loss)) > 1e-2  # and the balance needs it
