"""Replay (trackenv.replay, ``trackenv replay``): simulate → write_field_log → read → replay round trips.

The round trips check that interpolation and alignment are right: a log written from a simulation and
replayed must reproduce the simulated channels *at the log's own sample times* (NRMSE < 1e-3), for a
regular 50 Hz log, an irregular-rate log and a log whose time does not start at 0; a log whose
measurements are one sample out of step with its voltages must not.

The maneuver ends while the vehicle is still moving: near rest the model's discrete choices (the
leading edge is picked by the sign of the track's ground speed when the belt is almost still,
docs/model.md §3) amplify float32 round-off (1e-7 V) into ~0.04 A, which is the model's sensitivity, not
the replay's. Compiles are shared: every 50 Hz replay has the same shapes, so only four programs are
compiled in this file.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

import trackenv as te
from trackenv.cli import main
from trackenv.fieldlog import FieldLogError, read_field_log, write_field_log
from trackenv.replay import _grid_step, replay

# straight, then a turn with the right track driven backwards (its current changes sign), then a gentle turn
BREAKPOINTS = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [1.0, 12.0, 12.0], [1.3, 14.0, -6.0], [2.2, 14.0, -6.0],
               [2.5, 15.0, 9.0]]
T_END = 3.0
META = {"terrain": "dry_sand", "maneuver": "j_turn", "notes": "round-trip test"}
CHANNELS = ("i_left", "i_right", "speed_ideal", "yaw_rate", "x", "y", "heading")


@pytest.fixture(scope="module")
def original():
    """The 'truth': a 1 ms-output simulation of the profile (so logs at any ms times are exact)."""
    params = te.load_params("dry_sand")
    profile = te.VoltageProfile.from_breakpoints(BREAKPOINTS)
    return profile, te.simulate(params, profile, T_END, dt=0.001)


@pytest.fixture(scope="module")
def logs(original, tmp_path_factory):
    profile, traj = original
    base = tmp_path_factory.mktemp("logs")
    t50 = np.arange(int(round(T_END / 0.02)) + 1) * 0.02
    out = {
        "abs50": write_field_log(base / "abs50", traj, META, "absolute", times=t50, profile=profile),
        "signed50": write_field_log(base / "signed50", traj, META, "signed", times=t50, profile=profile),
    }
    rng = np.random.default_rng(7)
    ms = np.unique(np.concatenate([[0, 3000], np.asarray(BREAKPOINTS)[:, 0] * 1000,
                                   rng.choice(np.arange(1, 3000), 150, replace=False)]).round().astype(int))
    keep = np.concatenate([[True], np.diff(ms) >= 4])  # irregular: 4 ms .. tens of ms apart
    out["irregular"] = write_field_log(base / "irregular", traj, META, "absolute", times=ms[keep] * 1e-3,
                                       profile=profile)
    return out


def assert_reproduces(res, tol=1e-3):
    chans = res.metrics["channels"]
    assert set(chans) == set(CHANNELS)
    for name, c in chans.items():
        assert c["nrmse"] is not None and c["nrmse"] < tol, (name, c)


def test_grid_step():
    assert _grid_step(0.05, 0.001, 0.02) == pytest.approx(0.02)
    assert _grid_step(0.05, 0.001, 0.0199999999) == pytest.approx(0.02)  # float noise of a logged 50 Hz grid
    assert _grid_step(0.05, 0.001, 0.2) == pytest.approx(0.05)
    assert _grid_step(0.05, 0.001, 0.0005) == pytest.approx(0.001)
    assert _grid_step(0.01, 0.02, 1.0) == pytest.approx(0.01)


def test_round_trip_50hz(logs, tmp_path):
    log = logs["abs50"]
    assert log.synthetic and len(log) == 151 and log.current_sensor == "absolute"
    res = replay(log.folder, tmp_path / "out", figure=False)
    assert res.kind == "field_log" and res.dt_sim == pytest.approx(0.02) and res.t_offset == 0.0
    assert_reproduces(res)
    # the simulated log has the input's rows and times, and is labelled as simulated
    sim = read_field_log(tmp_path / "out")
    np.testing.assert_array_equal(sim.t, log.t)
    assert sim.meta["synthetic"] is True and sim.meta["simulated"] is True and sim.current_sensor == "absolute"
    assert (sim.data["i_right"] >= 0).all()
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["channels"]["i_left"]["n"] == 151 and m["log_is_synthetic"] is True


def test_round_trip_irregular_rate(logs, tmp_path):
    log = logs["irregular"]
    dts = np.diff(log.t)
    assert dts.min() < 0.006 and dts.max() > 0.04  # really irregular
    res = replay(log.folder, tmp_path / "out", figure=False)
    assert res.dt_sim == pytest.approx(0.001 * round(dts.min() * 1000))  # at least as fine as the log
    assert_reproduces(res)


def test_time_offset_and_missing_samples(logs, tmp_path):
    """t need not start at 0 (shifted; the written log keeps the input's times); empty cells are skipped."""
    src = tmp_path / "shifted"
    shutil.copytree(logs["abs50"].folder, src)
    df = pd.read_csv(src / "log.csv", dtype=str, keep_default_na=False)
    df["t"] = [f"{1000.0 + float(t):.12g}" for t in df["t"]]
    df.loc[10:40, "yaw_rate"] = ""
    df.loc[:, "speed_ideal"] = ""
    df.to_csv(src / "log.csv", index=False)
    res = replay(src, tmp_path / "out", figure=False)
    assert res.t_offset == 1000.0
    assert "speed_ideal" in res.metrics["not_in_log"] and res.metrics["channels"]["yaw_rate"]["n"] == 151 - 31
    for name, c in res.metrics["channels"].items():
        assert c["nrmse"] < 1e-3, (name, c)
    assert read_field_log(tmp_path / "out").t[0] == 1000.0


def test_misaligned_log_is_detected(logs, tmp_path):
    """Measurements one sample (20 ms) late relative to the voltages: the comparison must see it."""
    src = tmp_path / "late"
    shutil.copytree(logs["abs50"].folder, src)
    df = pd.read_csv(src / "log.csv")
    for c in CHANNELS:
        df[c] = df[c].shift(1)
    df.to_csv(src / "log.csv", index=False, na_rep="")
    res = replay(src, tmp_path / "out", figure=False)
    assert res.metrics["channels"]["i_left"]["nrmse"] > 1e-2
    assert res.metrics["channels"]["yaw_rate"]["nrmse"] > 1e-2


def test_signed_and_absolute_ammeter(logs, tmp_path):
    signed = logs["signed50"]
    assert (signed.data["i_right"] < -1).any()  # the right track is driven backwards
    res = replay(signed.folder, tmp_path / "signed", figure=False)
    assert_reproduces(res)
    assert (read_field_log(tmp_path / "signed").data["i_right"] < -1).any()

    # an absolute log relabelled "signed": the simulated signed current no longer matches |i|
    wrong = tmp_path / "wrong"
    shutil.copytree(logs["abs50"].folder, wrong)
    meta = json.loads((wrong / "meta.json").read_text())
    (wrong / "meta.json").write_text(json.dumps(dict(meta, current_sensor="signed")))
    res = replay(wrong, tmp_path / "out", figure=False)
    assert res.metrics["channels"]["i_right"]["nrmse"] > 0.1
    assert res.metrics["channels"]["i_left"]["nrmse"] < 1e-3  # the left current stays positive

    # a signed log relabelled "absolute" is rejected: an |i| ammeter cannot read negative currents
    bad = tmp_path / "bad"
    shutil.copytree(signed.folder, bad)
    (bad / "meta.json").write_text(json.dumps(dict(meta, current_sensor="absolute")))
    with pytest.raises(FieldLogError, match=r"column 'i_right', line \d+ \(data row \d+\).*negative"):
        replay(bad, tmp_path / "out2")


def test_refuses_to_overwrite_the_input_log(logs):
    folder = logs["abs50"].folder
    before = (folder / "log.csv").read_text()
    with pytest.raises(FieldLogError, match="overwrite the measured log"):
        replay(folder, folder)
    assert (folder / "log.csv").read_text() == before


def test_bad_source(tmp_path):
    with pytest.raises(FieldLogError, match="neither a thesis test id"):
        replay("no_such_test", tmp_path / "o")
    with pytest.raises(FieldLogError, match="no such field-log folder"):
        replay(tmp_path / "missing", tmp_path / "o")
    with pytest.raises(te.ConfigError, match="unknown effect id 'slip_sunkage'"):
        replay("go_stop_dry_sand", tmp_path / "o", effects=("slip_sunkage",))


# ---------------------------------------------------------------------------------------------- CLI


def test_cli_replay_thesis_test(tmp_path, capsys):
    out = tmp_path / "tmp"
    assert main(["replay", "go_stop_dry_sand", "--out", str(out)]) == 0
    for name in ("log.csv", "meta.json", "replay.png", "metrics.json"):
        assert (out / name).is_file(), name
    log = read_field_log(out)
    assert log.meta["synthetic"] is True and log.meta["reconstructed"] is True
    assert "RECONSTRUCTED" in log.meta["source"] and "not measured" in log.meta["source"]
    assert log.current_sensor == "absolute" and len(log) == 101
    m = json.loads((out / "metrics.json").read_text())
    assert m["kind"] == "thesis_test" and "RECONSTRUCTED" in m["note"]
    current = next(a for a in m["anchors"] if a["signal"] == "current")
    assert current["thesis_field"] == 1.98 and 1.7 < current["simulated"] < 2.1
    printed = capsys.readouterr().out
    assert "RECONSTRUCTED" in printed and "replay.png" in printed


def test_cli_replay_log_folder_with_figure(logs, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["replay", str(logs["abs50"].folder), "--out", str(out)]) == 0
    assert (out / "replay.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "synthetic log" in printed and "NRMSE" in printed


def test_cli_list(capsys):
    assert main(["replay", "--list"]) == 0
    printed = capsys.readouterr().out
    assert "go_stop_dry_sand" in printed and "zero_radius_turn_dry_sand" in printed and "RECONSTRUCTED" in printed


def test_cli_errors_exit_2_with_message(tmp_path, capsys):
    assert main(["replay", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such field-log folder" in capsys.readouterr().err

    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "meta.json").write_text(json.dumps({"terrain": "dry_sand", "maneuver": "go_stop",
                                               "current_sensor": "absolute"}))
    (bad / "log.csv").write_text("t,v_left,v_right,i_left,i_right,speed_ideal,yaw_rate\n0,0,0,,,,\n0.1,1,x1,,,,\n")
    assert main(["replay", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "log.csv" in err and "column 'v_right'" in err and "line 3 (data row 2)" in err
    assert "Traceback" not in err

    assert main(["replay", "go_stop_dry_sand", "--effects", "bogus", "--out", str(tmp_path / "o")]) == 2
    assert "unknown effect id 'bogus'" in capsys.readouterr().err
    assert main(["replay", "--out", str(tmp_path / "o")]) == 2
    assert "--list" in capsys.readouterr().err
    assert main(["replay", "not_a_test", "--out", str(tmp_path / "o")]) == 2
    assert "neither a thesis test id" in capsys.readouterr().err
