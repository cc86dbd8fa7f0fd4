"""SB3 drivers: config validation, policy loading, evaluation metrics, and a learning smoke test."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

import trackenv  # noqa: F401
from trackenv.params import ConfigError

pytest.importorskip("stable_baselines3")

from trackenv import drivers  # noqa: E402
from trackenv.cli import main  # noqa: E402
from trackenv.envs import controllers  # noqa: E402
from trackenv.envs.tasks import task_class  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


# ----------------------------------------------------------------------------------------------
# bad input: clear errors before anything trains


def test_shipped_configs_validate():
    for algo in drivers.ALGOS:
        for task in drivers.TASKS:
            for terrain in ("dry_sand", "asphalt"):
                cfg = drivers.load_config(algo, task, terrain)
                assert cfg["n_timesteps"] > 0 and cfg["policy"] == "MlpPolicy"
    plain = drivers.load_config("ppo", "go_stop", "asphalt", drivers.ROOT / "configs" / "train" / "ppo_plain.yaml")
    assert plain["residual"] == 0.0 and plain["policy_kwargs"]["log_std_init"] == -2.2 and plain["guide"] == 0.5


def test_unknown_config_key_names_file_and_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"default": {"n_timesteps": 1000, "learning_rat": 1e-3}}))
    with pytest.raises(ConfigError, match=r"bad\.yaml.*learning_rat"):
        drivers.load_config("ppo", "go_stop", "dry_sand", bad)
    bad.write_text(yaml.safe_dump({"GoStopp-v0": {"n_timesteps": 1000}}))
    with pytest.raises(ConfigError, match=r"bad\.yaml.*GoStopp-v0"):
        drivers.load_config("ppo", "go_stop", "dry_sand", bad)
    bad.write_text(yaml.safe_dump({"default": {"n_timesteps": -5}}))
    with pytest.raises(ConfigError, match="n_timesteps"):
        drivers.load_config("ppo", "go_stop", "dry_sand", bad)
    # SAC-only key in a PPO config
    bad.write_text(yaml.safe_dump({"default": {"n_timesteps": 1000, "buffer_size": 10}}))
    with pytest.raises(ConfigError, match="buffer_size"):
        drivers.load_config("ppo", "go_stop", "dry_sand", bad)


def test_linear_learning_rate_schedule_falls_to_zero_over_the_run(tmp_path):
    cfg = {"default": {"n_envs": 4, "n_timesteps": 128, "n_steps": 16, "batch_size": 32, "n_epochs": 1,
                       "residual": 0.0, "learning_rate": "lin_0.001", "policy_kwargs": {"net_arch": [8]},
                       "env_kwargs": {"max_time": 0.5}}}
    res = drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path, progress_bar=False, tensorboard=False,
                        config=cfg)
    model = drivers.load_policy(res.model_path, "go_stop", "dry_sand", warn=False)
    assert model.lr_schedule(1.0) == pytest.approx(1e-3) and model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    # the optimiser's rate at the last of the two updates, set after all 128 steps were collected: the end
    assert model.policy.optimizer.param_groups[0]["lr"] == 0.0
    bad = tmp_path / "bad.yaml"
    for spec in ("lin_fast", "exp_0.001", "lin_-1"):
        bad.write_text(yaml.safe_dump({"default": {"n_timesteps": 1000, "learning_rate": spec}}))
        with pytest.raises(ConfigError, match=r"bad\.yaml.*learning_rate.*lin_<number>"):
            drivers.load_config("ppo", "go_stop", "dry_sand", bad)


def test_config_extends_another_and_overrides_key_by_key(tmp_path):
    f = tmp_path / "plain.yaml"
    f.write_text("extends: ppo.yaml\ndefault:\n  residual: 0.0\n  policy_kwargs: {log_std_init: -2.0}\n")
    base = drivers.load_config("ppo", "lane_change", "asphalt")
    cfg = drivers.load_config("ppo", "lane_change", "asphalt", f)
    assert cfg["residual"] == 0.0 and base["residual"] > 0
    assert cfg["policy_kwargs"] == {**base["policy_kwargs"], "log_std_init": -2.0}
    assert cfg["error_weight"] == base["error_weight"] == 20.0  # the base file's terrain section still applies
    f.write_text("extends: nowhere.yaml\ndefault: {}\n")
    with pytest.raises(ConfigError, match="nowhere.yaml"):
        drivers.load_config("ppo", "go_stop", "dry_sand", f)


def test_unknown_task_terrain_algo_fail_before_training(tmp_path, capsys):
    with pytest.raises(ConfigError, match="unknown task"):
        drivers.train("go_stopp", "dry_sand", "ppo", out_dir=tmp_path)
    with pytest.raises(ConfigError, match="unknown terrain"):
        drivers.train("go_stop", "mud", "ppo", out_dir=tmp_path)
    with pytest.raises(ConfigError, match="unknown algorithm"):
        drivers.train("go_stop", "dry_sand", "dqn", out_dir=tmp_path)
    assert not any(tmp_path.iterdir())  # nothing was built or written
    assert main(["train", "NoSuchTask-v0", "--terrain", "dry_sand", "--out", str(tmp_path)]) == 2
    assert "unknown task" in capsys.readouterr().err
    assert main(["evaluate", "none", "--task", "go_stop", "--terrain", "moon"]) == 2
    assert "unknown terrain" in capsys.readouterr().err
    assert drivers.resolve_task("JTurn-v0") == "j_turn" and drivers.resolve_task("trackenv/GoStop-v0") == "go_stop"


# ----------------------------------------------------------------------------------------------
# policy loading


@pytest.fixture(scope="module")
def tiny_policy(tmp_path_factory):
    """A tiny (untrained) PPO zip for GoStop-v0."""
    d = tmp_path_factory.mktemp("pol")
    res = drivers.train("go_stop", "dry_sand", "ppo", timesteps=64, out_dir=d, progress_bar=False, tensorboard=False,
                        config={"default": {"n_envs": 4, "n_timesteps": 64, "n_steps": 16, "batch_size": 32, "n_epochs": 1,
                                            "policy_kwargs": {"net_arch": [8]}, "checkpoint_freq": 32,
                                            "env_kwargs": {"max_time": 0.5}}})
    return res


def test_train_writes_zip_record_and_checkpoints_and_resumes(tiny_policy):
    res = tiny_policy
    assert res.model_path.name == "GoStop-v0-dry_sand.zip" and res.model_path.is_file()
    info = json.loads(res.info_path.read_text())
    assert info["n_timesteps"] >= 64 and info["train_seconds"] > 0 and 0 < info["env_step_share"] <= 1
    assert info["seed"] == 0 and info["config"]["n_envs"] == 4
    assert drivers.latest_checkpoint(res.model_path.parent) is not None
    first = pd.read_csv(res.model_path.parent / "GoStop-v0-dry_sand.curve.csv")
    cfg = dict(info["config"])
    r2 = drivers.train("go_stop", "dry_sand", "ppo", config={"default": cfg}, timesteps=128, out_dir=res.model_path.parent,
                       resume=True, progress_bar=False, tensorboard=False)
    assert r2.info["resumed_from"] and r2.info["n_timesteps"] >= 128
    # the learning curve: one row per rollout, continued across the resume, and its figure
    curve = pd.read_csv(r2.model_path.parent / "GoStop-v0-dry_sand.curve.csv")
    assert list(curve.columns) == ["timesteps", "wall_s", "env_s", "mean_return", "success_rate", "episodes"]
    assert len(first) == 64 // (4 * 16) and len(curve) == 128 // (4 * 16)
    assert curve["timesteps"].is_monotonic_increasing and curve["wall_s"].is_monotonic_increasing
    assert curve["timesteps"].iloc[-1] == r2.info["n_timesteps"]
    assert curve.iloc[: len(first)].equals(first)
    assert (curve["env_s"] <= curve["wall_s"]).all() and (curve["env_s"] > 0).all()
    assert (r2.model_path.parent / "GoStop-v0-dry_sand.curve.png").stat().st_size > 10_000


def test_randomized_training_names_the_driver_and_records_the_ranges(tmp_path):
    res = drivers.train("go_stop", "dry_sand", "ppo", timesteps=64, out_dir=tmp_path, progress_bar=False,
                        tensorboard=False, randomize=True,
                        config={"default": {"n_envs": 4, "n_timesteps": 64, "n_steps": 16, "batch_size": 32,
                                            "n_epochs": 1, "policy_kwargs": {"net_arch": [8]},
                                            "env_kwargs": {"max_time": 0.5}}})
    assert res.model_path.name == "GoStop-v0-dry_sand-randomized.zip" and res.model_path.is_file()
    info = res.info
    assert info["config"]["env_kwargs"]["domain_randomization"] is True
    assert info["driver_meta"]["domain_randomization"] is True
    assert info["command"].endswith("--randomize") and info["driver"] == "GoStop-v0-dry_sand-randomized"
    model = drivers.load_policy(res.model_path, "go_stop", "dry_sand", warn=False)
    assert model.trackenv_driver["domain_randomization"] is True


def test_ground_mixture_training_records_the_grounds(tmp_path):
    cfg = {"default": {"n_envs": 4, "n_timesteps": 64, "n_steps": 16, "batch_size": 32, "n_epochs": 1,
                       "policy_kwargs": {"net_arch": [8]}, "env_kwargs": {"max_time": 0.5}}}
    with pytest.raises(ConfigError, match="randomize"):
        drivers.train("go_stop", "asphalt", "ppo", out_dir=tmp_path, config=cfg, grounds=["asphalt", "dry_sand"])
    with pytest.raises(ConfigError, match="already set domain_randomization"):
        drivers.train("go_stop", "asphalt", "ppo", out_dir=tmp_path, randomize=True, grounds=["dry_sand"],
                      config={"default": {**cfg["default"], "env_kwargs": {"domain_randomization": True}}})
    with pytest.raises(ConfigError, match="unknown terrain 'moon'"):
        drivers.train("go_stop", "asphalt", "ppo", out_dir=tmp_path, config=cfg, randomize=True, grounds=["moon"])
    res = drivers.train("go_stop", "asphalt", "ppo", out_dir=tmp_path, progress_bar=False, tensorboard=False,
                        randomize=True, grounds=["asphalt", "dry_sand"], config=cfg)
    assert res.info["config"]["env_kwargs"]["domain_randomization"] == {"grounds": ["asphalt", "dry_sand"]}
    assert res.info["command"].endswith("--randomize --grounds asphalt,dry_sand")
    assert res.model_path.name == "GoStop-v0-asphalt-randomized.zip"


def test_load_warns_pickle_and_checks_spaces(tiny_policy, capsys):
    with pytest.warns(drivers.PickleWarning, match="trusted sources"):
        model = drivers.load_policy(tiny_policy.model_path, "go_stop", "dry_sand")
    assert "trusted sources" in capsys.readouterr().err
    assert model.observation_space.shape[0] == len(drivers.expected_spaces("go_stop")[0].low)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(drivers.PolicySpaceError, match="observation space"):
            drivers.load_policy(tiny_policy.model_path, "zero_radius_turn", "dry_sand")  # other task, other obs
        with pytest.raises(drivers.PolicySpaceError):
            drivers.evaluate("j_turn", "dry_sand", tiny_policy.model_path, episodes=1, methods=("learned",))
    assert main(["evaluate", str(tiny_policy.model_path), "--task", "lane_change", "--terrain", "dry_sand"]) == 2
    assert "does not match" in capsys.readouterr().err


# ----------------------------------------------------------------------------------------------
# evaluation metrics


def test_open_loop_energy_is_integral_of_v_i_and_logs_are_field_logs(tmp_path):
    from trackenv.fieldlog import read_field_log

    res = drivers.evaluate("go_stop", "dry_sand", None, episodes=1, methods=("open_loop", "classical"),
                           log_dir=tmp_path / "logs", figures=tmp_path / "fig")
    ol = res["methods"]["open_loop"]
    ep = ol["episodes"][0]
    log = read_field_log(tmp_path / "logs" / "open_loop_seed1000")
    assert log.synthetic and log.meta["simulated"] and log.current_sensor == "signed"
    t, v, m = log.t, log.volts, log.measured()
    # energy = integral of sum_k max(V_k i_k, 0) dt, independently from the 20 Hz log (rectangle rule on the
    # held voltage with the current at both ends of each step); the env integrates over 1 ms substeps
    p0 = np.maximum(v[:-1] * np.stack([m["i_left"][:-1], m["i_right"][:-1]], 1), 0).sum(1)
    p1 = np.maximum(v[:-1] * np.stack([m["i_left"][1:], m["i_right"][1:]], 1), 0).sum(1)
    e_log = float(np.sum(0.5 * (p0 + p1) * np.diff(t)))
    assert ep["energy"] == pytest.approx(e_log, rel=0.06)
    assert ep["peak_current"] == pytest.approx(np.max(np.abs([m["i_left"], m["i_right"]])), rel=1e-5)
    # the open-loop go-stop ramps from 0 V up to its voltage, holds it and ramps down to 0: the first command
    # and the steps between commands (from the log, whose last row repeats the last command) add up to twice
    # the peak, on a few of the control steps
    dv = np.diff(v[:-1], axis=0)
    assert np.abs(v[0]) + np.abs(dv).sum(0) == pytest.approx(2 * np.abs(v).max(0), rel=1e-5)
    assert 0 < np.count_nonzero(np.abs(dv).max(1) > 0.1) < len(dv) / 4
    assert ep["voltage_step_rms"] == pytest.approx(float(np.sqrt(np.mean(dv**2))), rel=1e-5)
    assert ep["success"] and ep["completion_time"] == pytest.approx(ep["time"])
    # classical PI (tuned gains) succeeds on the go-stop
    assert res["methods"]["classical"]["summary"]["success_rate"] == 1.0
    assert len(res["figures"]) == 3 and all(Path(f).is_file() for f in res["figures"])
    table = drivers.format_table(res)
    assert "open_loop" in table and "classical" in table


# ----------------------------------------------------------------------------------------------
# learning smoke test: a few thousand PPO steps beat the random policy on the same seeds

SMOKE_ENV = {"max_time": 2.0}
SMOKE_CFG = {"default": {"n_envs": 16, "n_timesteps": 12288, "n_steps": 32, "batch_size": 128, "n_epochs": 10,
                         "learning_rate": 3e-3, "gamma": 0.95, "policy_kwargs": {"net_arch": [32, 32]},
                         "checkpoint_freq": 100000, "env_kwargs": SMOKE_ENV}}


def smoke_returns(driver, seeds, env_kwargs=SMOKE_ENV):
    venv = drivers.make_eval_env("go_stop", "dry_sand", len(seeds), randomize=True, env_kwargs=env_kwargs)
    eps = drivers.run_episodes(venv, driver, seeds)
    venv.close()
    return np.array([e["episode_return"] for e in eps])


def test_ppo_learns_go_stop_better_than_random(tmp_path):
    seeds = list(range(100, 116))
    rng = np.random.default_rng(0)
    random_returns = smoke_returns(lambda obs: rng.uniform(-1, 1, (len(obs), 2)).astype(np.float32), seeds)
    res = drivers.train("go_stop", "dry_sand", "ppo", config=SMOKE_CFG, seed=0, out_dir=tmp_path, progress_bar=False,
                        tensorboard=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = drivers.load_policy(res.model_path, "go_stop", "dry_sand", warn=False)
    learned = smoke_returns(drivers.Learned(model), seeds)
    # significantly better: Welch's t statistic of the gain > 5 (p << 1e-4), and a sizeable gain
    gain = learned.mean() - random_returns.mean()
    se = np.sqrt(learned.var(ddof=1) / len(seeds) + random_returns.var(ddof=1) / len(seeds))
    assert gain > 8.0 and gain / max(se, 1e-9) > 5.0, (learned.mean(), random_returns.mean(), se)


def test_sac_trains_saves_and_loads(tmp_path):
    cfg = {"default": {"n_envs": 4, "n_timesteps": 64, "learning_starts": 16, "batch_size": 16, "buffer_size": 1000,
                       "policy_kwargs": {"net_arch": [8]}, "env_kwargs": {"max_time": 0.5}}}
    res = drivers.train("zero_radius_turn", "asphalt", "sac", config=cfg, out_dir=tmp_path, progress_bar=True,
                        tensorboard=False)
    assert res.info["algo"] == "sac" and res.model_path.name == "ZeroRadiusTurn-v0-asphalt.zip"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = drivers.load_policy(res.model_path, "ZeroRadiusTurn-v0", "asphalt")
    assert type(model).__name__ == "SAC"


def test_residual_driver_with_zero_policy_is_the_classical_controller():
    """The residual wrapper applies classical(obs) + r * action: a zero action reproduces the PI episode."""
    gains = controllers.load_gains("go_stop", "dry_sand")
    venv, _, _ = drivers.make_vec_env("go_stop", "dry_sand", 2, {}, seed=1000, residual={"scale": 0.3, "gains": gains})
    obs = venv.reset()
    rewards = []
    for _ in range(30):
        obs, r, done, _ = venv.step(np.zeros((2, 2), np.float32))
        rewards.append(r[0])
    venv.close()
    env = drivers.make_eval_env("go_stop", "dry_sand", 1)
    eps = drivers.run_episodes(env, controllers.classical_for(env.params, gains), [1000])
    assert eps[0]["success"]
    # same returns over the first 30 steps (nominal terrain: the seed does not matter)
    partial = float(np.sum(rewards))
    env2 = drivers.make_eval_env("go_stop", "dry_sand", 1, env_kwargs={"max_time": 1.5})
    eps2 = drivers.run_episodes(env2, controllers.classical_for(env2.params, gains), [1000])
    assert partial == pytest.approx(eps2[0]["episode_return"], rel=1e-4, abs=1e-3)


def test_records_name_repository_files_relative_to_the_repository(tmp_path):
    from trackenv.drivers.config import CONFIG_DIR, repo_relative

    assert repo_relative(CONFIG_DIR / "ppo.yaml") == "configs/train/ppo.yaml"
    assert repo_relative(tmp_path / "x.zip") == str(tmp_path / "x.zip")  # outside the repository: as given
    assert repo_relative(None) is None


def test_guided_plain_driver_fades_the_classical_part_and_saves_a_plain_policy(tmp_path):
    """``guide: f``: the classical weight falls linearly 1 -> 0 over f x n_timesteps; the saved driver is plain
    (no classical part at inference); a guide on a residual driver is a config error naming the key."""
    from trackenv.drivers.wrappers import GuideSchedule

    gains = controllers.load_gains("go_stop", "dry_sand")
    venv, _, guided = drivers.make_vec_env("go_stop", "dry_sand", 2, {}, seed=1000,
                                           residual={"scale": 1.0, "gains": gains, "classical_weight": 1.0})
    sched = GuideSchedule(guided, 1000)
    assert [sched.weight(s) for s in (0, 250, 1000, 5000)] == [1.0, 0.75, 0.0, 0.0]
    # weight 0 and a zero action: zero voltages, the vehicle does not move; weight 1: the PI drives
    for w, moves in ((0.0, False), (1.0, True)):
        guided.classical_weight = w
        obs0 = venv.reset()
        for _ in range(10):
            obs, *_ = venv.step(np.zeros((2, 2), np.float32))
        dist = obs0[0, 1] - obs[0, 1]  # distance_to_mark shrinks as it drives
        assert (dist > 0.05) == moves, (w, dist)
    venv.close()
    with pytest.raises(ConfigError, match="guide"):
        drivers.load_config("ppo", "go_stop", config={"default": {"n_timesteps": 64, "residual": 0.3, "guide": 0.5}})
    cfg = {"default": {"n_envs": 4, "n_steps": 8, "batch_size": 16, "n_epochs": 1, "n_timesteps": 64, "guide": 0.5,
                       "policy_kwargs": {"net_arch": [8]}, "env_kwargs": {"max_time": 0.5}}}
    res = drivers.train("go_stop", "dry_sand", "ppo", config=cfg, out_dir=tmp_path, progress_bar=False,
                        tensorboard=False)
    meta = res.info["driver_meta"]
    assert meta["residual"] == 0.0 and meta["guide"]["fraction"] == 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = drivers.load_policy(res.model_path, "go_stop", "dry_sand")
    assert drivers.Learned(model).ctrl is None  # acts alone


def test_guide_release_stop_leaves_the_stop_to_the_policy():
    """``guide_release_stop``: in the J-turn's stop phase (observation phase_stop = 1) the guide's classical
    part is not applied; outside it, it is. Without a guide, or on a task without a stop phase, it is a
    config error naming the key."""
    gains = controllers.load_gains("j_turn", "asphalt")
    venv, _, guided = drivers.make_vec_env("j_turn", "asphalt", 2, {}, seed=1000,
                                           residual={"scale": 1.0, "gains": gains, "classical_weight": 1.0,
                                                     "release_stop": True})
    col = guided.release_column
    assert col == list(task_class("j_turn").obs_names).index("phase_stop")
    venv.reset()
    steps = []  # (phase_stop before the step, |PI voltages|, the weight applied)
    for _ in range(120):
        before = guided._obs.copy()
        _, _, dones, _ = venv.step(np.zeros((2, 2), np.float32))  # the policy adds nothing: the guide drives
        steps.append((float(before[0, col]), float(np.abs(guided.last_classical[0]).sum()), float(guided.last_weight[0])))
        if dones.any():
            break
    assert any(p == 0.0 and c > 0.05 and w == 1.0 for p, c, w in steps), "the guide drives before the stop phase"
    stop = [(c, w) for p, c, w in steps if p == 1.0]
    assert stop and all(w == 0.0 for _, w in stop), "in the stop phase the classical part is released"
    assert any(c > 0.0 for c, _ in stop), "the PI would still act there"
    venv.close()
    for bad in ({"guide": 0.0, "guide_release_stop": True}, {"guide": 0.5, "guide_release_stop": "yes"}):
        with pytest.raises(ConfigError, match="guide_release_stop"):
            drivers.load_config("ppo", "j_turn", config={"default": {"n_timesteps": 64, **bad}})
    with pytest.raises(ConfigError, match="phase_stop"):
        drivers.load_config("ppo", "go_stop", config={"default": {"n_timesteps": 64, "guide": 0.5,
                                                                  "guide_release_stop": True}})


def test_speed_error_penalty_makes_standing_still_costly():
    """``speed_error_weight``: the reward drops by w_v (e_v / 0.2 m/s)^2 on the speed error of the next
    observation; a task without a speed error observation (zero-radius turn) is a config error."""
    rewards = {}
    for w in (0.0, 2.0):
        venv, _, _ = drivers.make_vec_env("j_turn", "dry_sand", 2, {}, seed=1000, speed_error_weight=w)
        venv.reset()
        obs, r, _, _ = venv.step(np.zeros((2, 2), np.float32))  # zero voltages: the vehicle stays put
        rewards[w] = (r, obs)
        venv.close()
    (r0, obs0), (r2, _) = rewards[0.0], rewards[2.0]
    e_v = obs0[:, 0]  # speed_error: the reference speed, as the vehicle does not move
    assert np.all(e_v > 0.1)
    np.testing.assert_allclose(r0 - r2, 2.0 * (e_v / 0.2) ** 2, rtol=1e-4)
    with pytest.raises(ConfigError, match="speed_error"):
        drivers.train("zero_radius_turn", "asphalt", "ppo", out_dir=None, tensorboard=False, progress_bar=False,
                      config={"default": {"n_envs": 4, "n_steps": 8, "n_timesteps": 64, "speed_error_weight": 1.0}})


def test_action_rate_penalty_prices_the_change_of_the_action_within_an_episode():
    """``action_rate_weight``: the reward drops by w_a mean_k (a_k - a_k,prev)^2, nothing on an episode's first
    step or while the action holds; a negative weight is a config error naming the key."""
    w = 3.0
    a1 = np.array([[0.2, 0.4], [0.3, 0.3]], np.float32)
    a2 = np.array([[0.5, -0.2], [0.3, 0.3]], np.float32)
    rewards = {}
    for weight in (0.0, w):
        venv, _, _ = drivers.make_vec_env("j_turn", "dry_sand", 2, {}, seed=1000, action_rate_weight=weight)
        venv.reset()
        rewards[weight] = [venv.step(a)[1] for a in (a1, a2, a2)]
        venv.close()
    first, change, hold = (r0 - rw for r0, rw in zip(rewards[0.0], rewards[w]))
    np.testing.assert_allclose(first, 0.0, atol=1e-6)
    np.testing.assert_allclose(change, w * np.mean((a2 - a1) ** 2, axis=1), rtol=1e-4, atol=1e-6)
    assert change[0] > 0.5 and abs(change[1]) < 1e-6  # the second environment holds its action
    np.testing.assert_allclose(hold, 0.0, atol=1e-6)
    with pytest.raises(ConfigError, match="'action_rate_weight' must be a non-negative number"):
        drivers.load_config("ppo", "go_stop", config={"default": {"n_timesteps": 64, "action_rate_weight": -1}})


def test_imitation_warm_start_clones_the_classical_controller():
    """``imitate: n``: the policy's mean action is fitted to n steps of the PI's episodes, after which the
    plain policy alone reproduces the PI's voltages on the states of a fresh PI episode (mean squared error
    in units of the voltage limit, against an untrained policy's), and the environment is left plain; with
    a guide it is a config error."""
    from stable_baselines3 import PPO

    from trackenv.drivers.train import imitate_classical

    gains = controllers.load_gains("go_stop", "dry_sand")
    venv, _, guided = drivers.make_vec_env("go_stop", "dry_sand", 8, {}, seed=1000,
                                           residual={"scale": 1.0, "gains": gains, "classical_weight": 0.0})
    kw = {"n_steps": 16, "batch_size": 64, "seed": 0, "device": "cpu", "policy_kwargs": {"net_arch": [64, 64]}}
    model, untrained = PPO("MlpPolicy", venv, **kw), PPO("MlpPolicy", venv, **kw)
    res = imitate_classical(model, venv, guided, steps=1600, epochs=30)
    assert res["samples"] == 1600 and guided.classical_weight == 0.0
    guided.classical_weight = 1.0  # a fresh PI episode: its states and the PI's actions
    obs = venv.reset()
    states, actions = [], []
    for _ in range(60):
        states.append(obs)
        obs, *_ = venv.step(np.zeros((8, 2), np.float32))
        actions.append(np.clip(guided.last_classical, -1.0, 1.0))
    venv.close()
    x, y = np.concatenate(states), np.concatenate(actions)
    mse = {name: float(np.mean((np.clip(m.predict(x, deterministic=True)[0], -1, 1) - y) ** 2))
           for name, m in (("cloned", model), ("untrained", untrained))}
    assert res["action_mse"] < 1e-2 and mse["cloned"] < 5e-3 and mse["cloned"] < 0.05 * mse["untrained"], (res, mse)
    with pytest.raises(ConfigError, match="imitate"):
        drivers.load_config("ppo", "go_stop", config={"default": {"n_timesteps": 64, "guide": 0.5, "imitate": 100}})


def test_init_continues_a_trained_driver_and_never_overwrites_it(tmp_path):
    plain = {"default": {"n_envs": 4, "n_timesteps": 64, "n_steps": 16, "batch_size": 32, "n_epochs": 1,
                         "residual": 0.0, "policy_kwargs": {"net_arch": [8]}, "env_kwargs": {"max_time": 0.5}}}
    first = drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path / "a", progress_bar=False, tensorboard=False,
                          config=plain)
    polish = {"default": {**plain["default"], "learning_rate": 1e-5}}
    res = drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path / "b", progress_bar=False, tensorboard=False,
                        config=polish, init=first.model_path)
    assert res.info["n_timesteps"] == 64  # a new run of n_timesteps steps, not the first run's counter
    assert res.info["total_timesteps"] == 128 and res.info["init_record"]["n_timesteps"] == 64
    assert res.info["total_train_seconds"] > res.info["train_seconds"]
    assert res.info["init_from"] == str(first.model_path) and "--init" in res.info["command"]
    model = drivers.load_policy(res.model_path, "go_stop", "dry_sand", warn=False)
    assert model.learning_rate == 1e-5 and model.trackenv_driver["init_from"] == str(first.model_path)
    before = drivers.load_policy(first.model_path, "go_stop", "dry_sand", warn=False)
    w0 = before.policy.state_dict()["action_net.weight"]
    assert not (model.policy.state_dict()["action_net.weight"] == w0).all()  # it trained on
    stamp = first.model_path.stat().st_mtime_ns
    with pytest.raises(ConfigError, match="never overwritten"):
        drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path / "a", config=polish, init=first.model_path)
    with pytest.raises(ConfigError, match="residual"):
        drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path / "c", progress_bar=False, tensorboard=False,
                      config={"default": {**plain["default"], "residual": 0.3}}, init=first.model_path)
    with pytest.raises(ConfigError, match="no driver zip"):
        drivers.train("go_stop", "dry_sand", "ppo", out_dir=tmp_path / "c", config=plain, init=tmp_path / "none.zip")
    assert first.model_path.stat().st_mtime_ns == stamp
