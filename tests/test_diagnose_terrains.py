"""One diagnosis per terrain (``trackenv.diagnose.diagnose_each_terrain``): the split, the combined verdict, the
files, ``--after`` routed terrain by terrain, and the command line. The per-terrain diagnoses are stand-ins here
(their fits are :func:`trackenv.diagnose.diagnose`'s, tested in test_diagnose.py); the grouping reads the field
twin's real meta.json files."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

import trackenv.diagnose.terrains as terrains
from trackenv.diagnose import DiagnosisError, diagnose_each_terrain
from trackenv.diagnose.candidates import named_fits_from_report
from trackenv.diagnose.terrains import combined_verdict, folder_name, terrain_groups

TWIN = Path(__file__).resolve().parent.parent / "data" / "field" / "thesis"
SIX = ["go_stop_dry_sand", "go_stop_asphalt", "j_turn_dry_sand", "j_turn_asphalt", "lane_change_dry_sand",
       "lane_change_asphalt"]


def _verdict(effect, confidence=0.9, before=1.0, after=None, ins=0.0):
    """A verdict of report.json: the held-out gap ``before`` -> ``after`` (unchanged for none), in-sample shrink ``ins``."""
    return {"effect": effect, "confidence": confidence, "verdict_line": f"{effect} (confidence {confidence:.2f})",
            "gap_before": before, "gap_before_heldout": before, "gap_after": before if after is None else after,
            "insample_gap_shrink": ins, "heldout_gap_shrink_ci": [0.1, 0.9], "insample_gap_shrink_ci": [0.2, 0.8]}


def test_the_twin_splits_by_the_terrain_its_logs_name():
    groups, excluded = terrain_groups(TWIN, SIX)
    assert excluded == []
    assert groups == {"asphalt": ["go_stop_asphalt", "j_turn_asphalt", "lane_change_asphalt"],
                      "dry_sand": ["go_stop_dry_sand", "j_turn_dry_sand", "lane_change_dry_sand"]}


def test_terrain_folder_names_are_safe_and_unique():
    taken: set[str] = set()
    assert folder_name("dry_sand", taken) == "dry_sand"
    assert folder_name("configs/terrain/dry_sand.yaml", taken) == "dry_sand_2"
    assert folder_name("my soil (wet)", taken) == "my_soil__wet"
    assert folder_name("..", taken) == "terrain"


def test_the_combined_verdict_names_one_effect_only_where_the_terrains_agree():
    agree = combined_verdict({"dry_sand": _verdict("slip_sinkage", 0.8), "asphalt": _verdict("none", 0.3)})
    assert agree["effect"] == "slip_sinkage" and agree["confidence"] == pytest.approx(0.8)
    assert agree["verdict_line"].startswith("slip_sinkage on dry_sand; none on asphalt")
    differ = combined_verdict({"dry_sand": _verdict("slip_sinkage", 0.8) | {"flags": ["fit of slip_sinkage not converged"]},
                               "asphalt": _verdict("grouser_stiction", 0.6)})
    assert differ["flags"] == ["dry_sand: fit of slip_sinkage not converged"]
    assert differ["effect"] == "several" and differ["confidence"] == pytest.approx(0.6)
    assert differ["effects_by_terrain"] == {"dry_sand": "slip_sinkage", "asphalt": "grouser_stiction"}
    quiet = combined_verdict({"dry_sand": _verdict("none", 0.2), "asphalt": _verdict("none", 0.5)})
    assert quiet["effect"] == "none" and quiet["confidence"] == pytest.approx(0.2)
    assert quiet["heldout_gap_shrink"] == 0.0


def test_the_combined_shrink_is_over_all_tests():
    """The gap is the root of a mean over tests: sand's 3 tests go from a held-out gap of 2 to 1, asphalt's 1 test
    stays at 1 (none named there), so the gap over the 4 tests goes from sqrt(13/4) to sqrt(4/4). In sample the
    same with sand's own in-sample shrink 50 % (2 -> 1). An interval only where one terrain is all there is."""
    v = combined_verdict({"dry_sand": _verdict("slip_sinkage", before=2.0, after=1.0, ins=0.5),
                          "asphalt": _verdict("none", before=1.0, ins=0.7)}, {"dry_sand": 3, "asphalt": 1})
    assert v["heldout_gap_shrink"] == pytest.approx(1.0 - (4 / 13) ** 0.5)
    assert v["insample_gap_shrink"] == pytest.approx(1.0 - (4 / 13) ** 0.5)
    assert v["heldout_gap_shrink_ci"] is None
    alone = combined_verdict({"dry_sand": _verdict("slip_sinkage", before=2.0, after=1.0, ins=0.5)}, {"dry_sand": 3})
    assert alone["heldout_gap_shrink"] == pytest.approx(0.5) and alone["heldout_gap_shrink_ci"] == [0.1, 0.9]


