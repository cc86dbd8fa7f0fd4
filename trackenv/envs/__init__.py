"""Gymnasium environments of the PackBot maneuvers (thesis Fig. 4.9, §5.3).

Importing this package (or ``trackenv``) registers::

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

ENV_IDS = {
    "trackenv/GoStop-v0": "GoStopEnv",
    "trackenv/JTurn-v0": "JTurnEnv",
    "trackenv/LaneChange-v0": "LaneChangeEnv",
    "trackenv/ZeroRadiusTurn-v0": "ZeroRadiusTurnEnv",
}
TASK_OF_ID = {
    "trackenv/GoStop-v0": "go_stop",
    "trackenv/JTurn-v0": "j_turn",
    "trackenv/LaneChange-v0": "lane_change",
    "trackenv/ZeroRadiusTurn-v0": "zero_radius_turn",
}


def _register() -> None:
    for env_id, cls in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=f"trackenv.envs.gym_env:{cls}",
            vector_entry_point=f"trackenv.envs.vector:{cls.replace('Env', 'VectorEnv')}",
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
