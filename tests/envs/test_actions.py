"""Action handling: clipping to the space, errors for NaN/inf and wrong shapes; divergence."""

import gymnasium as gym
import numpy as np
import pytest

import trackenv
from trackenv.envs import core
from trackenv.envs.vector import TrackVectorEnv
from trackenv.integrate import physical_bounds


def step_once(action, env_id="trackenv/GoStop-v0", **kwargs):
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    return env.step(action)


def test_out_of_range_actions_are_clipped():
    o1, r1, *_, i1 = step_once(np.array([100.0, -100.0], np.float32))
    o2, r2, *_, i2 = step_once(np.array([24.0, -24.0], np.float32))
    np.testing.assert_array_equal(o1, o2)
    assert r1 == r2
    np.testing.assert_array_equal(i1["state"]["omega"], i2["state"]["omega"])
    names = gym.make("trackenv/GoStop-v0").unwrapped.obs_names
    assert o1[names.index("prev_voltage_left")] == 24.0 and o1[names.index("prev_voltage_right")] == -24.0


def test_normalized_actions_scale_to_volts():
    o1, *_ = step_once(np.array([0.5, -2.0], np.float32), normalize_action=True)
    o2, *_ = step_once(np.array([12.0, -24.0], np.float32))
    np.testing.assert_allclose(o1, o2, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("bad", [[np.nan, 1.0], [1.0, np.inf], [-np.inf, 0.0]])
def test_non_finite_action_raises(bad):
    env = gym.make("trackenv/GoStop-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array(bad, np.float32))


@pytest.mark.parametrize("bad", [[1.0], [1.0, 2.0, 3.0], [[1.0, 2.0]], "ab", None])
def test_wrong_shape_raises(bad):
    env = gym.make("trackenv/GoStop-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(bad)


def test_vector_bad_actions():
    venv = TrackVectorEnv("go_stop", 3)
    venv.reset(seed=0)
    a = np.zeros((3, 2), np.float32)
    a[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"environment\(s\) \[1\]"):
        venv.step(a)
    with pytest.raises(ValueError, match="shape"):
        venv.step(np.zeros((2, 2)))


def test_divergence_truncates_with_flag():
    # A drive inertia 1e5 times too small makes the sprocket dynamics far too stiff for the substep:
    # the state goes non-finite in the first step.
    sim = trackenv.replace(trackenv.load_params("dry_sand"), **{"vehicle.drive_inertia": 1e-7})
    params = core.make_params("go_stop", sim_params=sim)
    env = gym.make("trackenv/GoStop-v0", params=params)
    obs, _ = env.reset(seed=0)
    obs, r, term, trunc, info = env.step(np.array([11.8, 11.8], np.float32))
    assert trunc is True and term is False
    assert info["diverged"] is True and info["success"] is False
    assert r == 0.0
    assert np.all(np.isfinite(obs)) and obs in env.observation_space
    for v in info["state"].values():
        assert np.all(np.isfinite(v))  # frozen at the last finite state
    # the nominal vehicle does not diverge
    *_, info = step_once(np.array([11.8, 11.8], np.float32))
    assert info["diverged"] is False


@pytest.mark.parametrize("substep", [0.03, 0.0125])
def test_substep_above_stable_limit_is_rejected(substep):
    with pytest.raises(ValueError, match=r"substep = .* exceeds the stable limit MAX_SUBSTEP = 0.01 s"):
        gym.make("trackenv/GoStop-v0", substep=substep)
    with pytest.raises(ValueError, match="MAX_SUBSTEP"):
        TrackVectorEnv("go_stop", 2, substep=substep)


def test_substep_above_control_dt_is_rejected():
    with pytest.raises(ValueError, match=r"substep = 0.008 s exceeds control_dt = 0.005 s"):
        gym.make("trackenv/GoStop-v0", control_dt=0.005, substep=0.008)


def test_blow_up_is_flagged_before_overflow():
    # J_eff / 100 at the largest accepted substep: the integration blows up; the step that leaves the
    # physical bounds is flagged and the state returned is the last physical one.
    sim = trackenv.replace(trackenv.load_params("dry_sand"), **{"vehicle.drive_inertia": 1.7e-4})
    params = core.make_params("go_stop", sim_params=sim, substep=0.01)
    env = gym.make("trackenv/GoStop-v0", params=params)
    env.reset(seed=0)
    i_max, w_max = (float(b) for b in physical_bounds(sim))
    for _ in range(40):
        obs, r, term, trunc, info = env.step(np.array([11.8, 11.8], np.float32))
        assert np.max(np.abs(info["state"]["current"])) <= i_max
        assert np.max(np.abs(info["state"]["omega"])) <= w_max
        assert abs(r) < 100.0
        if trunc:
            break
    assert info["diverged"] is True and trunc is True


def test_vector_divergence_resets():
    sim = trackenv.replace(trackenv.load_params("dry_sand"), **{"vehicle.drive_inertia": 1e-7})
    params = core.make_params("go_stop", sim_params=sim)
    venv = TrackVectorEnv("go_stop", 2, params=params, autoreset_mode="next_step")
    venv.reset(seed=0)
    _, r, term, trunc, info = venv.step(np.full((2, 2), 11.8))
    assert trunc.all() and not term.any() and info["diverged"].all()
