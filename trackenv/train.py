"""Stable-Baselines3 drivers: configs, training, loading.

    trackenv train j_turn --terrain dry_sand --algo ppo --seed 0          # configs/train/ppo.yaml
    trackenv train JTurn-v0 --terrain asphalt --algo sac --timesteps 20000 --out out/train/jt
    trackenv train j_turn --terrain dry_sand --algo ppo --resume          # from the latest checkpoint

    from trackenv.train import load_config, train, load_policy
    cfg = load_config("ppo", "j_turn")                 # validated dict (RL Zoo style)
    result = train("j_turn", "dry_sand", "ppo", seed=0, out_dir="out/train/jt")
    model = load_policy(result.model_path, "j_turn", "dry_sand")   # warns: SB3 zips are pickles

Configs (``configs/train/<algo>.yaml``) follow the RL Baselines3 Zoo layout: one section per
environment name (``GoStop-v0``, ``JTurn-v0``, ``LaneChange-v0``, ``ZeroRadiusTurn-v0``) merged over a
``default`` section; optional ``<EnvName>-<terrain>`` sections (e.g. ``JTurn-v0-asphalt``) are merged
last. Keys of a section:

==================  ==============================================================================
n_envs              environments in the native vector env (one jitted, vmapped call per step)
n_timesteps         total environment steps
policy              ``MlpPolicy``
policy_kwargs       dict: ``net_arch`` (list or dict), ``activation_fn`` (``tanh``/``relu``/``elu``),
                    ``log_std_init``, ``ortho_init``, ``squash_output`` ... (SB3's policy kwargs)
env_kwargs          dict passed to :class:`~trackenv.envs.vector.TrackVectorEnv` (``control_dt``,
                    ``substep``, ``domain_randomization``, task options such as ``max_time``)
checkpoint_freq     environment steps between checkpoints (default 100 000)
residual            0 (default): the policy's action is the voltages; r > 0: a **residual** driver, the
                    voltages are the classical PI controller's (trackenv.envs.controllers.ClassicalController,
                    gains of configs/train/classical_gains.yaml) plus r x the policy's action, all in
                    units of the 24 V limit (the gains and r are stored in the zip; see train/README.md)
error_weight        w >= 0 (default 0): training reward shaping, r - w (e / s)^2 with e the task's
                    primary tracking error (the evaluated RMSE's) read from the next observation and s
                    its kernel scale (go-stop 0.2 m/s, J-turn/lane change 0.15 m, zero-radius 0.5 rad/s);
                    the environment's reward kernels saturate for large errors, the RMSE does not.
                    VecMonitor (and the reported returns) see the unshaped reward
any other key       a keyword of the algorithm's constructor (``learning_rate``, ``n_steps``,
                    ``batch_size``, ``gamma``, ``gae_lambda``, ``ent_coef``, ``clip_range``,
                    ``n_epochs``, ``buffer_size``, ``train_freq``, ...), checked against its signature
==================  ==============================================================================

An unknown key, task, terrain or algorithm raises :class:`~trackenv.params.ConfigError` naming the
file and key **before** any environment is built or any training starts.

Training runs on :class:`~trackenv.envs.vector.SB3VecEnv` (actions normalised to [-1, 1] x 24 V)
wrapped in ``VecMonitor`` and a step timer that measures the share of wall time spent stepping the
environment. Outputs of a run (``out_dir``):

- ``<EnvName>-<terrain>.zip``: the final policy (SB3 zip);
- ``<EnvName>-<terrain>.json``: task, terrain, algorithm, seed, the resolved config, timesteps, wall
  time [s], time in env.step / env.reset [s], the command that reproduces it, library versions;
- ``checkpoints/``: ``rl_model_<steps>_steps.zip`` every ``checkpoint_freq`` steps (``--resume``
  continues from the latest one, the step counter included);
- ``tb/``: TensorBoard logs (when ``tensorboard`` is installed).

Loading a policy (:func:`load_policy`) warns that SB3 zips are pickles that can run code and must come
from trusted sources, and checks its observation and action spaces against the environment's.
"""

from __future__ import annotations

