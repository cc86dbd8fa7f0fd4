"""The four maneuver tasks of the thesis (Fig. 4.9, §5.3)."""

from .base import FOOTPRINT_LENGTH, FOOTPRINT_WIDTH, RewardParams, Task, TaskEval, reward_params
from .go_stop import GoStop
from .j_turn import JTurn
from .lane_change import LaneChange
from .zero_radius_turn import ZeroRadiusTurn

TASKS = {"go_stop": GoStop, "j_turn": JTurn, "lane_change": LaneChange, "zero_radius_turn": ZeroRadiusTurn}

__all__ = ["TASKS", "Task", "TaskEval", "RewardParams", "reward_params", "GoStop", "JTurn", "LaneChange",
           "ZeroRadiusTurn", "FOOTPRINT_LENGTH", "FOOTPRINT_WIDTH"]
