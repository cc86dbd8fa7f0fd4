import jax.numpy as jnp
import numpy as np
import pytest

from trackenv.effects import get_effect

from .conftest import sim


def test_moment_law():
    e = get_effect("grouser_stiction", yaw_moment=10.0, yaw_smoothing=0.05, yaw_fade=1.5)
    assert float(e.moment(jnp.asarray(0.0))) == 0.0
    assert float(e.moment(jnp.asarray(0.05))) == pytest.approx(-10 * np.exp(-0.05 / 1.5), rel=1e-5)
    assert float(e.moment(jnp.asarray(-0.05))) == pytest.approx(10 * np.exp(-0.05 / 1.5), rel=1e-5)  # odd
    assert abs(float(e.moment(jnp.asarray(6.0)))) == pytest.approx(10 * np.exp(-4.0), rel=1e-5)  # fades
    e2 = get_effect("grouser_stiction", force=20.0)
    assert float(e2.longitudinal(jnp.asarray(1.0))) == pytest.approx(-20 * np.exp(-1.0 / 0.2), rel=1e-5)


def t90(tr):
    y = np.abs(np.asarray(tr.channels["yaw_rate"]))
    ss = y[-10:].mean()
    return float(np.asarray(tr.t)[np.argmax(y >= 0.9 * ss)]), ss


def test_asphalt_zrt_slower_start_same_steady():
    tb, sb = t90(sim("asphalt", t_end=3.0))
    te_, se = t90(sim("asphalt", (get_effect("grouser_stiction"),), t_end=3.0))
    assert te_ >= 1.5 * tb  # transient visibly slower (~2x)
    assert se == pytest.approx(sb, rel=0.1)


def test_nothing_on_sand():
    b = sim("dry_sand", t_end=1.0)
    e = sim("dry_sand", (get_effect("grouser_stiction"),), t_end=1.0)
    np.testing.assert_allclose(e.channels["yaw_rate"], b.channels["yaw_rate"], atol=1e-6)


def test_lateral_stribeck_law():
    e = get_effect("grouser_stiction", lateral_gain=0.8, lateral_slide_speed=0.1)
    assert float(e.lateral_factor(jnp.asarray(0.0))) == pytest.approx(1.8, rel=1e-6)  # static peak 1 + β
    assert float(e.lateral_factor(jnp.asarray(-0.1))) == pytest.approx(1 + 0.8 / np.e, rel=1e-5)  # even in v_y
    assert float(e.lateral_factor(jnp.asarray(2.0))) == pytest.approx(1.0, abs=1e-6)  # fades once sliding
    assert float(get_effect("grouser_stiction").lateral_factor(jnp.asarray(0.0))) == 1.0  # default β = 0


def test_lateral_stribeck_slows_asphalt_turn_only():
    e = get_effect("grouser_stiction", yaw_moment=0.0, lateral_gain=1.0, lateral_slide_speed=0.3)
    tb, sb = t90(sim("asphalt", t_end=3.0))
    te_, se = t90(sim("asphalt", (e,), t_end=3.0))
    assert te_ > 1.2 * tb  # more lateral resistance while the elements slide slowly: a slower breakaway
    assert se < sb  # and slower steady turning (the elements near the turning centre keep sliding slowly)
    b = sim("dry_sand", t_end=1.0)
    s = sim("dry_sand", (e,), t_end=1.0)
    np.testing.assert_allclose(s.channels["yaw_rate"], b.channels["yaw_rate"], atol=1e-6)