import copy
import inspect
import json
import re
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .envs.tasks import ENV_NAMES, task_class
from .envs.tasks import TASKS as _TASK_CLASSES
from .params import ConfigError

ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = ROOT / "configs" / "train"
DRIVERS_DIR = ROOT / "train" / "drivers"

TASKS = tuple(_TASK_CLASSES)  # task ids, from the task registry (trackenv.envs.tasks)
ENV_NAME = ENV_NAMES  # task id -> env name
TERRAINS = ("dry_sand", "asphalt")  # the shipped drivers' terrains; any configs/terrain id trains
ALGOS = ("ppo", "sac")
META_KEYS = ("n_envs", "n_timesteps", "policy", "policy_kwargs", "env_kwargs", "checkpoint_freq", "residual",
             "error_weight")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")
PICKLE_WARNING = ("SB3 policy zips are pickles and can run arbitrary code when loaded: load only policies "
                  "from trusted sources")


class PolicySpaceError(ValueError):
    """A policy zip was trained for another observation or action space than the environment's."""


class PickleWarning(UserWarning):
    """Loading an SB3 zip unpickles it (it can run code)."""


# ----------------------------------------------------------------------------------------------
# names


def resolve_task(task: str) -> str:
    """Task id from a task id (``j_turn``), an env name (``JTurn-v0``) or an env id (``trackenv/JTurn-v0``)."""
    return task_class(task).name


def resolve_terrain(terrain: str) -> str:
    """A terrain id of configs/terrain (``dry_sand``, ``asphalt``, ``sandy_loam_1`` ...), checked."""
    from .params import list_terrains  # noqa: PLC0415

    known = list_terrains()
    if terrain not in known:
        raise ConfigError(f"unknown terrain {terrain!r}; known: {', '.join(known)}")
    return terrain


def resolve_algo(algo: str) -> str:
    a = str(algo).lower()
    if a not in ALGOS:
        raise ConfigError(f"unknown algorithm {algo!r}; known: {', '.join(ALGOS)}")
    return a


def algo_class(algo: str):
    import stable_baselines3 as sb3  # noqa: PLC0415

    return {"ppo": sb3.PPO, "sac": sb3.SAC}[resolve_algo(algo)]


def driver_name(task: str, terrain: str) -> str:
    """``<EnvName>-<terrain>``, e.g. ``JTurn-v0-dry_sand`` (the shipped zip's stem)."""
    return f"{ENV_NAME[resolve_task(task)]}-{terrain}"


# ----------------------------------------------------------------------------------------------
# configs


def _allowed_algo_keys(algo: str) -> set[str]:
    cls = algo_class(algo)
    sig = inspect.signature(cls.__init__)
    skip = {"self", "policy", "env", "policy_kwargs", "tensorboard_log", "verbose", "seed", "device",
            "_init_setup_model", "kwargs"}
    return {k for k in sig.parameters if k not in skip}


def _check_section(section: Any, where: str, allowed: set[str]) -> dict:
    if section is None:
        return {}
    if not isinstance(section, dict):
        raise ConfigError(f"{where}: must be a mapping of hyperparameters, got {type(section).__name__}")
    for k in section:
        if k not in allowed:
            raise ConfigError(f"{where}: unknown key '{k}'; allowed: {', '.join(sorted(allowed))}")
    return section


def config_path(algo: str, config: str | Path | None = None) -> Path:
    return Path(config) if config is not None else CONFIG_DIR / f"{resolve_algo(algo)}.yaml"


