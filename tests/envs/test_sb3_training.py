"""Stable-Baselines3 trains directly on the batched adapter."""

import numpy as np
import pytest

import trackenv  # noqa: F401
from trackenv.envs.vector import SB3VecEnv


def test_ppo_runs_a_few_hundred_steps():
    sb3 = pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import VecMonitor

    venv = VecMonitor(SB3VecEnv("trackenv/GoStop-v0", num_envs=8, normalize_action=True, max_time=1.0))
    model = sb3.PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (8, 2) and np.all(np.abs(action) <= 1.0)
    assert len(model.ep_info_buffer) > 0  # episodes ended and were logged through VecMonitor
