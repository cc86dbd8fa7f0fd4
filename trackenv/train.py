"""Training names under ``trackenv.train``: re-exports of :mod:`trackenv.drivers` (configs, training, loading).

The code lives in :mod:`trackenv.drivers.config`, :mod:`trackenv.drivers.train` and
:mod:`trackenv.drivers.policy`; this module keeps ``from trackenv import train as tr`` working.
"""

from .drivers import *  # noqa: F403
from .drivers import __all__ as _drivers_all
from .drivers.wrappers import ErrorPenalty, ResidualVecEnv, StepTimer

__all__ = [*_drivers_all, "ErrorPenalty", "ResidualVecEnv", "StepTimer"]
