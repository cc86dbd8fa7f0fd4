"""Training of the Stable-Baselines3 drivers.

    trackenv train j_turn --terrain dry_sand --algo ppo --seed 0          # configs/train/ppo.yaml
    trackenv train JTurn-v0 --terrain asphalt --algo sac --timesteps 20000 --out out/train/jt
    trackenv train j_turn --terrain dry_sand --algo ppo --resume          # from the latest checkpoint
    trackenv train j_turn --config configs/train/ppo_plain_polish.yaml --init out/stage1/JTurn-v0-dry_sand.zip \
        --out train/drivers/plain                                         # continue a trained driver

    from trackenv.drivers import load_config, train, load_policy
    cfg = load_config("ppo", "j_turn")                 # validated dict (RL Zoo style, trackenv.drivers.config)
    result = train("j_turn", "dry_sand", "ppo", seed=0, out_dir="out/train/jt")
    model = load_policy(result.model_path, "j_turn", "dry_sand")   # warns: SB3 zips are pickles

Training runs on :class:`~trackenv.envs.vector.SB3VecEnv` (actions normalised to [-1, 1] times the
vehicle's voltage limit) wrapped in ``VecMonitor`` and a step timer that measures the share of wall
time spent stepping the environment (:mod:`trackenv.drivers.wrappers`). Outputs of a run (``out_dir``):

- ``<EnvName>-<terrain>.zip``: the final policy (SB3 zip);
- ``<EnvName>-<terrain>.json``: task, terrain, algorithm, seed, the resolved config, timesteps, wall
  time [s], time in env.step / env.reset [s], the command that reproduces it, library versions; paths
  inside the repository are written relative to it. A run started with ``--init`` also records the
  driver it continued (``init_from``, ``init_record``) and the totals over both (``total_train_seconds``,
  ``total_timesteps``);
- ``<EnvName>-<terrain>.curve.csv`` / ``.curve.png``: the learning curve (:mod:`trackenv.drivers.curves`);
- ``checkpoints/``: ``rl_model_<steps>_steps.zip`` every ``checkpoint_freq`` steps (``--resume``
  continues from the latest one, the step counter included);
- ``tb/``: TensorBoard logs (when ``tensorboard`` is installed).
"""

from __future__ import annotations

import json
import re
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..envs.tasks import task_class
from ..params import ConfigError, is_integer
from .config import (
    ROOT,
    algo_class,
    algo_kwargs,
    check_budget,
    config_path,
    driver_name,
    load_config,
    policy_kwargs,
    repo_relative,
    resolve_algo,
    resolve_task,
    resolve_terrain,
)
from .curves import LearningCurve, _BaseCallback, curve_figure, read_curve, write_curve
from .policy import load_policy
from .wrappers import ActionRatePenalty, ErrorPenalty, GuideSchedule, ResidualVecEnv, StepTimer


