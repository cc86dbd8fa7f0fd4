"""Rewards and terminations behave: the thesis input beats doing nothing; scripted drivers succeed."""

import gymnasium as gym
import numpy as np
import pytest
from envs_common import ENV_IDS, TERRAINS

import trackenv  # noqa: F401
from trackenv.envs import controllers


def run(env, policy, seed=0):
    obs, info = env.reset(seed=seed)
    total, k = 0.0, 0
    while True:
        obs, r, term, trunc, info = env.step(policy(k, obs))
        total += r
        k += 1
        if term or trunc:
            return total, term, trunc, info


def test_go_stop_thesis_input_beats_zero_voltage():
    env = gym.make("trackenv/GoStop-v0", terrain="dry_sand")
    # The reconstructed thesis go-stop (configs/field/go_stop_dry_sand.yaml): 11.8 V, released at 3.0 s.
    thesis, term, _, info = run(env, lambda k, o: np.array([11.8, 11.8] if k < 60 else [0.0, 0.0], np.float32))
    assert term and info["success"] and info["completion"] == 1.0
    idle, term0, trunc0, info0 = run(env, lambda k, o: np.zeros(2, np.float32))
    assert trunc0 and not term0 and info0["timeout"] and not info0["success"]
    assert thesis > idle + 50.0
    # Holding the voltage through the mark overshoots: off course, and a lower return.
    overshoot, term1, _, info1 = run(env, lambda k, o: np.array([11.8, 11.8], np.float32))
    assert term1 and info1["off_course"] and not info1["success"]
    assert overshoot < thesis
    # energy accounting: 11.8 V x ~1.9 A x 2 motors x ~2.7 s of cruise plus the in-rush
    assert 100.0 < info["energy"] < 250.0


@pytest.mark.parametrize("terrain", TERRAINS)
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_scripted_driver_succeeds(env_id, terrain):
    env = gym.make(env_id, terrain=terrain)
    driver = controllers.make_driver(env)
    total, term, trunc, info = run(env, lambda k, o: driver(o))
    assert term and info["success"] and not info["off_course"], info
    assert info["completion"] == pytest.approx(1.0, abs=0.05)
    assert total > 100.0


def test_j_turn_off_course_detected():
    env = gym.make("trackenv/JTurn-v0")
    # never turning runs straight past the end of the J: off course (cross-track error)
    _, term, _, info = run(env, lambda k, o: np.array([11.8, 11.8], np.float32))
    assert term and info["off_course"]


def test_lane_change_cone_hit():
    env = gym.make("trackenv/LaneChange-v0")
    # steering right from the start leaves the entry lane through its side
    _, term, _, info = run(env, lambda k, o: np.array([13.0, 10.6], np.float32))
    assert term and info["off_course"] and info["time"] < 2.0


def test_zero_radius_turn_tracking_reward_prefers_target_rate():
    env = gym.make("trackenv/ZeroRadiusTurn-v0", terrain="asphalt", max_time=1.0)
    slow, *_ = run(env, lambda k, o: np.array([2.0, -2.0], np.float32))
    right, *_ = run(env, lambda k, o: np.array([7.0, -7.0], np.float32))  # about -3 rad/s on asphalt
    assert right > slow
