"""Nothing recompiles after the first step of the first episode (single and vector envs)."""

import gymnasium as gym
import jax
import numpy as np
import pytest

import trackenv  # noqa: F401
from trackenv.envs.vector import TrackVectorEnv

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


@pytest.fixture
def compile_counter():
    events = []

    def listener(event, duration, **kwargs):
        if event == COMPILE_EVENT:
            events.append(event)

    jax.monitoring.register_event_duration_secs_listener(listener)
    yield events
    jax.monitoring.unregister_event_duration_listener(listener)


def test_single_env_no_recompilation(compile_counter):
    env = gym.make("trackenv/JTurn-v0", max_time=0.5)
    obs, _ = env.reset(seed=0)
    env.step(env.action_space.sample())
    first = len(compile_counter)
    u = env.unwrapped  # its jitted row program is shared with vector envs of the same structure (other shapes)
    cached = (u._step_fn._cache_size(), u._reset_fn._cache_size())
    env.action_space.seed(0)
    for episode in range(3):
        for _ in range(12):  # runs past the 0.5 s time limit: truncation, then reset
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            if term or trunc:
                break
        env.reset(seed=episode if episode % 2 else None)
    env.step(np.array([30.0, -30.0]))  # out-of-range (clipped) and float64 input
    env.step([1, 2])  # ints in a list
    assert len(compile_counter) == first, "recompiled after the first step"
    assert (u._step_fn._cache_size(), u._reset_fn._cache_size()) == cached
    # a second env of the same kind (other terrain) shares the compiled program
    env2 = gym.make("trackenv/JTurn-v0", terrain="asphalt", max_time=0.5)
    env2.reset(seed=1)
    env2.step(env2.action_space.sample())
    assert len(compile_counter) == first


def test_vector_env_no_recompilation(compile_counter):
    venv = TrackVectorEnv("go_stop", 4, autoreset_mode="next_step", max_time=0.2)
    venv.reset(seed=0)
    venv.step(np.full((4, 2), 11.8, np.float32))
    first = len(compile_counter)
    for _ in range(10):  # several autoresets
        venv.step(np.random.default_rng(0).uniform(-30, 30, (4, 2)))
    venv.reset()
    venv.step(np.zeros((4, 2)))
    assert len(compile_counter) == first
