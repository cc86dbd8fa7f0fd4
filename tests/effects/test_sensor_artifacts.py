import jax
import jax.numpy as jnp
import numpy as np
import pytest

from trackenv.effects import get_effect
from trackenv.effects.sensor_artifacts import moving_average

from .conftest import sim


def test_bias_adds_exactly_and_rectified_nonnegative():
    base = sim("dry_sand", t_end=2.0)
    e = get_effect("sensor_artifacts", gyro_bias=0.02, ripple_amplitude=0.5, ripple_frequency=7.0, window=0.0)
    tr = sim("dry_sand", (e,), t_end=2.0)
    np.testing.assert_allclose(tr.channels["yaw_rate"], np.asarray(base.channels["yaw_rate"]) + 0.02, atol=1e-6)
    for k in ("i_left", "i_right"):
        assert np.all(np.asarray(tr.channels[k]) >= 0)
        t = np.asarray(tr.t)
        np.testing.assert_allclose(tr.channels[k], np.abs(np.asarray(base.channels[k]) + 0.5 * np.sin(2 * np.pi * 7 * t)),
                                   atol=1e-4)
    np.testing.assert_allclose(tr.channels["speed_ideal"], base.channels["speed_ideal"], atol=1e-6)  # W = 0
    assert np.all(np.asarray(base.channels["i_right"])[10:] < 0)  # signed before: rectification mattered


def test_ammeter_offsets_and_gyro_scale_act_before_rectification():
    """i_m = |i + c| per channel (an offset of the sensor, rectified with the current) and r_m = (1 + ε) r + β."""
    base = sim("dry_sand", t_end=2.0)
    e = get_effect("sensor_artifacts", window=0.0, gyro_bias=0.01, gyro_scale=0.1, current_offset_left=0.3,
                   current_offset_right=-0.4)
    tr = sim("dry_sand", (e,), t_end=2.0)
    np.testing.assert_allclose(tr.channels["yaw_rate"], 1.1 * np.asarray(base.channels["yaw_rate"]) + 0.01, atol=1e-6)
    for k, c in (("i_left", 0.3), ("i_right", -0.4)):
        np.testing.assert_allclose(tr.channels[k], np.abs(np.asarray(base.channels[k]) + c), atol=1e-5)
    # the default has no offset and no scale error: only the encoder window acts
    d = sim("dry_sand", (get_effect("sensor_artifacts", window=0.0),), t_end=2.0)
    np.testing.assert_allclose(d.channels["yaw_rate"], base.channels["yaw_rate"], atol=1e-7)
    np.testing.assert_allclose(d.channels["i_left"], np.abs(np.asarray(base.channels["i_left"])), atol=1e-6)


def test_moving_average_of_step_is_ramp():
    t = jnp.arange(0, 41) * 0.05  # 0..2 s
    s = jnp.where(t >= 1.0, 1.0, 0.0)  # piecewise linear: ramps 0.95 -> 1.0
    avg = np.asarray(moving_average(t, s, jnp.asarray(0.5)))
    tt = np.asarray(t)
    # exact: integral of the piecewise-linear step over [t-0.5, t] / 0.5
    def integral(a, b):
        f = lambda x: np.where(x < 0.95, 0.0, np.where(x < 1.0, (x - 0.95) ** 2 / 0.1, 0.025 + (x - 1.0)))  # noqa
        return f(b) - f(a)
    np.testing.assert_allclose(avg, integral(tt - 0.5, tt) / 0.5, atol=1e-5)
    assert avg[20] == pytest.approx(0.05, abs=1e-5)  # t = 1.0: half the last segment
    assert avg[24] == pytest.approx((0.025 + 0.2) / 0.5, abs=1e-5)  # t = 1.2: window [0.7, 1.2]
    assert avg[30] == pytest.approx(1.0, abs=1e-5)  # t = 1.5: window [1.0, 1.5] all ones
    assert avg[-1] == pytest.approx(1.0)
    # causal: nothing before the step
    assert np.all(avg[:20] == 0.0)
    # batched channels (T, b)
    sb = jnp.stack([s, 2 * s], axis=1)
    np.testing.assert_allclose(moving_average(t, sb, jnp.asarray(0.5))[:, 1], 2 * avg, atol=1e-5)


def test_grad_through_window():
    t = jnp.arange(0, 41) * 0.05
    s = t**2
    g = jax.grad(lambda w: moving_average(t, s, w)[-1])(jnp.asarray(0.3))
    assert np.isfinite(g) and g < 0  # longer window of a rising signal lowers the reading
