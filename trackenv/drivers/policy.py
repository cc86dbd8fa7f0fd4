"""Loading SB3 policy zips, checked against the environment's spaces, and a policy as a batch driver.

Loading a policy (:func:`load_policy`) warns that SB3 zips are pickles that can run code and must come
from trusted sources, and checks its observation and action spaces against the environment's.
"""

from __future__ import annotations

import json
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np

from ..envs.controllers import DEFAULT_GAINS, classical_for
from ..envs.tasks import task_class
from ..params import ConfigError
from .config import algo_class

PICKLE_WARNING = ("SB3 policy zips are pickles and can run arbitrary code when loaded: load only policies "
                  "from trusted sources")


class PolicySpaceError(ValueError):
    """A policy zip was trained for another observation or action space than the environment's."""


class PickleWarning(UserWarning):
    """Loading an SB3 zip unpickles it (it can run code)."""


def expected_spaces(task: str, terrain: str = "dry_sand", env_kwargs: dict | None = None):
    """(observation space, action space) of the SB3 env for ``task`` (normalised actions)."""
    from gymnasium import spaces  # noqa: PLC0415

    from ..envs import core  # noqa: PLC0415

    kw = {k: v for k, v in (env_kwargs or {}).items() if k not in ("physics_batching",)}
    p = core.make_params(task_class(task).name, terrain=terrain, normalize_action=True, **kw)
    obs = spaces.Box(np.asarray(p.obs_low), np.asarray(p.obs_high), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, (2,), np.float32)
    return obs, act


def same_box(a, b) -> bool:
    """Two ``Box`` spaces with the same shape and bounds."""
    return (getattr(a, "shape", None) == getattr(b, "shape", None) and type(a).__name__ == type(b).__name__
            and np.allclose(np.asarray(a.low, np.float64), np.asarray(b.low, np.float64))
            and np.allclose(np.asarray(a.high, np.float64), np.asarray(b.high, np.float64)))


def check_observation_space(model, params) -> None:
    """:class:`PolicySpaceError` when ``model``'s observation space is not the env's (``EnvParams``)."""
    from gymnasium import spaces  # noqa: PLC0415

    want = spaces.Box(np.asarray(params.obs_low), np.asarray(params.obs_high), dtype=np.float32)
    if not same_box(model.observation_space, want):
        raise PolicySpaceError(f"the policy's observation space {model.observation_space} does not match "
                               f"{type(params.task).env_name}'s {want}")


def load_policy(path: str | Path, task: str, terrain: str = "dry_sand", *, env=None, algo: str | None = None,
                warn: bool = True, overrides: dict | None = None):
    """Load an SB3 policy zip for ``task``; warn that it is a pickle; check its spaces.

    ``algo`` (ppo/sac) is read from the zip when not given; ``overrides``: attributes of the model to
    change as it loads (SB3's ``load`` keywords, e.g. ``learning_rate``). Raises :class:`PolicySpaceError` when
    the zip's observation or action space differs from the environment's, ``FileNotFoundError`` for a
    missing file and ``ConfigError`` for a file that is not an SB3 zip.
    """
    path = Path(path)
    cls_task = task_class(task)
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
    obs_space, act_space = (env.observation_space, env.action_space) if env is not None else expected_spaces(
        cls_task.name, terrain)
    zobs, zact = data.get("observation_space"), data.get("action_space")
    if zobs is None or not same_box(zobs, obs_space):
        raise PolicySpaceError(f"{path}: the policy's observation space {zobs} does not match {cls_task.env_name}'s "
                               f"{obs_space} (a policy for another task?)")
    if zact is None or not same_box(zact, act_space):
        raise PolicySpaceError(f"{path}: the policy's action space {zact} does not match the expected normalised "
                               f"{act_space}")
    return cls.load(str(path), env=env, device="cpu", **(overrides or {}))


def _algo_of_zip(path: Path) -> str:
    """'ppo' or 'sac' from the zip's stored class (the policy class name)."""
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


class Learned:
    """An SB3 policy as a batch driver (deterministic actions).

    A residual driver (trained with ``residual: r`` in its config; the zip stores ``trackenv_driver``
    with r and the PI gains) applies clip(classical(obs) + r * policy(obs), -1, 1) with ``params``'s
    classical controller.
    """

    def __init__(self, model, params=None):
        self.model = model
        meta = getattr(model, "trackenv_driver", None) or {}
        self.scale = float(meta.get("residual", 0.0) or 0.0)
        self.ctrl = None
        if self.scale > 0:
            if params is None:
                raise ValueError("a residual driver needs the environment's params for its classical part")
            self.ctrl = classical_for(params, meta.get("gains") or DEFAULT_GAINS)

    def reset(self):
        if self.ctrl is not None:
            self.ctrl.reset()

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        a, _ = self.model.predict(obs, deterministic=True)
        a = np.asarray(a, np.float32)
        if self.ctrl is not None:
            a = np.clip(self.ctrl(obs) + self.scale * a, -1.0, 1.0)
        return a.astype(np.float32)
