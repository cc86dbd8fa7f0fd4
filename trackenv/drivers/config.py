"""Names and training configs of the SB3 drivers: tasks, terrains, algorithms, RL-Zoo-style YAML.

Configs (``configs/train/<algo>.yaml``) follow the RL Baselines3 Zoo layout: one section per
environment name (one per task of :data:`trackenv.envs.tasks.TASK_CLASSES`: ``GoStop-v0``,
``JTurn-v0`` ...) merged over a ``default`` section; optional ``<EnvName>-<terrain>`` sections
(e.g. ``JTurn-v0-asphalt``) are merged last. Keys of a section:

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
                    units of the vehicle's voltage limit (the gains and r are stored in the zip; see train/README.md)
guide               0 (default) or a fraction f in (0, 1], plain drivers only (``residual: 0``): a guided
                    curriculum, the classical PI controller's voltages times a weight falling linearly
                    from 1 to 0 over the first f x n_timesteps steps are added to the policy's
                    (:class:`~trackenv.drivers.wrappers.GuideSchedule`); the saved driver acts alone
imitate             0 (default) or a number of environment steps, plain drivers only: a behaviour-cloning
                    warm start, the policy's mean action and value fitted to that many steps of the classical
                    controller's episodes before training (:func:`~trackenv.drivers.train.imitate_classical`)
error_weight        w >= 0 (default 0): training reward shaping, r - w (e / s)^2 with e the task's
                    primary tracking error (``Task.primary_error``, the evaluated RMSE's) read from the next
                    observation and s its kernel scale; the environment's reward kernels saturate for large
                    errors, the RMSE does not. VecMonitor (and the reported returns) see the unshaped reward
speed_error_weight  w_v >= 0 (default 0): a second shaping term, r - w_v (e_v / s_v)^2 on the ``speed_error``
                    observation (the tasks that observe one: go-stop, J-turn, lane change; s_v its kernel
                    scale, 0.2 m/s). It makes standing still costly for a plain policy, for which the
                    cross-track penalty alone rewards not driving at all (train/README.md, "Plain PPO")
action_rate_weight  w_a >= 0 (default 0): a shaping term against a chattering command, r - w_a mean_k
                    (a_k - a_k,prev)^2 on the policy's normalised action and the one before it in the
                    episode (:class:`~trackenv.drivers.wrappers.ActionRatePenalty`)
learning_rate       a number, or ``lin_<value>`` (RL Zoo's linear schedule: from ``<value>`` at the start to 0 at
                    ``n_timesteps``; a driver continued with ``--init`` starts the schedule again)
any other key       a keyword of the algorithm's constructor (``learning_rate``, ``n_steps``,
                    ``batch_size``, ``gamma``, ``gae_lambda``, ``ent_coef``, ``clip_range``,
                    ``n_epochs``, ``buffer_size``, ``train_freq``, ...), checked against its signature
==================  ==============================================================================

A file may begin with ``extends: <file>`` (e.g. ``extends: ppo.yaml``): the sections of that config
(in ``configs/train``) are read first and this file's keys override them, nested dicts key by key.

An unknown key, task, terrain or algorithm raises :class:`~trackenv.params.ConfigError` naming the
file and key **before** any environment is built or any training starts.
"""

from __future__ import annotations

import copy
import inspect
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..envs.tasks import ENV_NAMES, task_class
from ..envs.tasks import TASKS as TASK_CLASSES
from ..params import CONFIG_DIR as _CONFIGS
from ..params import ConfigError

ROOT = Path(__file__).resolve().parent.parent.parent  # the repository
CONFIG_DIR = _CONFIGS / "train"
DRIVERS_DIR = ROOT / "train" / "drivers"

TASKS = tuple(TASK_CLASSES)  # task ids, from the task registry
ENV_NAME = ENV_NAMES  # task id -> env name
TERRAINS = ("dry_sand", "asphalt")  # the shipped drivers' terrains; any configs/terrain id trains
ALGOS = ("ppo", "sac")
META_KEYS = ("n_envs", "n_timesteps", "policy", "policy_kwargs", "env_kwargs", "checkpoint_freq", "residual",
             "error_weight", "guide", "guide_release_stop", "speed_error_weight", "action_rate_weight", "imitate")
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu")


# ----------------------------------------------------------------------------------------------
# names


def resolve_task(task: str) -> str:
    """Task id from a task id (``j_turn``), an env name (``JTurn-v0``) or an env id (``trackenv/JTurn-v0``)."""
    return task_class(task).name


def resolve_terrain(terrain: str) -> str:
    """A terrain id of configs/terrain (``dry_sand``, ``asphalt``, ``sandy_loam_1`` ...), checked."""
    known = _terrain_ids()
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


