"""Shared constants of the environment tests."""

ENV_IDS = ["trackenv/GoStop-v0", "trackenv/JTurn-v0", "trackenv/LaneChange-v0", "trackenv/ZeroRadiusTurn-v0"]
TERRAINS = ["dry_sand", "asphalt"]
