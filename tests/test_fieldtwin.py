"""The synthetic field twin (trackenv.fieldtwin): valid §9 logs, labelled synthetic, truth withheld, deterministic,
and calibrated to the thesis's headline numbers (ZRT-sand yaw gap, go-stop currents)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackenv.effects import EFFECT_IDS
from trackenv.fieldlog import read_field_log
from trackenv.fieldtwin import make_field_twin

TESTS = ("go_stop_dry_sand", "go_stop_2ms_dry_sand", "zero_radius_turn_dry_sand")


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    out = tmp_path_factory.mktemp("twin")
    folders = make_field_twin(out, seed=0, tests=TESTS)
    return out, folders


def _mean(log, col, t0, t1):
    k = (log.t >= t0) & (log.t <= t1)
    return float(np.mean(log.data[col].to_numpy()[k]))


def test_folders_read_back_and_meta(twin):
    out, folders = twin
    assert sorted(f.name for f in folders) == sorted(TESTS)
    assert (out / "README.md").is_file()
    for f in folders:
        log = read_field_log(f)
        assert log.synthetic and log.meta["synthetic"] is True
        assert log.current_sensor == "absolute"
        assert log.vehicle == "packbot"
        assert "SYNTHETIC" in log.meta["notes"] and "RECONSTRUCTED" in log.meta["notes"]
        assert "not measured" in log.meta["notes"].lower()
        for c in ("i_left", "i_right"):
            i = log.data[c].to_numpy()
            assert np.all(np.isfinite(i)) and np.all(i >= 0)
        assert np.allclose(np.diff(log.t), 0.02)


def test_truth_withheld(twin):
    _, folders = twin
    for f in folders:
        truth = json.loads((f / "truth.json").read_text())
        assert truth["synthetic"] is True and truth["effects"]
        assert set(truth["effects"]) <= set(EFFECT_IDS)
        meta_text = (f / "meta.json").read_text()
        meta = json.loads(meta_text)
        values = json.dumps(list(meta.values()))
        assert "truth.json" not in values and "truth" not in meta
        for eid in EFFECT_IDS:  # the answer is not in meta.json
            assert eid not in meta_text


def test_dry_sand_effects(twin):
    _, folders = twin
    truth = json.loads((folders[0] / "truth.json").read_text())
    assert set(truth["effects"]) == {"slip_sinkage", "internal_resistance", "sensor_artifacts"}
    assert truth["effects"]["internal_resistance"]["b0"] == pytest.approx(0.88)
    assert truth["effects"]["sensor_artifacts"]["window"] == pytest.approx(0.1)


def test_deterministic_and_seeded(twin, tmp_path):
    out, _ = twin
    tid = "go_stop_2ms_dry_sand"
    make_field_twin(tmp_path / "a", seed=0, tests=[tid], write_readme=False)
    make_field_twin(tmp_path / "b", seed=1, tests=[tid], write_readme=False)
    same = (tmp_path / "a" / tid / "log.csv").read_bytes()
    assert same == (out / tid / "log.csv").read_bytes()
    other = read_field_log(tmp_path / "b" / tid)
    ref = read_field_log(out / tid)
    assert np.array_equal(other.volts, ref.volts)
    d = other.data["yaw_rate"].to_numpy() - ref.data["yaw_rate"].to_numpy()
    assert np.std(d) == pytest.approx(0.02 * np.sqrt(2), rel=0.3)


def test_zrt_sand_yaw_gap(twin):
    import trackenv as te
    from trackenv.field_profiles import load_field_profile

    out, _ = twin
    tid = "zero_radius_turn_dry_sand"
    log = read_field_log(out / tid)
    prof = load_field_profile(tid)
    base = te.simulate(te.load_params("dry_sand"), te.VoltageProfile.from_arrays(prof.t, prof.volts), 6.0, dt=0.02)
    t = np.asarray(base.t)
    k = (t >= 3.0) & (t <= 6.0)
    base_yaw = float(np.mean(np.abs(np.asarray(base.channels["yaw_rate"])[k])))
    kk = (log.t >= 3.0) & (log.t <= 6.0)
    twin_yaw = float(np.mean(np.abs(log.data["yaw_rate"].to_numpy()[kk])))
    assert base_yaw / twin_yaw > 5.0


@pytest.mark.parametrize("tid, t0, t1, amps", [("go_stop_dry_sand", 1.0, 3.0, 1.98),
                                               ("go_stop_2ms_dry_sand", 1.0, 2.3, 2.23)])
def test_go_stop_sand_currents(twin, tid, t0, t1, amps):
    out, _ = twin
    log = read_field_log(out / tid)
    i = 0.5 * (_mean(log, "i_left", t0, t1) + _mean(log, "i_right", t0, t1))
    assert i == pytest.approx(amps, rel=0.05)
