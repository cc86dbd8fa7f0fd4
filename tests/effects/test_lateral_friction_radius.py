import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.effects import get_effect
from trackenv.physics.model import evaluate, initial_state

from .conftest import sim


def test_coefficient_limits():
    e = get_effect("lateral_friction_radius", mu_max=0.6, a=0.925, b=0.15)
    assert float(e.coefficient(0.0)) == pytest.approx(0.6 / 0.925, rel=1e-6)
    assert float(e.coefficient(10.0)) == pytest.approx(0.6 / (0.925 + 1.5), rel=1e-6)
    assert float(e.coefficient(1e4)) < 1e-3
    assert float(e.turning_radius(jnp.asarray(1.0), jnp.asarray(0.5))) == pytest.approx(2.0)
    assert float(e.turning_radius(jnp.asarray(0.0), jnp.asarray(3.0))) == 0.0  # ZRT: R = 0


def test_force_opposes_lateral_velocity_and_magnitude():
    e = get_effect("lateral_friction_radius")
    p = te.load_params("dry_sand", effects=(e,))
    s = eqx.tree_at(lambda s: s.vel, initial_state(p), jnp.asarray([0.0, 0.0, 2.0]))
    ev = evaluate(s, jnp.zeros(2), p)
    lat, vy, n = map(np.asarray, (ev.forces.lateral, ev.kin.lateral_velocity, ev.forces.normal))
    assert np.all(lat * vy <= 0)
    far = np.abs(vy[0]) > 0.06
    mu = 0.53 / 0.925
    np.testing.assert_allclose(np.abs(lat)[:, far], mu * n[:, far], rtol=1e-5)
    # symmetric: the forces cancel, a moment resists r > 0
    assert abs(float(lat.sum())) < 1e-3
    assert float((ev.kin.x * lat).sum()) < 0


def test_zrt_end_to_end():
    base = sim("dry_sand", t_end=3.0)
    tr = sim("dry_sand", (get_effect("lateral_friction_radius"),), t_end=3.0)
    yb, ye = float(base.channels["yaw_rate"][-1]), float(tr.channels["yaw_rate"][-1])
    assert ye < 0 and abs(ye - yb) > 0.05 * abs(yb)  # a different, still clockwise, steady turn
    # with mu_max = 0 nothing resists yaw laterally: it turns faster than the shear-law base
    tr0 = sim("dry_sand", (get_effect("lateral_friction_radius", mu_max=0.0),), t_end=3.0)
    assert float(tr0.channels["yaw_rate"][-1]) < yb


def test_mu_min_floor():
    """mu_t(R) = mu_min + mu_max/(a + bR) levels off at mu_min in wide turns."""
    e = get_effect("lateral_friction_radius", mu_max=0.6, a=1.0, b=1.0, mu_min=0.2)
    np.testing.assert_allclose(np.asarray(e.coefficient(np.array([0.0, 1.0, 1e6]))), [0.8, 0.5, 0.2], rtol=1e-5)


def test_blend_spans_the_shear_law_and_the_radius_law():
    """blend = 0 gives the base model's lateral forces (the shear law) to the last bit, blend = 1 the law alone
    (the default), and a partial blend lies between them in proportion."""
    s = None
    out = {}
    for blend in (None, 0.0, 0.4, 1.0):
        effects = () if blend is None else (get_effect("lateral_friction_radius", blend=blend),)
        p = te.load_params("dry_sand", effects=effects)
        if s is None:
            s = eqx.tree_at(lambda s: s.vel, initial_state(p), jnp.asarray([0.3, 0.0, 1.5]))
        out[blend] = np.asarray(evaluate(s, jnp.asarray([6.0, -6.0]), p).forces.lateral)
    assert np.array_equal(out[0.0], out[None])
    law = np.asarray(evaluate(s, jnp.asarray([6.0, -6.0]),
                              te.load_params("dry_sand", effects=(get_effect("lateral_friction_radius"),))).forces.lateral)
    assert np.array_equal(out[1.0], law)
    assert np.abs(law - out[None]).max() > 1.0  # the two laws differ here, so the blend is tested
    np.testing.assert_allclose(out[0.4], 0.4 * law + 0.6 * out[None], rtol=1e-5, atol=1e-4)
    with pytest.raises(ValueError, match="blend"):
        get_effect("lateral_friction_radius", blend=1.5)
