"""The four maneuver tasks of the thesis (Fig. 4.9, §5.3) and their registry.

:data:`TASK_CLASSES` is the one list of the tasks: the Gymnasium registration
(:mod:`trackenv.envs`), the env classes (:mod:`trackenv.envs.gym_env`, :mod:`trackenv.envs.vector`),
the controllers and the training and evaluation names all derive from it and from the class
variables of each task (:class:`~trackenv.envs.tasks.base.Task`).
"""

from __future__ import annotations

from ...params import ConfigError
from .base import FOOTPRINT_LENGTH, FOOTPRINT_WIDTH, PrimaryError, RewardParams, Task, TaskEval, reward_params
from .go_stop import GoStop
from .j_turn import JTurn
from .lane_change import LaneChange
from .zero_radius_turn import ZeroRadiusTurn

TASK_CLASSES: tuple[type[Task], ...] = (GoStop, JTurn, LaneChange, ZeroRadiusTurn)
TASKS: dict[str, type[Task]] = {cls.name: cls for cls in TASK_CLASSES}  # task id -> class
ENV_NAMES: dict[str, str] = {cls.name: cls.env_name for cls in TASK_CLASSES}  # task id -> env name
MANEUVERS: tuple[str, ...] = tuple(cls.field_profile for cls in TASK_CLASSES)  # maneuver names of configs/field


def task_class(task: str | type[Task]) -> type[Task]:
    """The task class of a task id (``j_turn``), an env name (``JTurn-v0``), an env id
    (``trackenv/JTurn-v0``) or a task class; :class:`~trackenv.params.ConfigError` (a ``ValueError``)
    for anything else, listing the known names."""
    if isinstance(task, type) and issubclass(task, Task):
        return task
    name = str(task).split("/")[-1]
    for cls in TASK_CLASSES:
        if name in (cls.name, cls.env_name):
            return cls
    raise ConfigError(f"unknown task {task!r}; known: {', '.join(TASKS)} or {', '.join(ENV_NAMES.values())}")


__all__ = ["TASK_CLASSES", "TASKS", "ENV_NAMES", "MANEUVERS", "task_class", "Task", "TaskEval", "PrimaryError", "RewardParams",
           "reward_params", "GoStop", "JTurn", "LaneChange", "ZeroRadiusTurn", "FOOTPRINT_LENGTH", "FOOTPRINT_WIDTH"]