def make_vec_env(task: str, terrain: str, n_envs: int, env_kwargs: dict | None = None, seed: int | None = None,
                 residual: dict | None = None, error_weight: float = 0.0, speed_error_weight: float = 0.0,
                 action_rate_weight: float = 0.0):
    """The SB3 training env: ``SB3VecEnv`` (normalised actions) in a step timer and ``VecMonitor``;
    with ``residual`` (``{"scale": r, "gains": {...}}``, optionally ``"classical_weight"`` and ``"release_stop"``)
    the policy's action is added to the classical controller's (:class:`~trackenv.drivers.wrappers.ResidualVecEnv`);
    with ``error_weight`` > 0 the reward is shaped on the task's primary tracking error, with
    ``speed_error_weight`` > 0 also on its speed error (:class:`~trackenv.drivers.wrappers.ErrorPenalty`), with
    ``action_rate_weight`` > 0 on the change of the policy's action (:class:`~trackenv.drivers.wrappers.ActionRatePenalty`).
    Returns the env, the step timer and the ``ResidualVecEnv`` (None without ``residual``)."""
    from stable_baselines3.common.vec_env import VecMonitor  # noqa: PLC0415

    from ..envs.vector import SB3VecEnv  # noqa: PLC0415

    venv = SB3VecEnv(task=resolve_task(task), num_envs=int(n_envs), normalize_action=True, terrain=terrain,
                     **(env_kwargs or {}))
    timer = StepTimer(venv)
    inner = (ResidualVecEnv(timer, residual["scale"], residual["gains"], residual.get("classical_weight", 1.0),
                            release_column=(venv.venv.obs_names.index("phase_stop") if residual.get("release_stop")
                                            else None))
             if residual else timer)
    mon = VecMonitor(inner, info_keywords=("is_success", "tracking_rmse"))
    if error_weight > 0:
        pe = task_class(task).primary_error  # its TaskEval.error (the RMSE metric) and its kernel scale
        mon = ErrorPenalty(mon, venv.venv.obs_names.index(pe.obs_name), pe.scale, error_weight)
    if speed_error_weight > 0:
        cls = task_class(task)
        if "speed_error" not in venv.venv.obs_names:
            raise ConfigError(f"speed_error_weight: task {cls.name} has no speed_error observation "
                              f"(observations: {', '.join(venv.venv.obs_names)})")
        mon = ErrorPenalty(mon, venv.venv.obs_names.index("speed_error"), cls.kernel_scales["speed_error"],
                           speed_error_weight)
    if action_rate_weight > 0:
        mon = ActionRatePenalty(mon, action_rate_weight)
    if seed is not None:
        mon.seed(int(seed))
    return mon, timer, (inner if residual else None)


