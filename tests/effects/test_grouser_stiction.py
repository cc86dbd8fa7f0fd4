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
