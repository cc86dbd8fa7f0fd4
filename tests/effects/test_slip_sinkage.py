import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.effects import SlipSinkage, get_effect
from trackenv.physics.model import evaluate, initial_state

from .conftest import sim


def forces_at(z, terrain="dry_sand", vel=(0.0, 0.0, -1.0), omega=(5.0, -5.0)):
    e = get_effect("slip_sinkage")
    p = te.load_params(terrain, effects=(e,))
    s = initial_state(p)
    s = eqx.tree_at(lambda s: (s.vel, s.omega, s.extra), s,
                    (jnp.asarray(vel), jnp.asarray(omega), {"slip_sinkage": jnp.full((2,), z)}))
    pb = te.load_params(terrain)
    sb = eqx.tree_at(lambda s: (s.vel, s.omega), initial_state(pb), (jnp.asarray(vel), jnp.asarray(omega)))
    return evaluate(s, jnp.zeros(2), p), evaluate(sb, jnp.zeros(2), pb), e, p


def test_passive_pressure_hand_value():
    from trackenv.effects.slip_sinkage import passive_pressure_force
    # phi = 30 deg: N_phi = 3; gamma z^2 N/2 + 2 c z sqrt(N)
    q = passive_pressure_force(jnp.asarray(0.05), 1000.0, jnp.deg2rad(30.0), 16000.0)
    assert float(q) == pytest.approx(16000 * 0.0025 * 3 / 2 + 2 * 1000 * 0.05 * np.sqrt(3), rel=1e-5)


def test_zero_at_zero_sinkage_and_grows_and_opposes():
    ev0, base, e, p = forces_at(0.0)
    np.testing.assert_allclose(ev0.forces.lateral, base.forces.lateral, atol=1e-5)
    np.testing.assert_allclose(ev0.forces.compaction, base.forces.compaction, atol=1e-5)
    moments = []
    for z in (0.02, 0.05):
        ev, base, e, p = forces_at(z)
        dlat = np.asarray(ev.forces.lateral - base.forces.lateral)
        vy = np.asarray(ev.kin.lateral_velocity)
        assert np.all(dlat * vy <= 1e-6)  # side bulldozing opposes lateral velocity
        m = float((ev.kin.x * (ev.forces.lateral - base.forces.lateral)).sum())
        moments.append(m)
        # hand value: q(z) L^2/4 per track for r x over the whole length (|v_y| > v_s except near x = 0)
        q = float(e.wall_force(type("C", (), {"params": p})(), jnp.asarray(z)))
        assert m == pytest.approx(2 * q * 0.508**2 / 4, rel=0.05)
        dfront = np.asarray(ev.forces.compaction - base.forces.compaction)
        assert np.all(dfront * np.asarray(ev.kin.ground_speed) < 0)  # front bulldozing opposes ground speed
        assert abs(dfront[0]) == pytest.approx(float(p.vehicle.track_width) * q, rel=1e-3)
    assert moments[0] > 0 and moments[1] > 2 * moments[0]  # resists the clockwise turn (r < 0); grows with z


def test_nothing_on_hard_ground():
    ev, base, _, _ = forces_at(0.05, "asphalt")
    np.testing.assert_allclose(ev.forces.lateral, base.forces.lateral, atol=1e-5)
    np.testing.assert_allclose(ev.forces.compaction, base.forces.compaction, atol=1e-5)
    assert float(jnp.abs(ev.drive.extra["slip_sinkage"]).max()) == 0.0


def test_zrt_calibration():
    """ZRT dry sand ±12 V: yaw falls from the base -5.0 rad/s to ~1/11 within a few s, stalls, sinks 2-3 in."""
    tr = sim("dry_sand", (get_effect("slip_sinkage"),), t_end=20.0)
    y = np.asarray(tr.channels["yaw_rate"])
    t = np.asarray(tr.t)
    z = np.asarray(tr.state.extra["slip_sinkage"])
    base = -5.002
    assert y[t == 1.0][0] < 0.8 * base * 0 - 3.5  # still turning fast at first
    ratio = base / np.mean(y[(t >= 3.0) & (t <= 6.0)])
    assert 5 < ratio < 25  # ≈ 1/11 (field) after a few seconds
    assert np.all(np.abs(y[t >= 15.0]) < 0.1 * abs(base) / 11)  # stalled
    assert 0.05 <= z[-1, 0] <= 0.075 and z[-1, 0] == pytest.approx(z[-1, 1], rel=1e-4)
    assert np.all(np.diff(z[:, 0]) >= -1e-7)


def test_vmap_and_grad():
    from trackenv.simulate import simulate_core
    prof = te.VoltageProfile.from_breakpoints([[0, 0, 0], [0.3, 12, -12], [5, 12, -12]])

    def final_yaw(kb):
        e = eqx.tree_at(lambda m: m.bulldozing_factor, SlipSinkage.default(), kb)
        p = te.load_params("dry_sand", effects=(e,))
        return simulate_core(p, prof, initial_state(p), n_steps=16, dt=0.05, substeps=50).channels["yaw_rate"][-1]

    ys = jax.vmap(final_yaw)(jnp.array([0.0, 5.0]))
    assert float(ys[1]) > float(ys[0])  # less negative: slower turn
    g = jax.grad(final_yaw)(jnp.asarray(2.0))
    assert np.isfinite(g)
