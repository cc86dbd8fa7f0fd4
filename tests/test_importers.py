"""The BorealTC importer (trackenv/importers/borealtc.py) on the shipped MEASURED subset
(data/measured/borealtc/): valid speed-mode field logs, values copied exactly, the yaw rate's box
filter, the maneuver classes, the overwrite guard, bad input and the command line. Fast: no
simulation."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from trackenv.cli import main
from trackenv.fieldlog import read_field_log
from trackenv.importers import DatasetError, classify_maneuver, import_borealtc
from trackenv.outputs import OutputFolderError

ROOT = Path(__file__).resolve().parent.parent
SUBSET = ROOT / "data" / "measured" / "borealtc"
RUNS = ["ASPHALT/03", "ASPHALT/05", "SANDY_LOAM/01", "SANDY_LOAM/02", "SANDY_LOAM/09"]


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    out = tmp_path_factory.mktemp("borealtc")
    folders = import_borealtc(SUBSET, out)
    return out, folders


def raw(run: str):
    cls, xx = run.split("/")
    return pd.read_csv(SUBSET / cls / f"pro_{xx}.csv"), pd.read_csv(SUBSET / cls / f"imu_{xx}.csv")


def test_subset_is_shipped_with_licence():
    assert (SUBSET / "LICENSE").read_text().startswith("MIT License")
    readme = (SUBSET / "README.md").read_text()
    assert "MEASURED" in readme and "MIT" in readme
    size = 0
    for run in RUNS:
        cls, xx = run.split("/")
        for kind in ("pro", "imu"):
            f = SUBSET / cls / f"{kind}_{xx}.csv"
            assert f.is_file(), f
            size += f.stat().st_size
    assert size < 4e6


def test_every_run_is_a_valid_speed_log(imported):
    out, folders = imported
    assert sorted(f.name for f in folders) == sorted(r.replace("/", "_") for r in RUNS)
    for run in RUNS:
        log = read_field_log(out / run.replace("/", "_"))
        assert log.input_mode == "speed" and log.speed_input[0] == "track_speed"
        assert log.vehicle == "husky" and log.current_sensor == "absolute"
        assert log.terrain == ("asphalt" if run.startswith("ASPHALT") else "sandy_loam_1")
        assert log.is_measured and not log.synthetic and log.meta["data"] == "MEASURED"
        assert log.meta["source"]["licence"] == "MIT" and log.meta["source"]["run"] == run
        assert "MEASURED" in log.meta["notes"]
        assert np.all(np.diff(log.t) > 0) and log.t[0] == 0.0
        assert set(log.measured()) == {"i_left", "i_right", "yaw_rate"}  # speed_ideal: an empty column
        assert "speed_ideal" in log.data.columns
        s = log.meta["sensors"]
        assert s["track_speed_left"]["rate_hz"] == 6.5 and s["yaw_rate"]["rate_hz"] == 100.0
        assert s["track_speed_left"]["quantisation"] == pytest.approx(1 / 127, rel=1e-9)
        assert s["i_left"]["resolution"] == 0.01 and 0.12 <= s["i_left"]["quantisation"] <= 0.14
        assert log.meta["time_bases"]["offset_applied_s"] == 0.0


@pytest.mark.parametrize("run", ["ASPHALT/03", "SANDY_LOAM/02"])
def test_values_copied_exactly(imported, run):
    out, _ = imported
    log = read_field_log(out / run.replace("/", "_"))
    pro, _ = raw(run)
    np.testing.assert_array_equal(log.t, pro["time"])
    np.testing.assert_array_equal(log.speed_input[1], pro[["velL", "velR"]].to_numpy())
    np.testing.assert_array_equal(log.data["i_left"], pro["curL"])
    np.testing.assert_array_equal(log.data["i_right"], pro["curR"])


@pytest.mark.parametrize("run", ["ASPHALT/05", "SANDY_LOAM/02"])
def test_yaw_rate_is_a_box_average(imported, run):
    out, _ = imported
    log = read_field_log(out / run.replace("/", "_"))
    pro, imu = raw(run)
    half = (2 / 13) / 2  # half the 6.5 Hz wheel-service period
    yaw = log.data["yaw_rate"].to_numpy()
    for k in (0, 1, 37, len(pro) // 2, len(pro) - 20):
        tk = pro["time"].iloc[k]
        window = (imu["time"] >= tk - half) & (imu["time"] < tk + half)
        assert window.sum() >= 8
        assert yaw[k] == pytest.approx(imu["wz"][window].mean(), rel=1e-12, abs=1e-15)
    # the IMU record ends before the wheel service's: the last cells, without IMU samples, are empty
    assert np.isnan(yaw[-1]) == (imu["time"].iloc[-1] < pro["time"].iloc[-1] - half / 2)


def test_yaw_rate_sign_agrees_with_the_speeds(imported):
    out, _ = imported
    log = read_field_log(out / "SANDY_LOAM_02")  # left side backwards, right forwards: turning left
    assert np.nanmean(log.data["yaw_rate"]) > 0.05


@pytest.mark.parametrize("run, maneuver", [("ASPHALT/03", "straight"), ("SANDY_LOAM/01", "straight"),
                                           ("SANDY_LOAM/02", "zero_radius_turn"), ("SANDY_LOAM/09", "turn"),
                                           ("ASPHALT/05", "mixed")])
def test_maneuver_classes(imported, run, maneuver):
    out, _ = imported
    meta = json.loads((out / run.replace("/", "_") / "meta.json").read_text())
    assert meta["maneuver"] == maneuver


def test_classify_maneuver_rule():
    assert classify_maneuver([0.5] * 10, [0.51] * 10)[0] == "straight"
    assert classify_maneuver([-0.3] * 10, [0.3] * 10)[0] == "zero_radius_turn"
    assert classify_maneuver([0.1] * 10, [0.4] * 10)[0] == "turn"
    assert classify_maneuver([0.5] * 5 + [-0.3] * 5, [0.5] * 5 + [0.3] * 5)[0] == "mixed"
    assert classify_maneuver([0.0] * 4, [0.01] * 4)[0] == "standstill"


def test_refuses_to_overwrite(tmp_path):
    import_borealtc(SUBSET, tmp_path / "o", runs=["SANDY_LOAM/09"])
    log_csv = tmp_path / "o" / "SANDY_LOAM_09" / "log.csv"
    log_csv.write_text(log_csv.read_text())  # unchanged content, new mtime
    before = log_csv.read_bytes()
    with pytest.raises(OutputFolderError, match="SANDY_LOAM_09.*refusing to overwrite"):
        import_borealtc(SUBSET, tmp_path / "o", runs="SANDY_LOAM/09")
    assert log_csv.read_bytes() == before
    import_borealtc(SUBSET, tmp_path / "o", runs=["SANDY_LOAM/09"], force=True)
    # somebody's field log (no trackenv manifest) in the output folder itself
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "log.csv").write_text("t\n")
    with pytest.raises(OutputFolderError, match="did not write"):
        import_borealtc(SUBSET, theirs, runs=["SANDY_LOAM/09"])


def copy_run(tmp_path, run="SANDY_LOAM/09"):
    cls, xx = run.split("/")
    d = tmp_path / "ds" / cls
    d.mkdir(parents=True)
    for kind in ("pro", "imu"):
        shutil.copy(SUBSET / cls / f"{kind}_{xx}.csv", d / f"{kind}_{xx}.csv")
    return tmp_path / "ds", d


def test_missing_imu_file(tmp_path):
    ds, d = copy_run(tmp_path)
    (d / "imu_09.csv").unlink()
    with pytest.raises(DatasetError, match="imu_09.csv: missing file"):
        import_borealtc(ds, tmp_path / "o")
    assert not (tmp_path / "o").exists()  # nothing written


def test_pro_file_with_a_missing_column(tmp_path):
    ds, d = copy_run(tmp_path)
    pro = pd.read_csv(d / "pro_09.csv").drop(columns=["velR"])
    pro.to_csv(d / "pro_09.csv", index=False)
    with pytest.raises(DatasetError) as exc:
        import_borealtc(ds, tmp_path / "o")
    assert "pro_09.csv" in str(exc.value) and "'velR'" in str(exc.value)


def test_bad_cell_and_unknown_class(tmp_path):
    ds, d = copy_run(tmp_path)
    lines = (d / "pro_09.csv").read_text().splitlines()
    lines[4] = lines[4].replace(lines[4].split(",")[1], "oops", 1)
    (d / "pro_09.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"pro_09.csv: column 'curL', line 5 \(data row 4\)"):
        import_borealtc(ds, tmp_path / "o")
    (d.parent / "GRASS").mkdir()
    shutil.copy(SUBSET / "SANDY_LOAM" / "pro_09.csv", d.parent / "GRASS" / "pro_00.csv")
    with pytest.raises(DatasetError, match="terrain class 'GRASS' has no terrain id"):
        import_borealtc(ds, tmp_path / "o", runs=["GRASS/00"])


def test_bad_run_names(tmp_path):
    with pytest.raises(DatasetError, match="expected CLASS/XX"):
        import_borealtc(SUBSET, tmp_path / "o", runs=["ASPHALT-03"])
    with pytest.raises(DatasetError, match="pro_01.csv: missing file"):
        import_borealtc(SUBSET, tmp_path / "o", runs=["ASPHALT/01"])
    with pytest.raises(DatasetError, match="no such dataset folder"):
        import_borealtc(tmp_path / "nothing", tmp_path / "o")


def test_cli(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["import", "borealtc", str(SUBSET), "--out", str(out), "--runs", "SANDY_LOAM/02,ASPHALT/03"]) == 0
    text = capsys.readouterr().out
    assert "SANDY_LOAM_02" in text and "wrote 2 MEASURED field log(s)" in text and "IMU 0.." in text
    assert read_field_log(out / "ASPHALT_03").input_mode == "speed"
    assert main(["import", "borealtc", str(SUBSET), "--out", str(out), "--runs", "ASPHALT/03"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trackenv: error:") and "refusing to overwrite" in err and err.count("\n") == 1
    assert main(["import", "borealtc", str(tmp_path / "none"), "--out", str(out)]) == 2
    assert "no such dataset folder" in capsys.readouterr().err
    assert main(["import", "borealtc", str(SUBSET), "--out", str(out), "--runs", "ASPHALT/03", "--force"]) == 0