def imitate_classical(model, venv, guided: ResidualVecEnv, steps: int, epochs: int = 20) -> dict:
    """Behaviour-cloning warm start of a plain policy: drive ``steps`` environment steps with the classical
    controller alone (``guided.classical_weight`` 1, zero policy action), then fit the policy's mean action
    to the controller's (clipped to [-1, 1]) and its value to the discounted (shaped) returns of those
    episodes, by Adam on the mean squared errors. The environment is left plain (weight 0). Returns the
    final losses."""
    import torch  # noqa: PLC0415

    n = venv.num_envs
    guided.classical_weight = 1.0
    obs = venv.reset()
    xs, ys, rs, ds = [], [], [], []
    zero = np.zeros((n, 2), np.float32)
    for _ in range(-(-int(steps) // n)):
        xs.append(obs)
        obs, r, done, _ = venv.step(zero)
        ys.append(np.clip(guided.last_classical, -1.0, 1.0))
        rs.append(r)
        ds.append(done)
    guided.classical_weight = 0.0
    g, rets = np.zeros(n), []
    for r, d in zip(reversed(rs), reversed(ds), strict=True):  # episodes cut by the collection end: no bootstrap
        g = r + model.gamma * g * (1.0 - d)
        rets.append(g.copy())
    x = torch.as_tensor(np.concatenate(xs), dtype=torch.float32)
    y = torch.as_tensor(np.concatenate(ys), dtype=torch.float32)
    ret = torch.as_tensor(np.concatenate(rets[::-1]), dtype=torch.float32)
    scale = float(ret.std()) + 1e-6
    pol = model.policy
    opt = torch.optim.Adam(pol.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(int(model.seed or 0))
    for _ in range(int(epochs)):
        for idx in torch.randperm(len(x), generator=gen).split(1024):
            mean = pol.get_distribution(x[idx]).distribution.mean
            v = pol.predict_values(x[idx]).squeeze(-1)
            a_loss = torch.mean((mean - y[idx]) ** 2)
            v_loss = torch.mean(((v - ret[idx]) / scale) ** 2)
            opt.zero_grad()
            (a_loss + v_loss).backward()
            opt.step()
    return {"samples": len(x), "action_mse": float(a_loss.detach()), "value_mse_scaled": float(v_loss.detach())}


class _GuideCallback(_BaseCallback):
    """Sets a :class:`~trackenv.drivers.wrappers.GuideSchedule`'s weight from SB3's step count before
    every environment step."""

    def __init__(self, schedule: GuideSchedule):
        super().__init__()
        self.schedule = schedule

    def _on_training_start(self) -> None:
        self.schedule(self.model.num_timesteps)

    def _on_step(self) -> bool:
        self.schedule(self.model.num_timesteps)
        return True


@dataclass
class TrainResult:
    """What :func:`train` wrote: the policy zip, its JSON record, and the record's content."""

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


def _optional_outputs(run: Path, tensorboard: bool, progress_bar: bool) -> tuple[str | None, bool]:
    """The TensorBoard folder (None without tensorboard) and whether a progress bar can be shown."""
    tb = None
    if tensorboard:
        try:
            import tensorboard as _tb  # noqa: F401,PLC0415

            tb = str(run / "tb")
        except ImportError:
            warnings.warn("tensorboard is not installed: no TensorBoard logs", stacklevel=3)
    if progress_bar:
        try:
            import rich  # noqa: F401,PLC0415
            import tqdm  # noqa: F401,PLC0415
        except ImportError:
            warnings.warn("tqdm/rich not installed: no progress bar", stacklevel=3)
            progress_bar = False
    return tb, progress_bar


def train(task: str, terrain: str = "dry_sand", algo: str = "ppo", *, config: str | Path | dict | None = None,
          seed: int = 0, timesteps: int | None = None, out_dir: str | Path | None = None,
          run_dir: str | Path | None = None, resume: bool = False,
          progress_bar: bool = True, tensorboard: bool = True, verbose: int = 0, threads: int = 1,
          command: str | None = None, randomize: bool = False, grounds: list[str] | tuple[str, ...] | None = None,
          init: str | Path | None = None) -> TrainResult:
    """Train a driver and save ``<out_dir>/<EnvName>-<terrain>.zip`` plus its ``.json`` record.

    ``randomize``: domain-randomised training, every episode on parameters drawn from the default ranges
    of ``terrain`` (:mod:`trackenv.envs.randomization`; sets ``env_kwargs.domain_randomization`` unless
    the config sets it); the driver is named ``<EnvName>-<terrain>-randomized``. ``grounds`` (with
    ``randomize``): a ground mixture instead, every episode on one of these terrains drawn first, then
    within its default ranges (``domain_randomization={"grounds": [...]}``); ``terrain`` still names the
    driver, its classical gains and its open-loop profile.

    ``init``: a trained driver's zip to start from instead of a fresh policy (RL Zoo's ``--trained-agent``):
    its weights, with this config's hyperparameters (``learning_rate`` ...), trained for ``n_timesteps``
    more steps; it must be a driver of the same kind (residual or plain) and is never overwritten.

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
        if not (is_integer(timesteps) and timesteps >= 1):
            raise ConfigError(f"timesteps must be a positive integer, got {timesteps!r}")
        cfg["n_timesteps"] = int(timesteps)
    check_budget(cfg, algo, where="--timesteps" if timesteps is not None else "n_timesteps")
    if grounds is not None and not randomize:
        raise ConfigError("grounds: a ground mixture is a domain randomisation; pass randomize=True (--randomize)")
    if grounds is not None and "domain_randomization" in cfg["env_kwargs"]:
        raise ConfigError("grounds: the config's env_kwargs already set domain_randomization; a ground mixture "
                          "would be ignored")
    if randomize:
        cfg["env_kwargs"] = {**cfg["env_kwargs"]}
        cfg["env_kwargs"].setdefault("domain_randomization",
                                     True if grounds is None else {"grounds": [resolve_terrain(g) for g in grounds]})
    name = driver_name(task, terrain, randomized=randomize)
    out = Path(out_dir) if out_dir is not None else ROOT / "out" / "train" / f"{name}-{algo}-s{seed}"
    run = Path(run_dir) if run_dir is not None else out
    ckpt = latest_checkpoint(run) if resume else None
    if resume and ckpt is None:
        raise ConfigError(f"--resume: no checkpoint in {run / 'checkpoints'}")
    if init is not None:
        init = Path(init)
        if resume:
            raise ConfigError("--init starts a new run from a trained driver; --resume continues a run: not both")
        if not init.is_file():
            raise ConfigError(f"--init: no driver zip at {init}")
        if init.resolve() == (out / f"{name}.zip").resolve():
            raise ConfigError(f"--init: {init} is this run's output; train into another --out (the input is "
                              "never overwritten)")

    import torch  # noqa: PLC0415
    from stable_baselines3.common.callbacks import CheckpointCallback  # noqa: PLC0415

    torch.set_num_threads(int(threads))
    out.mkdir(parents=True, exist_ok=True)
    run.mkdir(parents=True, exist_ok=True)
    driver_meta = {"task": task, "terrain": terrain, "residual": cfg["residual"],
                   "domain_randomization": cfg["env_kwargs"].get("domain_randomization", False)}
    if cfg["residual"] > 0 or cfg["guide"] > 0 or cfg["imitate"] > 0:
        from ..envs.controllers import load_gains  # noqa: PLC0415

        gains = load_gains(task, terrain)
    residual = None
    if cfg["residual"] > 0:
        driver_meta["gains"] = gains
        residual = {"scale": cfg["residual"], "gains": gains}
    elif cfg["guide"] > 0:  # a plain driver's curriculum: the classical part fades out during training
        driver_meta["guide"] = {"fraction": cfg["guide"], "gains": gains, "release_stop": cfg["guide_release_stop"]}
        residual = {"scale": 1.0, "gains": gains, "classical_weight": 1.0, "release_stop": cfg["guide_release_stop"]}
    elif cfg["imitate"] > 0:  # a plain driver's warm start from the classical controller's episodes
        driver_meta["imitate"] = {"steps": cfg["imitate"], "gains": gains}
        residual = {"scale": 1.0, "gains": gains, "classical_weight": 0.0}
    venv, timer, guided = make_vec_env(task, terrain, cfg["n_envs"], cfg["env_kwargs"], seed, residual,
                                       cfg["error_weight"], cfg["speed_error_weight"], cfg["action_rate_weight"])
    guide_steps = round(cfg["guide"] * cfg["n_timesteps"]) if cfg["guide"] > 0 else None
    callbacks = [_GuideCallback(GuideSchedule(guided, guide_steps))] if guide_steps else []
    tb, progress_bar = _optional_outputs(run, tensorboard, progress_bar)
    previous = {}
    if ckpt is not None:
        model = load_policy(ckpt, task, terrain, env=venv, algo=algo, warn=False)
        model.tensorboard_log = tb
        info_path = run / "progress.json"
        if info_path.is_file():
            previous = json.loads(info_path.read_text())
    elif init is not None:
        model = load_policy(init, task, terrain, env=venv, algo=algo, warn=False,
                            overrides={**algo_kwargs(cfg), "tensorboard_log": tb, "verbose": verbose})
        model.set_random_seed(int(seed))
        was = float((getattr(model, "trackenv_driver", None) or {}).get("residual", 0.0))
        if was != cfg["residual"]:
            raise ConfigError(f"--init: {init} is a {'residual' if was else 'plain'} driver (residual {was}), the config "
                              f"trains residual {cfg['residual']}")
        driver_meta["init_from"] = repo_relative(init)
    else:
        model = algo_class(algo)(cfg["policy"], venv, policy_kwargs=policy_kwargs(cfg), seed=int(seed), device="cpu",
                                 tensorboard_log=tb, verbose=verbose, **algo_kwargs(cfg))
    imitate_seconds = 0.0  # counted in train_seconds
    if cfg["imitate"] > 0 and ckpt is None and init is None:
        t_bc = time.perf_counter()
        driver_meta["imitate"]["result"] = imitate_classical(model, venv, guided, cfg["imitate"])
        imitate_seconds = driver_meta["imitate"]["result"]["seconds"] = time.perf_counter() - t_bc
    done_before = int(model.num_timesteps) if init is None else 0  # a driver continued with --init: a new run
    remaining = max(0, cfg["n_timesteps"] - done_before)
    checkpoints = CheckpointCallback(save_freq=max(1, cfg["checkpoint_freq"] // cfg["n_envs"]),
                                     save_path=str(run / "checkpoints"), name_prefix="rl_model")
    run_curve = run / "curve.csv"
    curve = LearningCurve(timer, every=0 if algo == "ppo" else max(cfg["n_envs"], cfg["n_timesteps"] // 200),
                          offset=(done_before, float(previous.get("train_seconds", 0.0)),
                                  float(previous.get("env_step_seconds", 0.0))),
                          rows=read_curve(run_curve) if (ckpt is not None and run_curve.is_file()) else None)
    t0 = time.perf_counter()
    model.learn(total_timesteps=remaining, callback=[*callbacks, checkpoints, curve], progress_bar=progress_bar,
                tb_log_name=name, reset_num_timesteps=ckpt is None)
    wall = time.perf_counter() - t0 + imitate_seconds
    model_path = out / f"{name}.zip"
    model.trackenv_driver = driver_meta  # saved in the zip's data; read back by trackenv.drivers.policy.Learned
    model.save(str(model_path))
    ep = list(model.ep_info_buffer)
    env_name = task_class(task).env_name
    info = {
        "driver": name, "task": task, "env_id": task_class(task).env_id, "terrain": terrain, "algo": algo,
        "seed": int(seed), "config": cfg,
        "config_file": None if isinstance(config, dict) else repo_relative(config_path(algo, config)),
        "n_timesteps": int(model.num_timesteps),
        "train_seconds": wall + float(previous.get("train_seconds", 0.0)),
        "env_step_seconds": timer.step_seconds + timer.reset_seconds + float(previous.get("env_step_seconds", 0.0)),
        "resumed_from": repo_relative(ckpt) if ckpt else None, "driver_meta": driver_meta,
        "init_from": repo_relative(init) if init is not None else None,
        "final_mean_return": float(np.mean([e["r"] for e in ep])) if ep else None,
        "final_success_rate": float(np.mean([e.get("is_success", 0.0) for e in ep])) if ep else None,
        "command": command or (f"trackenv train {env_name} --terrain {terrain} --algo {algo} --seed {seed}"
                               + (" --randomize" if randomize else "")
                               + (f" --grounds {','.join(grounds)}" if grounds else "")
                               + (f" --init {repo_relative(init)}" if init is not None else "")),
        "versions": _versions(), "model_bytes": model_path.stat().st_size,
    }
    info["env_step_share"] = info["env_step_seconds"] / max(info["train_seconds"], 1e-9)
    info["total_train_seconds"], info["total_timesteps"] = info["train_seconds"], info["n_timesteps"]
    init_record = init.with_suffix(".json") if init is not None else None
    if init_record is not None and init_record.is_file():  # the driver it continues, and its own stages
        first = json.loads(init_record.read_text())
        info["init_record"] = {k: first.get(k) for k in ("command", "train_seconds", "n_timesteps")}
        info["total_train_seconds"] += float(first.get("total_train_seconds", first.get("train_seconds", 0.0)))
        info["total_timesteps"] += int(first.get("total_timesteps", first.get("n_timesteps", 0)))
    write_curve(curve.rows, run_curve)
    curve_csv = write_curve(curve.rows, out / f"{name}.curve.csv")
    curve_png = curve_figure(curve.rows, f"{name} ({algo}{', guided' if guide_steps else ''}, seed {seed})",
                             out / f"{name}.curve.png", guide_steps=guide_steps)
    info["curve_csv"], info["curve_png"] = repo_relative(curve_csv), repo_relative(curve_png)
    info_path = out / f"{name}.json"
    info_path.write_text(json.dumps(info, indent=2) + "\n")
    (run / "progress.json").write_text(json.dumps(info, indent=2) + "\n")
    venv.close()
    return TrainResult(model_path, info_path, info)