RANDOMIZED_SUFFIX = "-randomized"


def driver_name(task: str, terrain: str, randomized: bool = False) -> str:
    """``<EnvName>-<terrain>``, e.g. ``JTurn-v0-dry_sand`` (the shipped zip's stem); a driver trained with
    domain randomisation ends in ``-randomized`` (``JTurn-v0-dry_sand-randomized``)."""
    return f"{task_class(task).env_name}-{terrain}" + (RANDOMIZED_SUFFIX if randomized else "")


def repo_relative(path: str | Path | None) -> str | None:
    """``path`` relative to the repository when it lies inside it (as written into the JSON records), else as given."""
    if path is None:
        return None
    p = Path(path)
    try:
        return Path(os.path.relpath(p.resolve(), ROOT)).as_posix() if p.resolve().is_relative_to(ROOT) else str(p)
    except (OSError, ValueError):
        return str(p)


def _terrain_ids() -> list[str]:
    from ..params import list_terrains  # noqa: PLC0415

    return list_terrains()


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


def _read_yaml(path: Path):
    if not path.is_file():
        raise ConfigError(f"training config not found: {path}")
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8")), str(path)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: invalid YAML: {exc}") from None


def _extend(raw: dict, where: str, seen: tuple = ()) -> dict:
    """Resolve ``extends: <file>`` (a config of the same layout, relative to ``configs/train``): its sections
    first, then this file's, merged section by section (nested dicts such as ``policy_kwargs`` key by key)."""
    base_name = raw.pop("extends", None)
    if base_name is None:
        return raw
    if not isinstance(base_name, str):
        raise ConfigError(f"{where}: 'extends' must name a config file, got {base_name!r}")
    path = CONFIG_DIR / base_name
    if str(path) in seen:
        raise ConfigError(f"{where}: 'extends' loops back to {path}")
    base, base_where = _read_yaml(path)
    if not isinstance(base, dict):
        raise ConfigError(f"{base_where}: must be a mapping of sections")
    base = _extend(base, base_where, (*seen, str(path)))
    out = copy.deepcopy(base)
    for section, body in raw.items():
        if isinstance(body, dict) and isinstance(out.get(section), dict):
            merged = dict(out[section])
            for k, v in body.items():
                merged[k] = {**merged[k], **v} if isinstance(v, dict) and isinstance(merged.get(k), dict) else v
            out[section] = merged
        else:
            out[section] = body
    return out


def load_config(algo: str, task: str, terrain: str | None = None, config: str | Path | dict | None = None) -> dict:
    """The validated hyperparameters for ``algo`` on ``task`` (and ``terrain``), RL Zoo style.

    ``config``: a YAML path (default ``configs/train/<algo>.yaml``) or a ready dict of the same layout; a
    top-level ``extends: <file>`` starts from another config of ``configs/train`` (see :func:`_extend`).
    Raises :class:`ConfigError` naming the file and the key on any unknown key or bad value.
    """
    algo = resolve_algo(algo)
    env_name = task_class(task).env_name
    if isinstance(config, dict):
        raw, where = copy.deepcopy(config), "config"
    else:
        raw, where = _read_yaml(config_path(algo, config))
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: must be a mapping of sections (default, <EnvName>, <EnvName>-<terrain>)")
    raw = _extend(raw, where)
    allowed = set(META_KEYS) | _allowed_algo_keys(algo)
    names = set(ENV_NAME.values())
    sections = {"default"} | names | {f"{n}-{t}" for n in names for t in _terrain_ids()}
    for key in raw:
        if key not in sections:
            raise ConfigError(f"{where}: unknown section '{key}'; sections are 'default', an env name "
                              f"({', '.join(sorted(names))}) or '<EnvName>-<terrain>'")
        _check_section(raw[key], f"{where} [{key}]", allowed)
    merged: dict = {}
    order = ["default", env_name] + ([f"{env_name}-{terrain}"] if terrain else [])
    for key in order:
        for k, v in (raw.get(key) or {}).items():
            if isinstance(v, dict) and isinstance(merged.get(k), dict):
                merged[k] = {**merged[k], **v}
            else:
                merged[k] = copy.deepcopy(v)
    label = f"{where} [{' + '.join(k for k in order if k in raw)}]"
    cfg = _validate_values(merged, label)
    if cfg["guide_release_stop"] and "phase_stop" not in task_class(task).obs_names:
        raise ConfigError(f"{label}: 'guide_release_stop' needs a phase_stop observation, which {env_name} does not have")
    if cfg["speed_error_weight"] > 0 and "speed_error" not in task_class(task).obs_names:
        raise ConfigError(f"{label}: 'speed_error_weight' needs a speed_error observation, which "
                          f"{env_name} does not have")
    return cfg


