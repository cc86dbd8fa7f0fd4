"""Gymnasium's and Stable-Baselines3's environment checkers pass for every env on both terrains."""

import gymnasium as gym
import numpy as np
import pytest
from envs_common import ENV_IDS, TERRAINS
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import trackenv  # noqa: F401  (registers the environments)


def test_registered():
    for env_id in ENV_IDS:
        assert env_id in gym.registry


@pytest.mark.parametrize("terrain", TERRAINS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_checkers(env_id, terrain):
    env = gym.make(env_id, terrain=terrain)
    check_env(env.unwrapped)  # includes render checks for rgb_array via the spec
    sb3_check_env(env.unwrapped)
    assert env.action_space == gym.spaces.Box(-24.0, 24.0, (2,), np.float32)
    assert env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    assert len(env.unwrapped.obs_names) == env.observation_space.shape[0]
    env.close()


def test_gym_make_options():
    env = gym.make("trackenv/ZeroRadiusTurn-v0", terrain="sandy_loam_1", control_dt=0.1, substep=0.005,
                   normalize_action=True, target_yaw_rate=(-4.0, -2.0))
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    obs, info = env.reset(seed=3)
    assert -4.0 <= obs[env.unwrapped.obs_names.index("target_yaw_rate")] <= -2.0
    assert env.unwrapped.params.substeps == 20 and env.unwrapped.params.control_dt == 0.1
    obs, r, term, trunc, info = env.step(np.array([1.0, -1.0], np.float32))
    assert info["time"] == pytest.approx(0.1)
    np.testing.assert_allclose(obs[env.unwrapped.obs_names.index("prev_voltage_left")], 24.0)
    with pytest.raises(TypeError, match="unknown option"):
        gym.make("trackenv/GoStop-v0", no_such_option=1)
    with pytest.raises(Exception, match="unknown terrain"):
        gym.make("trackenv/GoStop-v0", terrain="moon_dust")
    import trackenv.effects as fx

    if not (hasattr(fx, "get_effect") or hasattr(fx, "make_effect")):  # until the effects land
        with pytest.raises(NotImplementedError, match="slip_sinkage"):
            gym.make("trackenv/GoStop-v0", effects=("slip_sinkage",))
    with pytest.raises(ValueError, match="unknown effect"):
        gym.make("trackenv/GoStop-v0", effects=("warp_drive",))
