"""rgb_array rendering: a top-down frame; no rendering work when not rendering."""

import gymnasium as gym
import numpy as np
import pytest
from envs_common import ENV_IDS

import trackenv  # noqa: F401
from trackenv.envs.vector import TrackVectorEnv


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_render_rgb_array(env_id):
    env = gym.make(env_id, render_mode="rgb_array", max_time=0.5)
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([12.0, 10.0], np.float32))
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[0] >= 200 and frame.shape[1] >= 200
    assert frame.std() > 5  # not a blank image
    assert len(env.unwrapped._trail) == 6
    env.close()


def test_no_render_work_without_render_mode():
    env = gym.make("trackenv/GoStop-v0")
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.array([12.0, 12.0], np.float32))
    u = env.unwrapped
    assert u._trail == [] and u._renderer is None


def test_vector_render():
    venv = TrackVectorEnv("go_stop", 2, render_mode="rgb_array", max_time=0.5)
    venv.reset(seed=0)
    venv.step(np.full((2, 2), 11.8))
    frames = venv.render()
    assert len(frames) == 2 and frames[0].dtype == np.uint8 and frames[0].ndim == 3
