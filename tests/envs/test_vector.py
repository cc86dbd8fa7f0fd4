"""Batched VectorEnv: shapes, autoreset modes, seeding, and the SB3 adapter."""

import gymnasium as gym
import jax
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import trackenv  # noqa: F401
from trackenv.envs import core
from trackenv.envs.vector import SB3VecEnv, TrackVectorEnv

N = 8
CRUISE = np.full((N, 2), 11.8, np.float32)


def test_make_vec_and_shapes():
    venv = gym.make_vec("trackenv/GoStop-v0", num_envs=N)
    assert isinstance(venv, TrackVectorEnv)
    assert venv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    obs, info = venv.reset(seed=0)
    assert obs.shape == (N, venv.single_observation_space.shape[0]) and obs.dtype == np.float32
    assert obs in venv.observation_space
    obs, rew, term, trunc, info = venv.step(CRUISE)
    assert rew.shape == (N,) and term.dtype == np.bool_ and trunc.dtype == np.bool_
    assert info["time"].shape == (N,) and info["_time"].all()
    # every sub-env equals the single env with the same seed (here: no randomness at all)
    env = gym.make("trackenv/GoStop-v0")
    o1, _ = env.reset(seed=0)
    o1, r1, *_ = env.step(CRUISE[0])
    np.testing.assert_allclose(obs[3], o1, rtol=1e-5, atol=1e-5)
    assert rew[3] == pytest.approx(r1, rel=1e-5)


def test_next_step_autoreset():
    venv = TrackVectorEnv("go_stop", N, autoreset_mode="next_step", max_time=0.2)  # 4 steps
    venv.reset(seed=0)
    for _ in range(3):
        _, _, term, trunc, _ = venv.step(CRUISE)
        assert not (term | trunc).any()
    obs, rew, term, trunc, info = venv.step(CRUISE)
    assert trunc.all() and not term.any() and info["timeout"].all()
    assert info["time"] == pytest.approx(0.2)
    obs, rew, term, trunc, info = venv.step(CRUISE)  # the reset step: action ignored
    assert (rew == 0).all() and not (term | trunc).any()
    assert (info["time"] == 0).all()
    t_idx = venv.obs_names.index("time_fraction")
    assert (obs[:, t_idx] == 0).all()
    obs, *_ = venv.step(CRUISE)
    assert (obs[:, t_idx] > 0).all()


def test_same_step_autoreset():
    venv = TrackVectorEnv("go_stop", N, autoreset_mode="same_step", max_time=0.2)
    venv.reset(seed=0)
    t_idx = venv.obs_names.index("time_fraction")
    for _ in range(3):
        _, _, _, _, info = venv.step(CRUISE)
        assert "final_obs" not in info
    obs, rew, term, trunc, info = venv.step(CRUISE)
    assert trunc.all()
    assert info["_final_obs"].all() and info["final_obs"].dtype == object
    assert info["final_obs"][0][t_idx] == pytest.approx(1.0)  # the last observation of the ended episode
    assert (obs[:, t_idx] == 0).all()  # ... while obs is already the new episode's first
    assert info["final_info"]["timeout"].all() and info["final_info"]["time"] == pytest.approx(0.2)
    assert (rew > 0).all()  # the reward of the last step, not of a reset


def test_disabled_autoreset_and_reset_mask():
    venv = TrackVectorEnv("go_stop", N, autoreset_mode="disabled", max_time=0.1)
    venv.reset(seed=0)
    venv.step(CRUISE)
    _, _, _, trunc, _ = venv.step(CRUISE)
    assert trunc.all()
    mask = np.zeros(N, bool)
    mask[[1, 5]] = True
    obs, info = venv.reset(options={"reset_mask": mask})
    t_idx = venv.obs_names.index("time_fraction")
    assert (obs[mask, t_idx] == 0).all() and (obs[~mask, t_idx] == 1).all()