def load_config(algo: str, task: str, terrain: str | None = None, config: str | Path | dict | None = None) -> dict:
    """The validated hyperparameters for ``algo`` on ``task`` (and ``terrain``), RL Zoo style.

    ``config``: a YAML path (default ``configs/train/<algo>.yaml``) or a ready dict of the same layout.
    Raises :class:`ConfigError` naming the file and the key on any unknown key or bad value.
    """
    algo = resolve_algo(algo)
    task = resolve_task(task)
    if isinstance(config, dict):
        raw, where = copy.deepcopy(config), "config"
    else:
        path = config_path(algo, config)
        if not path.is_file():
            raise ConfigError(f"training config not found: {path}")
        try:
            raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {exc}") from None
        where = str(path)
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: must be a mapping of sections (default, <EnvName>, <EnvName>-<terrain>)")
    allowed = set(META_KEYS) | _allowed_algo_keys(algo)
    names = set(ENV_NAME.values())
    sections = {"default"} | names | {f"{n}-{t}" for n in names for t in _terrain_ids()}
    for key in raw:
        if key not in sections:
            raise ConfigError(f"{where}: unknown section '{key}'; sections are 'default', an env name "
                              f"({', '.join(sorted(names))}) or '<EnvName>-<terrain>'")
        _check_section(raw[key], f"{where} [{key}]", allowed)
    merged: dict = {}
    order = ["default", ENV_NAME[task]] + ([f"{ENV_NAME[task]}-{terrain}"] if terrain else [])
    for key in order:
        for k, v in (raw.get(key) or {}).items():
            if isinstance(v, dict) and isinstance(merged.get(k), dict):
                merged[k] = {**merged[k], **v}
            else:
                merged[k] = copy.deepcopy(v)
    return _validate_values(merged, f"{where} [{' + '.join(k for k in order if k in raw)}]", algo)


def _terrain_ids() -> list[str]:
    from .params import list_terrains  # noqa: PLC0415

    return list_terrains()


def _validate_values(cfg: dict, where: str, algo: str) -> dict:
    cfg = dict(cfg)
    cfg.setdefault("policy", "MlpPolicy")
    cfg.setdefault("n_envs", 64)
    cfg.setdefault("checkpoint_freq", 100_000)
    cfg.setdefault("policy_kwargs", {})
    cfg.setdefault("env_kwargs", {})
    cfg.setdefault("residual", 0.0)
    r = cfg["residual"]
    if isinstance(r, bool) or not isinstance(r, (int, float)) or not (0.0 <= float(r) <= 2.0):
        raise ConfigError(f"{where}: 'residual' must be a number in [0, 2] (0: plain policy), got {r!r}")
    cfg["residual"] = float(r)
    cfg.setdefault("error_weight", 0.0)
    w = cfg["error_weight"]
    if isinstance(w, bool) or not isinstance(w, (int, float)) or not (0.0 <= float(w) < 1e3):
        raise ConfigError(f"{where}: 'error_weight' must be a non-negative number, got {w!r}")
    cfg["error_weight"] = float(w)
    if "n_timesteps" not in cfg:
        raise ConfigError(f"{where}: missing key 'n_timesteps'")
    for k in ("n_envs", "n_timesteps", "checkpoint_freq"):
        v = cfg[k]
        if isinstance(v, float) and v.is_integer():
            v = cfg[k] = int(v)
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ConfigError(f"{where}: '{k}' must be a positive integer, got {v!r}")
    if cfg["policy"] != "MlpPolicy":
        raise ConfigError(f"{where}: 'policy' must be 'MlpPolicy', got {cfg['policy']!r}")
    for k in ("policy_kwargs", "env_kwargs"):
        if not isinstance(cfg[k], dict):
            raise ConfigError(f"{where}: '{k}' must be a mapping, got {cfg[k]!r}")
    act = cfg["policy_kwargs"].get("activation_fn")
    if act is not None and act not in ACTIVATIONS:
        raise ConfigError(f"{where}: policy_kwargs.activation_fn must be one of {ACTIVATIONS}, got {act!r}")
    bad_env = sorted(set(cfg["env_kwargs"]) & {"normalize_action", "autoreset_mode", "terrain", "task", "num_envs"})
    if bad_env:
        raise ConfigError(f"{where}: env_kwargs may not set {bad_env} (fixed by the trainer / command line)")
    for k in ("learning_rate", "gamma", "gae_lambda", "ent_coef", "clip_range", "tau", "vf_coef", "max_grad_norm"):
        if k in cfg and not (isinstance(cfg[k], (int, float)) and not isinstance(cfg[k], bool)
                             and np.isfinite(cfg[k]) and cfg[k] >= 0):
            if not (k == "ent_coef" and isinstance(cfg[k], str) and cfg[k].startswith("auto")):
                raise ConfigError(f"{where}: '{k}' must be a non-negative number, got {cfg[k]!r}")
    return cfg


