"""The demo's diagnoses: the search budget it passes, and the row it writes for each verdict."""

from types import SimpleNamespace

import trackenv.diagnose
from trackenv import demo


def test_demo_diagnoses_use_the_demo_budget_unless_full(monkeypatch, tmp_path):
    calls = []

    def fake_diagnose(folder, out, **kw):
        calls.append(kw)
        verdict = {"effect": "slip_sinkage", "confidence": 0.8, "heldout_gap_shrink": 0.98,
                   "heldout_gap_shrink_ci": [0.87, 0.99], "insample_gap_shrink": 0.98}
        return SimpleNamespace(verdict=verdict, report={"gap_cells": []})

    monkeypatch.setattr(trackenv.diagnose, "diagnose", fake_diagnose)
    lines = demo.gap_diagnoses(tmp_path)
    assert len(calls) == 2 and all({k: c[k] for k in demo.DEMO_BUDGET} == demo.DEMO_BUDGET for c in calls)
    assert calls[1]["internal_resistance"] == "viscous"
    assert sum("**slip_sinkage** (confidence 0.80) | 98% (95% CI 87-99%)" in ln for ln in lines) == 2
    calls.clear()
    demo.gap_diagnoses(tmp_path, {})
    assert all(not set(demo.DEMO_BUDGET) & set(c) for c in calls)  # the diagnose defaults
