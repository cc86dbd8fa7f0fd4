"""Gymnasium environments of the PackBot maneuvers (thesis Fig. 4.9, §5.3).

Importing this package (or ``trackenv``) registers one environment per task of
:data:`trackenv.envs.tasks.TASK_CLASSES`::

    trackenv/GoStop-v0          go-stop: reach and hold a speed, stop at a mark
    trackenv/JTurn-v0           J-turn: straight run, turn through a heading change, stop
    trackenv/LaneChange-v0      double lane change through PackBot-scale gates
    trackenv/ZeroRadiusTurn-v0  zero-radius turn: spin in place at a yaw rate through an angle

    env = gym.make("trackenv/GoStop-v0", terrain="asphalt", control_dt=0.05)
    venv = gym.make_vec("trackenv/GoStop-v0", num_envs=1024)      # native batched VectorEnv
    sb3 = trackenv.envs.SB3VecEnv("trackenv/GoStop-v0", num_envs=64, normalize_action=True)

Layers: :mod:`.core` (pure ``reset``/``step`` on pytrees, jit/vmap-able), :mod:`.tasks` (targets,
observations, rewards, terminations), :mod:`.gym_env` (``gymnasium.Env``), :mod:`.vector`
(``gymnasium.vector.VectorEnv`` and the Stable-Baselines3 ``VecEnv`` adapter), :mod:`.render`.
"""

from __future__ import annotations

import gymnasium as gym

from . import core
from .core import EnvParams, EnvState, StepResult, make_params, reset, step, step_autoreset
from .tasks import TASK_CLASSES

# Derived from the task registry (trackenv.envs.tasks.TASK_CLASSES): env id -> env class name in
# trackenv.envs.gym_env (the vector class is the same name with VectorEnv), and env id -> task id.
ENV_IDS = {cls.env_id: f"{cls.__name__}Env" for cls in TASK_CLASSES}
TASK_OF_ID = {cls.env_id: cls.name for cls in TASK_CLASSES}


def _register() -> None:
    for cls in TASK_CLASSES:
        if cls.env_id in gym.registry:
            continue
        gym.register(
            id=cls.env_id,
            entry_point=f"trackenv.envs.gym_env:{cls.__name__}Env",
            vector_entry_point=f"trackenv.envs.vector:{cls.__name__}VectorEnv",
            disable_env_checker=False,
        )


_register()


def __getattr__(name):  # lazy: the vector module imports stable-baselines3 only when asked
    if name in ("TrackVectorEnv", "SB3VecEnv"):
        from . import vector  # noqa: PLC0415

        return getattr(vector, name)
    if name == "TrackEnv":
        from .gym_env import TrackEnv  # noqa: PLC0415

        return TrackEnv
    raise AttributeError(name)


__all__ = ["ENV_IDS", "TASK_OF_ID", "EnvParams", "EnvState", "StepResult", "make_params", "reset", "step",
           "step_autoreset", "core", "TrackEnv", "TrackVectorEnv", "SB3VecEnv"]