def policy_kwargs(cfg: dict) -> dict:
    """SB3 policy kwargs from the config (activation names -> torch classes)."""
    import torch.nn as nn  # noqa: PLC0415

    pk = dict(cfg.get("policy_kwargs") or {})
    if "activation_fn" in pk:
        pk["activation_fn"] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "leaky_relu": nn.LeakyReLU}[pk["activation_fn"]]
    return pk


def _algo_kwargs(cfg: dict) -> dict:
    return {k: v for k, v in cfg.items() if k not in META_KEYS}


# ----------------------------------------------------------------------------------------------
# environments


def make_vec_env(task: str, terrain: str, n_envs: int, env_kwargs: dict | None = None, seed: int | None = None,
                 residual: dict | None = None, error_weight: float = 0.0):
    """The SB3 training env: ``SB3VecEnv`` (normalised actions) in a step timer and ``VecMonitor``;
    with ``residual`` (``{"scale": r, "gains": {...}}``) the policy's action is added to the classical
    controller's (:class:`ResidualVecEnv`)."""
    from stable_baselines3.common.vec_env import VecMonitor  # noqa: PLC0415

    from .envs.vector import SB3VecEnv  # noqa: PLC0415

    venv = SB3VecEnv(task=resolve_task(task), num_envs=int(n_envs), normalize_action=True, terrain=terrain,
                     **(env_kwargs or {}))
    timer = StepTimer(venv)
    inner = ResidualVecEnv(timer, residual["scale"], residual["gains"]) if residual else timer
    mon = VecMonitor(inner, info_keywords=("is_success", "tracking_rmse"))
    if error_weight > 0:
        # the task's primary tracking error (its TaskEval.error, the RMSE metric) and its kernel scale
        pe = task_class(task).primary_error
        mon = ErrorPenalty(mon, venv.venv.obs_names.index(pe.obs_name), pe.scale, error_weight)
    if seed is not None:
        mon.seed(int(seed))
    return mon, timer


try:
    from stable_baselines3.common.vec_env import VecEnvWrapper as _VecEnvWrapper
except ImportError:  # pragma: no cover
    _VecEnvWrapper = object


class StepTimer(_VecEnvWrapper):
    """Accumulates the wall time spent in the wrapped env's ``step_wait`` and ``reset`` [s]."""

    def __init__(self, venv):
        super().__init__(venv)
        self.step_seconds = 0.0
        self.reset_seconds = 0.0
        self.steps = 0

    def reset(self):
        t0 = time.perf_counter()
        obs = self.venv.reset()
        self.reset_seconds += time.perf_counter() - t0
        return obs

    def step_async(self, actions):
        self.venv.step_async(actions)

    def step_wait(self):
        t0 = time.perf_counter()
        out = self.venv.step_wait()
        self.step_seconds += time.perf_counter() - t0
        self.steps += self.num_envs
        return out


class ResidualVecEnv(_VecEnvWrapper):
    """Residual driver: applied action = clip(classical(obs) + scale * policy action, -1, 1) (units of 24 V).

    The classical PI controller (:class:`trackenv.envs.controllers.ClassicalController`) runs on the same
    observations, one integrator per environment, reset when an episode ends.
    """

    def __init__(self, venv, scale: float, gains: dict):
        super().__init__(venv)
        from .envs.controllers import classical_for  # noqa: PLC0415

        base = venv
        while not hasattr(base, "venv") or not hasattr(base.venv, "params"):
            base = base.venv
        self.params = base.venv.params
        self.scale = float(scale)
        self.ctrl = classical_for(self.params, gains)
        self._obs = None

    def reset(self):
        self._obs = self.venv.reset()
        self.ctrl.reset()
        return self._obs

    def step_async(self, actions):
        a = self.ctrl(self._obs) + self.scale * np.asarray(actions, np.float32)
        self.venv.step_async(np.clip(a, -1.0, 1.0).astype(np.float32))

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        if dones.any():
            self.ctrl.reset_rows(dones)
        self._obs = obs
        return obs, rew, dones, infos