@pytest.mark.parametrize("terrain", ["dry_sand", "asphalt"])
def test_outside_ranges_draw_every_parameter_outside_the_training_ranges(terrain):
    from trackenv.envs.randomization import default_ranges, outside_ranges
    from trackenv.params import load_params

    p = load_params(terrain)
    inside, outside = default_ranges(p), outside_ranges(p)
    assert set(outside) == set(inside)
    venv = TrackVectorEnv("go_stop", 8, terrain=terrain, domain_randomization=outside, autoreset_mode="disabled")
    _, info = venv.reset(seed=3)
    for k, (lo, hi) in inside.items():
        v = info["params"][k]
        assert v.shape == (8,) and len(set(v.tolist())) == 8
        assert ((v >= hi * (1 - 1e-6)) | (v <= lo * (1 + 1e-6))).all(), (k, v, lo, hi)
        a, b = outside[k]
        assert ((v >= a * (1 - 1e-6)) & (v <= b * (1 + 1e-6))).all(), (k, v, a, b)


@pytest.mark.parametrize("dr", [True, {"grounds": ["asphalt", "dry_sand"]}], ids=["ranges", "ground-mixture"])
def test_vector_seeding_and_randomisation(dr):
    a = TrackVectorEnv("go_stop", 4, domain_randomization=dr, autoreset_mode="next_step")
    b = TrackVectorEnv("go_stop", 4, domain_randomization=dr, autoreset_mode="next_step")
    _, ia = a.reset(seed=11)
    _, ib = b.reset(seed=11)
    for k in ia["params"]:
        np.testing.assert_array_equal(ia["params"][k], ib["params"][k])
        if dr is True or k == "vehicle.mass":  # a mixture pins asphalt's cohesion and draws 2 grounds
            assert len(set(ia["params"][k].tolist())) == 4  # envs draw different parameters
    rng = np.random.default_rng(0)
    for _ in range(5):
        act = rng.uniform(-24, 24, (4, 2))
        oa, ra, *_ = a.step(act)
        ob, rb, *_ = b.step(act)
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)
    # env i of a vector env reset with seed s starts like a single env reset with seed s + i
    single = gym.make("trackenv/GoStop-v0", domain_randomization=dr)
    o_single, info = single.reset(seed=13)
    o_vec, ia = a.reset(seed=11)
    np.testing.assert_array_equal(o_vec[2], o_single)
    for k in info["params"]:
        assert ia["params"][k][2] == pytest.approx(info["params"][k], rel=1e-6)
    # the full batched state is available on demand
    phys = a.physical_state()
    assert phys["pose"].shape == (4, 3) and phys["jz"].shape[0] == 4


def test_functional_core_jit_vmap():
    params = core.make_params("zero_radius_turn", terrain="asphalt")
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    state, out = jax.jit(jax.vmap(core.reset, in_axes=(0, None)))(keys, params)
    step = jax.jit(jax.vmap(core.step, in_axes=(0, 0, None)))
    act = np.array([[12.0, -12.0], [0.0, 0.0], [-12.0, 12.0]], np.float32)
    for _ in range(5):
        state, out = step(state, act, params)
    r = np.asarray(state.physics.vel[:, 2])
    assert r[0] < -1.0 and abs(r[1]) < 1e-6 and r[2] > 1.0


def test_sb3_adapter_semantics():
    venv = SB3VecEnv("trackenv/GoStop-v0", num_envs=4, max_time=0.15)
    venv.seed(5)
    obs = venv.reset()
    assert isinstance(obs, np.ndarray) and obs.shape == (4, venv.observation_space.shape[0])
    for _ in range(2):
        obs, rew, dones, infos = venv.step(np.full((4, 2), 11.8, np.float32))
        assert not dones.any() and rew.dtype == np.float32
    obs, rew, dones, infos = venv.step(np.full((4, 2), 11.8, np.float32))
    assert dones.all()
    for i, info in enumerate(infos):
        assert info["TimeLimit.truncated"] is True
        assert info["terminal_observation"].shape == obs[i].shape
        assert not np.array_equal(info["terminal_observation"], obs[i])  # obs is the next episode's first
        assert info["is_success"] is False


def test_native_physics_batching_matches_vmap():
    outs = []
    for batching in ("vmap", "native"):
        venv = TrackVectorEnv("j_turn", 3, physics_batching=batching, domain_randomization=True)
        obs, _ = venv.reset(seed=2)
        acts = np.random.default_rng(1).uniform(-24, 24, (4, 3, 2))
        seq = [obs]
        for a in acts:
            obs, rew, *_ = venv.step(a)
            seq += [obs, rew]
        outs.append(seq)
    for x, y in zip(*outs):
        np.testing.assert_allclose(x, y, rtol=1e-4, atol=1e-4)
