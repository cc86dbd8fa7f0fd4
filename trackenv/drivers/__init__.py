"""Stable-Baselines3 drivers of the tasks: configs, wrappers, training, evaluation episodes, figures, tuning.

One module per job (imports run one way, config <- policy <- train / episodes <- tune):

=======================  =====================================================================
:mod:`.config`           task / terrain / algorithm names and the RL-Zoo-style training YAML
:mod:`.policy`           loading SB3 zips (pickle warning, space checks); a policy as a batch driver
:mod:`.wrappers`         step timer, residual PI driver, error shaping (SB3); episode recorder
:mod:`.train`            ``train``: one driver, its zip and JSON record
:mod:`.episodes`         ``evaluate``: learned vs open loop vs classical on the same seeds; tables,
                         JSON, synthetic field logs
:mod:`.figures`          trajectory, voltage and trace figures of an evaluation
:mod:`.tune`             grid search of the PI gains (``python -m trackenv.drivers.tune``)
=======================  =====================================================================

The controllers themselves (PI, open loop, scripted) live in :mod:`trackenv.envs.controllers`.
"""

from __future__ import annotations

from .config import (
    ALGOS,
    DRIVERS_DIR,
    ENV_NAME,
    ROOT,
    TASKS,
    TERRAINS,
    check_budget,
    driver_name,
    load_config,
    resolve_algo,
    resolve_task,
    resolve_terrain,
)
from .episodes import METHODS, evaluate, evaluate_cli, format_table, make_eval_env, run_episodes, summarize
from .policy import Learned, PickleWarning, PolicySpaceError, expected_spaces, load_policy
from .train import TrainResult, latest_checkpoint, make_vec_env, train

__all__ = ["ALGOS", "DRIVERS_DIR", "ENV_NAME", "ROOT", "TASKS", "TERRAINS", "check_budget", "driver_name",
           "load_config", "resolve_algo", "resolve_task", "resolve_terrain", "METHODS", "evaluate", "evaluate_cli",
           "format_table", "make_eval_env", "run_episodes", "summarize", "Learned", "PickleWarning",
           "PolicySpaceError", "expected_spaces", "load_policy", "TrainResult", "latest_checkpoint", "make_vec_env",
           "train"]
