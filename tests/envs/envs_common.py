"""Shared constants of the environment tests."""

from trackenv.envs import ENV_IDS as _REGISTERED

ENV_IDS = list(_REGISTERED)  # one per task of trackenv.envs.tasks.TASK_CLASSES
TERRAINS = ["dry_sand", "asphalt"]
