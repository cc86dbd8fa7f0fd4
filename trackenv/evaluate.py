"""Evaluation names under ``trackenv.evaluate``: re-exports of :mod:`trackenv.drivers` and the controllers.

The code lives in :mod:`trackenv.drivers.episodes` (episodes, metrics, tables, field logs),
:mod:`trackenv.drivers.figures`, :mod:`trackenv.drivers.tune` and :mod:`trackenv.envs.controllers`;
this module keeps ``from trackenv import evaluate as ev`` working.
"""

from .drivers import *  # noqa: F403
from .drivers import __all__ as _drivers_all
from .drivers.episodes import METRICS, write_json, write_logs
from .envs.controllers import ClassicalController, OpenLoop, classical_for, load_gains

__all__ = [*_drivers_all, "METRICS", "write_json", "write_logs", "ClassicalController", "OpenLoop", "classical_for",
           "load_gains"]