class ErrorPenalty(_VecEnvWrapper):
    """Training reward shaping: r - weight * (e / scale)^2, e = observation column ``index`` after the step
    (the terminal observation on the step an episode ends)."""

    def __init__(self, venv, index: int, scale: float, weight: float):
        super().__init__(venv)
        self.index, self.scale, self.weight = int(index), float(scale), float(weight)

    def reset(self):
        return self.venv.reset()

    def step_async(self, actions):
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rew, dones, infos = self.venv.step_wait()
        e = obs[:, self.index].astype(np.float64).copy()
        for i in np.flatnonzero(dones):
            term = infos[i].get("terminal_observation")
            if term is not None:
                e[i] = float(term[self.index])
        return obs, (rew - self.weight * np.square(e / self.scale)).astype(np.float32), dones, infos


# ----------------------------------------------------------------------------------------------
# training


@dataclass
class TrainResult:
    model_path: Path
    info_path: Path
    info: dict


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The checkpoint with the most steps in ``run_dir/checkpoints`` (None if there is none)."""
    ck = Path(run_dir) / "checkpoints"
    best, best_steps = None, -1
    for p in ck.glob("rl_model_*_steps.zip") if ck.is_dir() else ():
        m = re.fullmatch(r"rl_model_(\d+)_steps\.zip", p.name)
        if m and int(m.group(1)) > best_steps:
            best, best_steps = p, int(m.group(1))
    return best


def _versions() -> dict:
    import jax  # noqa: PLC0415
    import stable_baselines3  # noqa: PLC0415
    import torch  # noqa: PLC0415

    return {"stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__, "jax": jax.__version__,
            "python": sys.version.split()[0]}


def rollout_steps(cfg: dict, algo: str) -> int:
    """Environment steps SB3 collects per unit of training: n_envs x n_steps (PPO), n_envs (SAC)."""
    if algo == "ppo":
        return int(cfg["n_envs"]) * int(cfg.get("n_steps", 2048))  # 2048: PPO's own default
    return int(cfg["n_envs"])


def check_budget(cfg: dict, algo: str, where: str = "n_timesteps") -> int:
    """``ConfigError`` if ``n_timesteps`` is below one rollout (SB3 would silently train a whole rollout);
    a warning if it is not a multiple of one (SB3 rounds up). Returns the steps that will be trained."""
    unit = rollout_steps(cfg, algo)
    n = int(cfg["n_timesteps"])
    how = (f"n_envs {cfg['n_envs']} x n_steps {cfg.get('n_steps', 2048)}" if algo == "ppo"
           else f"n_envs {cfg['n_envs']}")
    if n < unit:
        raise ConfigError(f"{where} = {n} is less than one {algo.upper()} rollout ({how} = {unit} steps), which "
                          f"SB3 would train anyway; give at least {unit}, or lower n_envs/n_steps in the config")
    trained = -(-n // unit) * unit
    if trained != n:
        warnings.warn(f"{where} = {n} is not a multiple of the {unit}-step rollout ({how}); SB3 trains {trained} "
                      "steps", stacklevel=3)
    return trained


def train(task: str, terrain: str = "dry_sand", algo: str = "ppo", *, config: str | Path | dict | None = None,
          seed: int = 0, timesteps: int | None = None, out_dir: str | Path | None = None,
          run_dir: str | Path | None = None, resume: bool = False,
          progress_bar: bool = True, tensorboard: bool = True, verbose: int = 0, threads: int = 1,
          command: str | None = None) -> TrainResult:
    """Train a driver and save ``<out_dir>/<EnvName>-<terrain>.zip`` plus its ``.json`` record.

    Everything is validated (task, terrain, algorithm, config keys and values) before an environment
    is built. ``timesteps`` overrides the config's ``n_timesteps``; ``resume`` continues from the
    latest checkpoint in ``run_dir/checkpoints`` (the step count continues; the config must be the
        same). ``run_dir`` (default ``out_dir``) holds the checkpoints and TensorBoard logs. ``threads``: torch
    threads (1 on a 2-core machine: the env runs in JAX's own threads).
    """
    task = resolve_task(task)
    terrain = resolve_terrain(terrain)
    algo = resolve_algo(algo)
    cfg = load_config(algo, task, terrain, config)
    if timesteps is not None:
        if isinstance(timesteps, bool) or not isinstance(timesteps, (int, np.integer)) or timesteps < 1:
            raise ConfigError(f"timesteps must be a positive integer, got {timesteps!r}")
        cfg["n_timesteps"] = int(timesteps)
    check_budget(cfg, algo, where="--timesteps" if timesteps is not None else "n_timesteps")
    name = driver_name(task, terrain)
    out = Path(out_dir) if out_dir is not None else ROOT / "out" / "train" / f"{name}-{algo}-s{seed}"
    run = Path(run_dir) if run_dir is not None else out
    ckpt = latest_checkpoint(run) if resume else None
    if resume and ckpt is None:
        raise ConfigError(f"--resume: no checkpoint in {run / 'checkpoints'}")

    import torch  # noqa: PLC0415
    from stable_baselines3.common.callbacks import CheckpointCallback  # noqa: PLC0415

    torch.set_num_threads(int(threads))
    out.mkdir(parents=True, exist_ok=True)
    run.mkdir(parents=True, exist_ok=True)
    driver_meta = {"task": task, "terrain": terrain, "residual": cfg["residual"]}
    if cfg["residual"] > 0:
        from .envs.controllers import load_gains  # noqa: PLC0415

        driver_meta["gains"] = load_gains(task, terrain)
    residual = {"scale": cfg["residual"], "gains": driver_meta["gains"]} if cfg["residual"] > 0 else None
    venv, timer = make_vec_env(task, terrain, cfg["n_envs"], cfg["env_kwargs"], seed, residual, cfg["error_weight"])
    tb = None
    if tensorboard:
        try:
            import tensorboard as _tb  # noqa: F401,PLC0415

            tb = str(run / "tb")
        except ImportError:
            warnings.warn("tensorboard is not installed: no TensorBoard logs", stacklevel=2)
    if progress_bar:
        try:
            import rich  # noqa: F401,PLC0415
            import tqdm  # noqa: F401,PLC0415
        except ImportError:
            warnings.warn("tqdm/rich not installed: no progress bar", stacklevel=2)
            progress_bar = False
    cls = algo_class(algo)
    previous = {}
    if ckpt is not None:
        model = load_policy(ckpt, task, terrain, env=venv, algo=algo, warn=False)
        model.tensorboard_log = tb
        info_path = run / "progress.json"
        if info_path.is_file():
            previous = json.loads(info_path.read_text())
    else:
        model = cls(cfg["policy"], venv, policy_kwargs=policy_kwargs(cfg), seed=int(seed), device="cpu",
                    tensorboard_log=tb, verbose=verbose, **_algo_kwargs(cfg))
    done_before = int(model.num_timesteps)
    remaining = max(0, cfg["n_timesteps"] - done_before)
    callback = CheckpointCallback(save_freq=max(1, cfg["checkpoint_freq"] // cfg["n_envs"]),
                                  save_path=str(run / "checkpoints"), name_prefix="rl_model")
    t0 = time.perf_counter()
    model.learn(total_timesteps=remaining, callback=callback, progress_bar=progress_bar, tb_log_name=name,
                reset_num_timesteps=ckpt is None)
    wall = time.perf_counter() - t0
    model_path = out / f"{name}.zip"
    model.trackenv_driver = driver_meta  # saved in the zip's data; read back by trackenv.evaluate.Learned
    model.save(str(model_path))
    ep = list(model.ep_info_buffer)
    info = {
        "driver": name, "task": task, "env_id": f"trackenv/{ENV_NAME[task]}", "terrain": terrain, "algo": algo,
        "seed": int(seed), "config": cfg, "config_file": None if isinstance(config, dict) else str(config_path(algo, config)),
        "n_timesteps": int(model.num_timesteps),
        "train_seconds": wall + float(previous.get("train_seconds", 0.0)),
        "env_step_seconds": timer.step_seconds + timer.reset_seconds + float(previous.get("env_step_seconds", 0.0)),
        "resumed_from": str(ckpt) if ckpt else None, "driver_meta": driver_meta,
        "final_mean_return": float(np.mean([e["r"] for e in ep])) if ep else None,
        "final_success_rate": float(np.mean([e.get("is_success", 0.0) for e in ep])) if ep else None,
        "command": command or f"trackenv train {ENV_NAME[task]} --terrain {terrain} --algo {algo} --seed {seed}",
        "versions": _versions(), "model_bytes": model_path.stat().st_size,
    }
    info["env_step_share"] = info["env_step_seconds"] / max(info["train_seconds"], 1e-9)
    info_path = out / f"{name}.json"
    info_path.write_text(json.dumps(info, indent=2) + "\n")
    (run / "progress.json").write_text(json.dumps(info, indent=2) + "\n")
    venv.close()
    return TrainResult(model_path, info_path, info)


# ----------------------------------------------------------------------------------------------
# loading


def expected_spaces(task: str, terrain: str = "dry_sand", env_kwargs: dict | None = None):
    """(observation space, action space) of the SB3 env for ``task`` (normalised actions)."""
    from gymnasium import spaces  # noqa: PLC0415

    from .envs import core  # noqa: PLC0415

    kw = {k: v for k, v in (env_kwargs or {}).items() if k not in ("physics_batching",)}
    p = core.make_params(resolve_task(task), terrain=terrain, normalize_action=True, **kw)
    obs = spaces.Box(np.asarray(p.obs_low), np.asarray(p.obs_high), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, (2,), np.float32)
    return obs, act


def _same_box(a, b) -> bool:
    return (getattr(a, "shape", None) == getattr(b, "shape", None) and type(a).__name__ == type(b).__name__
            and np.allclose(np.asarray(a.low, np.float64), np.asarray(b.low, np.float64))
            and np.allclose(np.asarray(a.high, np.float64), np.asarray(b.high, np.float64)))


def load_policy(path: str | Path, task: str, terrain: str = "dry_sand", *, env=None, algo: str | None = None,
                warn: bool = True):
    """Load an SB3 policy zip for ``task``; warn that it is a pickle; check its spaces.

    ``algo`` (ppo/sac) is read from the zip when not given. Raises :class:`PolicySpaceError` when
    the zip's observation or action space differs from the environment's, ``FileNotFoundError`` for a
    missing file and ``ConfigError`` for a file that is not an SB3 zip.
    """
    import zipfile  # noqa: PLC0415

    path = Path(path)
    task = resolve_task(task)
    if not path.is_file():
        raise FileNotFoundError(f"policy not found: {path}")
    if warn:
        warnings.warn(f"{path}: {PICKLE_WARNING}", PickleWarning, stacklevel=2)
        print(f"warning: {path}: {PICKLE_WARNING}", file=sys.stderr)
    if not zipfile.is_zipfile(path):
        raise ConfigError(f"{path}: not a Stable-Baselines3 zip")
    if algo is None:
        algo = _algo_of_zip(path)
    cls = algo_class(algo)
    from stable_baselines3.common.save_util import load_from_zip_file  # noqa: PLC0415

    data, _, _ = load_from_zip_file(path, device="cpu", load_data=True)
    obs_space, act_space = (env.observation_space, env.action_space) if env is not None else expected_spaces(task, terrain)
    zobs, zact = data.get("observation_space"), data.get("action_space")
    if zobs is None or not _same_box(zobs, obs_space):
        raise PolicySpaceError(f"{path}: the policy's observation space {zobs} does not match {ENV_NAME[task]}'s "
                               f"{obs_space} (a policy for another task?)")
    if zact is None or not _same_box(zact, act_space):
        raise PolicySpaceError(f"{path}: the policy's action space {zact} does not match the expected normalised "
                               f"{act_space}")
    return cls.load(str(path), env=env, device="cpu")


def _algo_of_zip(path: Path) -> str:
    """'ppo' or 'sac' from the zip's stored class (the policy class name)."""
    import zipfile  # noqa: PLC0415

    with zipfile.ZipFile(path) as z:
        try:
            data = json.loads(z.read("data").decode("utf-8"))
        except (KeyError, ValueError):
            raise ConfigError(f"{path}: not a Stable-Baselines3 zip (no 'data' entry)") from None
    text = json.dumps(data.get("policy_class", "")) + json.dumps(data.get("policy_kwargs", ""))
    if "sac" in text.lower() and "ActorCritic" not in text:
        return "sac"
    if "ActorCritic" in text:
        return "ppo"
    raise ConfigError(f"{path}: cannot tell the algorithm of this zip; pass algo='ppo' or 'sac'")
