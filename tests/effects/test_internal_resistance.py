import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.effects import InternalResistance, get_effect
from trackenv.effects.internal_resistance import OMEGA_SMOOTHING
from trackenv.physics.model import initial_state
from trackenv.simulate import simulate_core

GO_2MS = [[0, 0, 0], [0.3, 21.0, 21.0], [8, 21.0, 21.0]]


def test_torque_law():
    e = get_effect("internal_resistance", b0=0.5, b1=0.1)
    w = jnp.array([-20.0, -1.0, 0.0, 1.0, 20.0])
    np.testing.assert_allclose(e.torque(w), [-0.5 - 2.0, -0.6, 0.0, 0.6, 2.5], rtol=1e-6)
    assert float(e.torque(jnp.asarray(OMEGA_SMOOTHING / 2))) < 0.5 + 0.1  # smoothed near 0


def run(effect, rows=GO_2MS):
    p = te.load_params("dry_sand", effects=(effect,) if effect else ())
    tr = te.simulate(p, te.VoltageProfile.from_breakpoints(rows), 6.0, substep=0.001)
    return p, float(np.mean(np.asarray(tr.channels["i_left"])[-20:])), tr


def test_constant_default_and_linear_law_currents():
    p, i_base, tr = run(None)
    assert i_base == pytest.approx(2.1292, rel=0.01)  # docs/model.md §10
    # same as the base constant model
    _, i_const, _ = run(get_effect("internal_resistance", b0=0.78, b1=0.0))
    assert i_const == pytest.approx(i_base, rel=1e-3)
    # speed-linear law: i = (b0 + b1 w + b_eff w + tau_stick + tau_back)/alpha
    b0, b1 = 0.4, 0.04
    _, i_lin, tr = run(get_effect("internal_resistance", b0=b0, b1=b1))
    w = float(np.mean(np.asarray(tr.channels["omega_left"])[-20:]))
    veh = p.vehicle
    tau_back_base = float(veh.alpha) * i_base - 0.78 - float(veh.drive_damping) * 22.5 - float(veh.stiction_torque)
    pred = (b0 + b1 * w + float(veh.drive_damping) * w + float(veh.stiction_torque) + tau_back_base) / float(veh.alpha)
    assert i_lin == pytest.approx(pred, rel=0.02)
    assert i_lin > i_base + 0.3  # 0.4 + 0.9 N m vs 0.78 N m: visibly more current


def test_default_fits_field_anchors():
    """Default b0 = 0.88 N m: 1.98 A at 1.1 m/s and 2.23 A at 2 m/s (thesis §5.4.1) within 2%."""
    e = InternalResistance.default()
    _, i2, _ = run(e)
    _, i1, _ = run(e, [[0, 0, 0], [0.3, 11.8, 11.8], [8, 11.8, 11.8]])
    assert i2 == pytest.approx(2.23, rel=0.02)
    assert i1 == pytest.approx(1.98, rel=0.02)


def test_grad_finite():
    prof = te.VoltageProfile.from_breakpoints(GO_2MS)

    def final_speed(b1):
        p = te.load_params("dry_sand", effects=(InternalResistance(jnp.asarray(0.4), b1),))
        return simulate_core(p, prof, initial_state(p), n_steps=20, dt=0.05, substeps=50).channels["speed_ideal"][-1]

    g = jax.grad(final_speed)(jnp.asarray(0.04))
    assert np.isfinite(g) and g < 0


def test_quadratic_term_torque():
    """tau = b0 smoothsign + b1 w + b2 w|w| (the quadratic member of the family)."""
    import jax.numpy as jnp

    e = get_effect("internal_resistance", b0=0.3, b1=0.01, b2=0.002)
    w = jnp.array([-20.0, 20.0])
    tau = np.asarray(e.torque(w))
    np.testing.assert_allclose(tau, [-(0.3 + 0.2 + 0.8), 0.3 + 0.2 + 0.8], rtol=1e-5)
