"""trackenv: a fast, verified JAX simulator of the iRobot PackBot tracked vehicle on flat terrain.

Public API (see README):
    load_params, replace, list_terrains  -- parameters as immutable pytrees (configs/)
    VoltageProfile, SpeedProfile, simulate, Trajectory -- trajectories and instrument channels
    SimulationDiverged                   -- raised when a simulation goes non-finite
    enable_compilation_cache             -- reuse compiled programs across processes (compile_cache.py)
"""

from .parallel import configure_host_devices, configure_small_loops

configure_host_devices()  # one XLA CPU device per core for split batches, before JAX starts (parallel.py)
configure_small_loops()  # small loops (one vehicle's substeps) as one XLA kernel, before JAX starts (parallel.py)

from .compile_cache import enable_compilation_cache
from .params import ConfigError, Params, list_terrains, list_vehicles, load_params, replace
from .physics.model import State, initial_state
from .simulate import SimulationDiverged, SpeedProfile, Trajectory, VoltageProfile, simulate

__all__ = [
    "ConfigError", "Params", "load_params", "list_terrains", "list_vehicles", "replace",
    "State", "initial_state", "SimulationDiverged", "SpeedProfile", "Trajectory", "VoltageProfile", "simulate",
    "enable_compilation_cache",
]
__version__ = "0.1.0"

try:  # registers trackenv/GoStop-v0, JTurn-v0, LaneChange-v0, ZeroRadiusTurn-v0 with Gymnasium
    from . import envs  # noqa: E402,F401
except ImportError:  # pragma: no cover - gymnasium missing: the simulator still works
    pass
