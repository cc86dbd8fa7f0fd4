"""trackenv.compare: the comparison rules shared by replay and the diagnosis."""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from trackenv import compare as C


def test_interpolation_at_sample_times_hand_value():
    grid_x = np.array([0.0, 1.0, 4.0, 9.0])  # a channel on the grid t = 0, 0.1, 0.2, 0.3 s
    w = C.grid_weights(np.array([0.0, 0.05, 0.125, 0.3]), 0.1, 3)
    assert w.i0.tolist() == [0, 0, 1, 2]
    np.testing.assert_allclose(C.at_samples(grid_x, w), [0.0, 0.5, 1.75, 9.0], rtol=0, atol=1e-12)
    # vehicles on the last axis, numpy and jax alike
    two = np.stack([grid_x, 2 * grid_x], -1)
    np.testing.assert_allclose(C.at_samples(two, w)[:, 1], [0.0, 1.0, 3.5, 18.0], atol=1e-12)
    got = jax.jit(lambda x: C.at_samples(x, w))(jnp.asarray(two, jnp.float32))
    np.testing.assert_allclose(np.asarray(got), C.at_samples(two, w), rtol=1e-6)
    grid = np.arange(4) * 0.1
    np.testing.assert_allclose(C.interp_at([0.05, 0.125], grid, grid_x), [0.5, 1.75], atol=1e-12)


def test_rectification_only_currents_of_an_absolute_ammeter():
    ch = {"i_left": np.array([-2.0, 1.0]), "i_right": np.array([3.0, -4.0]), "yaw_rate": np.array([-1.0, 1.0])}
    abs_ = C.rectify_channels(ch, "absolute")
    assert abs_["i_left"].tolist() == [2.0, 1.0] and abs_["i_right"].tolist() == [3.0, 4.0]
    assert abs_["yaw_rate"].tolist() == [-1.0, 1.0]
    signed = C.rectify_channels(ch, "signed")
    assert all(signed[k] is ch[k] for k in ch)
    assert float(C.rectify("i_left", jnp.float32(-2.5), "absolute")) == 2.5


def test_pose_frame_rotation_round_trip():
    pose0 = (1.5, -2.0, 2.9)
    xs, ys, hs = np.array([0.0, 1.0, 0.3]), np.array([0.0, 0.0, -0.7]), np.array([0.0, 0.2, -1.0])
    X, Y, H = C.pose_to_log_frame(xs, ys, hs, pose0)
    assert (X[0], Y[0], H[0]) == pose0  # the start is the log's first pose
    c, s = math.cos(2.9), math.sin(2.9)
    assert X[1] == pytest.approx(1.5 + c) and Y[1] == pytest.approx(-2.0 + s)  # 1 m ahead along heading0
    back = C.pose_from_log_frame(X, Y, H, pose0)
    for a, b in zip(back, (xs, ys, hs)):
        np.testing.assert_allclose(a, b, atol=1e-12)
    # distances are kept (a rotation)
    assert np.hypot(X[2] - X[0], Y[2] - Y[0]) == pytest.approx(np.hypot(0.3, -0.7))


def test_wrapping_into_minus_pi_pi():
    a = np.array([0.0, math.pi, -math.pi, 3 * math.pi, 2 * math.pi + 0.5, -2 * math.pi - 0.5, 7.0, -7.0])
    w = C.wrap_angle(a)
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    assert w[1] == math.pi and w[2] == math.pi and w[4] == pytest.approx(0.5) and w[5] == pytest.approx(-0.5)
    wj = jax.jit(C.wrap_angle)(jnp.asarray(a, jnp.float32))
    assert np.all(np.asarray(wj) > -math.pi - 1e-6) and np.all(np.asarray(wj) <= math.pi + 1e-6)
    # heading errors are wrapped, other channels are not
    e = C.channel_error("heading", np.array([[3.0, 0.1]]).T, np.array([-3.0, 0.0]))
    np.testing.assert_allclose(e[:, 0], [6.0 - 2 * math.pi, 0.1])
    assert C.channel_error("yaw_rate", np.array([3.0]), np.array([-3.0])).tolist() == [6.0]


def test_unwrap_measured_keeps_missing_samples():
    x = np.array([3.0, np.nan, -3.0, -2.9])
    u = C.unwrap_measured(x)
    assert np.isnan(u[1]) and u[0] == 3.0 and u[2] == pytest.approx(2 * math.pi - 3.0)
    assert np.isnan(x[1]) and x[2] == -3.0  # the input is not changed


def test_json_clean():
    obj = {"a": float("nan"), "b": np.float32(0.5), "c": np.bool_(True), "d": (np.int64(3), float("inf")),
           1: np.array([1.0, np.nan]), "e": "x", "f": None}
    out = C.json_clean(obj)
    assert out == {"a": None, "b": 0.5, "c": True, "d": [3, None], "1": [1.0, None], "e": "x", "f": None}
    assert type(out["b"]) is float and type(out["c"]) is bool and type(out["d"][0]) is int
    json.dumps(out, allow_nan=False)


def test_stack_trees_along_a_new_last_axis():
    trees = [{"a": jnp.float32(k), "b": jnp.full((2,), k, jnp.float32), "n": 3, "s": "tag"} for k in range(4)]
    st = C.stack_trees(trees)
    assert st["a"].shape == (4,) and st["b"].shape == (2, 4) and st["n"] == 3 and st["s"] == "tag"
    np.testing.assert_array_equal(np.asarray(st["b"])[1], [0, 1, 2, 3])
    st32 = C.stack_trees([{"a": 1.0}, {"a": 2.0}], jnp.float32)
    assert st32["a"].dtype == jnp.float32 and st32["a"].tolist() == [1.0, 2.0]


def test_simulate_batch_is_simulate_without_checks():
    import trackenv as te
    from trackenv.simulate import n_substeps, simulate_batch

    params = C.stack_trees([te.load_params("dry_sand"), te.load_params("asphalt")])
    profile = te.VoltageProfile.from_arrays([0.0, 0.2, 0.5], np.array([[0, 0], [6, 9], [6, 9]], float)[:, :, None]
                                            * np.ones((1, 1, 2)))
    ref = te.simulate(params, profile, 0.5, dt=0.05)
    got = simulate_batch(params, profile, 10, 0.05, n_substeps(0.05, 0.0005))
    assert got.channels["x"].shape == (11, 2) and got.diverged.shape == (2,)
    for k in ("x", "yaw_rate", "i_left"):
        np.testing.assert_array_equal(np.asarray(got.channels[k]), np.asarray(ref.channels[k]))
