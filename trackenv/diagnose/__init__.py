"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it, how far
it shrinks once that effect is added.

    from trackenv.diagnose import diagnose
    d = diagnose("data/field/thesis", "out/diagnose", tests=["zero_radius_turn_dry_sand", ...])
    d.verdict["effect"], d.verdict["heldout_gap_shrink"]
    r = diagnose_each_terrain("data/field/thesis", "out/diagnose-each")   # one diagnosis per terrain
    r.verdict["effects_by_terrain"]

Command line: ``trackenv diagnose <folder> --out <dir>``; the withheld-effect check:
``trackenv diagnose-benchmark --cases N``. Modules: :mod:`.data` (logs, noise), :mod:`.phases`,
:mod:`.candidates`, :mod:`.batch` (batched simulation), :mod:`.fit` (held-out fitting),
:mod:`.metrics`, :mod:`.core` (the verdict), :mod:`.terrains` (one diagnosis per terrain), :mod:`.report`, :mod:`.blind` (blind cases),
:mod:`.benchmark`.
"""

from .candidates import NONE, RECALIBRATE, candidate_set
from .core import Diagnosis, diagnose
from .data import DiagnosisError
from .terrains import TerrainDiagnoses, diagnose_each_terrain

__all__ = ["diagnose", "diagnose_each_terrain", "Diagnosis", "TerrainDiagnoses", "DiagnosisError", "candidate_set", "NONE", "RECALIBRATE"]