@pytest.fixture
def stand_in(monkeypatch):
    """Replace each terrain's diagnosis: asphalt names grouser_stiction, dry sand names slip_sinkage on its first
    run and none once it continues another; records every call."""
    calls = []

    def fake(folder, out, *, tests, figures, progress, after, cache, **kw):
        terrain = "asphalt" if tests[0].endswith("asphalt") else "dry_sand"
        calls.append({"terrain": terrain, "out": out, "tests": tests, "after": after, "cache": cache, **kw})
        effect = {"asphalt": "grouser_stiction", "dry_sand": "none" if after else "slip_sinkage"}[terrain]
        report = {"verdict": _verdict(effect), "data_label": "SYNTHETIC: stand-in", "timing": {"wall_s": 1.0},
                  "base_model": {"internal_resistance": kw.get("internal_resistance", "constant"), "after": []}}
        if out is not None:
            Path(out).mkdir(parents=True, exist_ok=True)
            (Path(out) / "report.json").write_text(json.dumps(report))
        return SimpleNamespace(verdict=report["verdict"], report=report)

    monkeypatch.setattr(terrains, "diagnose", fake)
    return calls


def test_each_terrain_is_diagnosed_alone_and_summarised(tmp_path, stand_in):
    r = diagnose_each_terrain(TWIN, tmp_path / "each", tests=SIX, progress=False, seed=3, cache=tmp_path / "c")
    assert [c["terrain"] for c in stand_in] == ["asphalt", "dry_sand"]
    assert stand_in[1]["tests"] == ["go_stop_dry_sand", "j_turn_dry_sand", "lane_change_dry_sand"]
    assert stand_in[1]["out"] == tmp_path / "each" / "dry_sand" and stand_in[1]["cache"] == tmp_path / "c" / "dry_sand"
    assert all(c["seed"] == 3 and c["after"] is None for c in stand_in)
    assert r.verdict["effect"] == "several"
    rep = json.loads((tmp_path / "each" / "report.json").read_text())
    assert rep["mode"] == "each terrain" and rep["verdict"]["effects_by_terrain"] == {
        "asphalt": "grouser_stiction", "dry_sand": "slip_sinkage"}
    assert rep["terrains"]["dry_sand"]["report"] == "dry_sand/report.json"
    md = (tmp_path / "each" / "report.md").read_text()
    assert "[dry_sand/report.md](dry_sand/report.md)" in md and "**Verdict: several**" in md
    assert "Over all 6 tests, with each terrain's named effect in its model: held-out gap shrink 0%" in md