def _number(cfg: dict, key: str, lower: float, upper: float, where: str, expected: str,
            upper_open: bool = False) -> None:
    """``cfg[key]`` (default 0) as a float in [lower, upper] (or [lower, upper) with ``upper_open``), in place;
    a ``ConfigError`` saying it must be ``expected`` otherwise."""
    v = cfg.setdefault(key, 0.0)
    ok = (not isinstance(v, bool) and isinstance(v, (int, float))
          and lower <= float(v) and (float(v) < upper if upper_open else float(v) <= upper))
    if not ok:
        raise ConfigError(f"{where}: '{key}' must be {expected}, got {v!r}")
    cfg[key] = float(v)


def _validate_values(cfg: dict, where: str) -> dict:
    cfg = dict(cfg)
    cfg.setdefault("policy", "MlpPolicy")
    cfg.setdefault("n_envs", 64)
    cfg.setdefault("checkpoint_freq", 100_000)
    cfg.setdefault("policy_kwargs", {})
    cfg.setdefault("env_kwargs", {})
    _number(cfg, "residual", 0.0, 2.0, where, "a number in [0, 2] (0: plain policy)")
    _number(cfg, "guide", 0.0, 1.0, where, "a fraction of n_timesteps in [0, 1] (0: off)")
    if cfg["guide"] > 0 and cfg["residual"] > 0:
        raise ConfigError(f"{where}: 'guide' is a plain driver's curriculum and needs 'residual: 0', "
                          f"got residual {cfg['residual']!r}")
    cfg.setdefault("guide_release_stop", False)
    if not isinstance(cfg["guide_release_stop"], bool):
        raise ConfigError(f"{where}: 'guide_release_stop' must be true or false, got {cfg['guide_release_stop']!r}")
    if cfg["guide_release_stop"] and not cfg["guide"] > 0:
        raise ConfigError(f"{where}: 'guide_release_stop' releases the guided curriculum's classical part in the "
                          "stop phase and needs 'guide' > 0")
    _number(cfg, "error_weight", 0.0, 1e3, where, "a non-negative number", upper_open=True)
    cfg.setdefault("imitate", 0)
    m = cfg["imitate"]
    if isinstance(m, float) and m.is_integer():
        m = int(m)
    if isinstance(m, bool) or not isinstance(m, int) or m < 0:
        raise ConfigError(f"{where}: 'imitate' must be a number of environment steps >= 0 (0: off), got {m!r}")
    cfg["imitate"] = m
    if m > 0 and (cfg["residual"] > 0 or cfg["guide"] > 0):
        raise ConfigError(f"{where}: 'imitate' is a plain driver's warm start and needs 'residual: 0' and 'guide: 0'")
    _number(cfg, "speed_error_weight", 0.0, 1e3, where, "a non-negative number", upper_open=True)
    _number(cfg, "action_rate_weight", 0.0, 1e3, where, "a non-negative number", upper_open=True)
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
        if k == "learning_rate" and isinstance(cfg.get(k), str):
            if linear_schedule_start(cfg[k]) is None:
                raise ConfigError(f"{where}: 'learning_rate' must be a non-negative number or 'lin_<number>' "
                                  f"(a linear schedule to 0), got {cfg[k]!r}")
            continue
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


def linear_schedule_start(spec: str) -> float | None:
    """The start value of an RL-Zoo linear schedule ``"lin_<value>"``, or None if ``spec`` is not one."""
    if not spec.startswith("lin_"):
        return None
    try:
        value = float(spec[4:])
    except ValueError:
        return None
    return value if np.isfinite(value) and value >= 0 else None


class LinearSchedule:
    """SB3 schedule falling linearly from ``start`` (progress remaining 1) to 0 (progress remaining 0).

    RL Zoo's ``linear_schedule`` (``progress_remaining * initial_value``, the meaning of ``lin_`` in its
    configs) as a picklable class. SB3's own ``LinearSchedule(start, 0, 1)`` computes
    ``start + (1 - p) * (0 - start)``, which rounds differently, and a shipped driver is reproduced only by
    the arithmetic it was trained with."""

    def __init__(self, start: float):
        self.start = float(start)

    def __call__(self, progress_remaining: float) -> float:
        return progress_remaining * self.start

    def __repr__(self) -> str:
        return f"lin_{self.start}"


def algo_kwargs(cfg: dict) -> dict:
    """The algorithm's constructor keywords of a config (everything but the META_KEYS); a
    ``learning_rate`` of ``lin_<value>`` becomes a :class:`LinearSchedule`."""
    out = {k: v for k, v in cfg.items() if k not in META_KEYS}
    if isinstance(out.get("learning_rate"), str):
        out["learning_rate"] = LinearSchedule(linear_schedule_start(out["learning_rate"]))
    return out


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
