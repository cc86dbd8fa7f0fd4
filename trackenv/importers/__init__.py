"""Importers: public datasets of real vehicles converted to field-log folders (docs/model.md §9.1, §9.5).

    from trackenv.importers import import_borealtc
    folders = import_borealtc("data/measured/borealtc", "out/borealtc")   # one speed-mode log per run

An importer never changes its input; what it writes is MEASURED data (``"measured": true``,
``"data": "MEASURED"`` in every ``meta.json``), converted but not simulated.
"""

from .borealtc import BOREALTC_TERRAINS, DatasetError, classify_maneuver, import_borealtc

__all__ = ["BOREALTC_TERRAINS", "DatasetError", "classify_maneuver", "import_borealtc"]