def test_after_a_summary_each_terrain_continues_its_own_fit(tmp_path, stand_in):
    """A summary as ``after``: each terrain starts from the report its own diagnosis wrote, a terrain that named
    nothing starts from the base model; a single diagnosis's report would go to every terrain."""
    diagnose_each_terrain(TWIN, tmp_path / "first", tests=SIX, progress=False)
    stand_in.clear()
    diagnose_each_terrain(TWIN, tmp_path / "second", tests=SIX, progress=False, after=tmp_path / "first")
    by = {c["terrain"]: c["after"] for c in stand_in}
    assert by == {"asphalt": tmp_path / "first" / "asphalt" / "report.json",
                  "dry_sand": tmp_path / "first" / "dry_sand" / "report.json"}
    stand_in.clear()
    diagnose_each_terrain(TWIN, None, tests=SIX, progress=False, after=tmp_path / "second" / "report.json")
    assert {c["terrain"]: c["after"] for c in stand_in} == {
        "asphalt": tmp_path / "second" / "asphalt" / "report.json", "dry_sand": None}
    stand_in.clear()
    single = tmp_path / "first" / "asphalt" / "report.json"
    diagnose_each_terrain(TWIN, None, tests=SIX, progress=False, after=single)
    assert [c["after"] for c in stand_in] == [single, single]


def test_a_summary_is_not_taken_for_one_diagnosis(tmp_path, stand_in):
    diagnose_each_terrain(TWIN, tmp_path / "each", tests=SIX, progress=False)
    with pytest.raises(DiagnosisError, match="a summary of one diagnosis per terrain; continue it with one diagnosis per terrain"):
        named_fits_from_report(tmp_path / "each", "constant")


def test_bad_options_are_refused_before_any_fit(tmp_path, stand_in):
    with pytest.raises(DiagnosisError, match="polish_iters"):
        diagnose_each_terrain(TWIN, tmp_path / "x", tests=SIX, progress=False, polish_iters=-1)
    with pytest.raises(DiagnosisError, match="no test folder named nope"):
        diagnose_each_terrain(TWIN, tmp_path / "x", tests=["nope"], progress=False)
    assert stand_in == [] and not (tmp_path / "x").exists()


def test_cli_diagnoses_each_terrain_where_the_tests_span_several(tmp_path, capsys, stand_in, monkeypatch):
    """``--terrains auto`` (the default): one diagnosis per terrain for a mixed folder, one pooled diagnosis for a
    single terrain; ``--after`` a summary continues per terrain, ``--after`` a pooled report pooled."""
    import trackenv.diagnose
    from trackenv.cli import main

    pooled = []

    def fake_pooled(folder, out, **kw):
        pooled.append(kw)
        Path(out).mkdir(parents=True, exist_ok=True)
        report = {"verdict": _verdict("slip_sinkage"), "data_label": "SYNTHETIC", "gap_cells": [],
                  "timing": {"wall_s": 1.0}}
        return SimpleNamespace(verdict=report["verdict"], report=report)

    monkeypatch.setattr(trackenv.diagnose, "diagnose", fake_pooled)
    assert main(["diagnose", str(TWIN), "--out", str(tmp_path / "o"), "--tests", ",".join(SIX), "--no-figures"]) == 0
    cap = capsys.readouterr()
    assert "one diagnosis per terrain" in cap.err and not pooled
    assert "verdict: several" in cap.out
    assert "  dry_sand (go_stop_dry_sand, j_turn_dry_sand, lane_change_dry_sand): slip" in cap.out
    assert f"--after {tmp_path / 'o' / 'report.json'}" in cap.out
    assert main(["diagnose", str(TWIN), "--out", str(tmp_path / "o2"), "--tests", ",".join(SIX),
                 "--after", str(tmp_path / "o")]) == 0
    assert {c["terrain"]: c["after"] for c in stand_in[2:]} == {
        "asphalt": tmp_path / "o" / "asphalt" / "report.json", "dry_sand": tmp_path / "o" / "dry_sand" / "report.json"}
    n = len(stand_in)
    sand = "go_stop_dry_sand,j_turn_dry_sand"
    assert main(["diagnose", str(TWIN), "--out", str(tmp_path / "p"), "--tests", sand, "--no-figures"]) == 0
    assert len(pooled) == 1 and len(stand_in) == n and "one diagnosis per terrain" not in capsys.readouterr().err
    assert main(["diagnose", str(TWIN), "--out", str(tmp_path / "q"), "--tests", sand, "--terrains", "each"]) == 0
    assert len(pooled) == 1 and [c["terrain"] for c in stand_in[n:]] == ["dry_sand"]
