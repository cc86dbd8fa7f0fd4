"""Field logs (docs/model.md §9): reading, validation errors that name file/column/row, writing.

No simulation here (fast): ``write_field_log`` is exercised with a hand-made Trajectory; the
simulate → write → read → replay round trip is in ``test_replay.py``.
"""

from __future__ import annotations

import json
import re

import jax.numpy as jnp
import numpy as np
import pytest

from trackenv.fieldlog import (
    LOG_COLUMNS,
    FieldLogError,
    read_field_log,
    validate_meta,
    write_field_log,
    write_log_columns,
)
from trackenv.simulate import Trajectory

HEADER = "t,v_left,v_right,i_left,i_right,speed_ideal,yaw_rate"
ROWS = [
    "0.0,0,0,0,0,0,0",
    "0.02,0.8,0.8,1.5,1.5,0.01,0",
    "0.04,1.6,1.6,2.5,2.5,,0.001",  # a missing speed sample
    "0.06,2.4,2.4,3.1,3.0,0.05,",  # a missing yaw-rate sample
    "0.08,3.2,3.2,3.5,3.4,0.08,0.0",
]
META = {"terrain": "dry_sand", "maneuver": "go_stop", "current_sensor": "absolute"}


def make_log(folder, rows=None, header=HEADER, meta=None, meta_text=None):
    folder.mkdir(parents=True, exist_ok=True)
    lines = [header] + list(ROWS if rows is None else rows)
    (folder / "log.csv").write_text("\n".join(lines) + "\n")
    text = meta_text if meta_text is not None else json.dumps(META if meta is None else meta)
    (folder / "meta.json").write_text(text)
    return folder


def with_cell(row: int, col: str, value: str):
    """ROWS with data row ``row`` (1-based) column ``col`` replaced by ``value``."""
    cols = HEADER.split(",")
    rows = [r.split(",") for r in ROWS]
    rows[row - 1][cols.index(col)] = value
    return [",".join(r) for r in rows]


# ---------------------------------------------------------------------------------------------- good logs


def test_read_valid_log(tmp_path):
    log = read_field_log(make_log(tmp_path / "ok"))
    assert len(log) == 5
    np.testing.assert_allclose(log.t, [0, 0.02, 0.04, 0.06, 0.08])
    assert log.volts.shape == (5, 2) and log.volts.dtype == np.float64
    assert log.meta["vehicle"] == "packbot"  # default filled in
    assert log.terrain == "dry_sand" and log.current_sensor == "absolute" and not log.synthetic
    meas = log.measured()
    assert set(meas) == {"i_left", "i_right", "speed_ideal", "yaw_rate"}
    assert np.isnan(meas["speed_ideal"][2]) and np.isnan(meas["yaw_rate"][3])
    assert "FieldLog(" in repr(log)


def test_optional_and_extra_columns_and_keys(tmp_path):
    rows = [r + f",{k * 0.1},,,operator {k}" for k, r in enumerate(ROWS)]
    meta = dict(META, maneuver="figure eight on the quad", notes="windy", operator="JS", run=3)
    log = read_field_log(make_log(tmp_path / "x", rows, HEADER + ",x,y,heading,comment", meta))
    assert "x" in log.measured() and "y" not in log.measured()  # an all-empty optional column is "not logged"
    assert list(log.data["comment"]) == [f"operator {k}" for k in range(5)]
    assert log.meta["operator"] == "JS" and log.maneuver == "figure eight on the quad"


def test_time_need_not_start_at_zero_and_irregular_rate(tmp_path):
    rows = ["100.0,0,0,,,,", "100.013,1,1,,,,", "100.5,2,2,,,,", "101.25,2,2,,,,"]
    log = read_field_log(make_log(tmp_path / "x", rows))
    assert log.t[0] == 100.0 and log.measured() == {}  # measurement columns present but entirely empty


def test_entirely_empty_measurement_column_ok(tmp_path):
    rows = [",".join(r.split(",")[:6] + [""]) for r in ROWS]
    log = read_field_log(make_log(tmp_path / "x", rows))
    assert "yaw_rate" not in log.measured() and "i_left" in log.measured()


def test_missing_markers_and_blank_lines(tmp_path):
    rows = with_cell(2, "i_left", "NaN")
    rows.insert(2, "")  # a blank line is skipped
    log = read_field_log(make_log(tmp_path / "x", rows))
    assert len(log) == 5 and np.isnan(log.measured()["i_left"][1])


def test_signed_sensor_allows_negative_currents(tmp_path):
    rows = with_cell(3, "i_right", "-2.5")
    log = read_field_log(make_log(tmp_path / "x", rows, meta=dict(META, current_sensor="signed")))
    assert log.measured()["i_right"][2] == -2.5


# ---------------------------------------------------------------------------------------------- bad logs


def expect_error(folder, *fragments):
    with pytest.raises(FieldLogError) as info:
        read_field_log(folder)
    msg = str(info.value)
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"
    return msg


def test_missing_folder(tmp_path):
    expect_error(tmp_path / "nope", str(tmp_path / "nope"), "no such field-log folder")


def test_not_a_folder(tmp_path):
    (tmp_path / "f").write_text("x")
    expect_error(tmp_path / "f", "not a folder")


@pytest.mark.parametrize("name", ["log.csv", "meta.json"])
def test_missing_file(tmp_path, name):
    folder = make_log(tmp_path / "x")
    (folder / name).unlink()
    expect_error(folder, str(folder / name), "missing file")


def test_invalid_json_names_line(tmp_path):
    folder = make_log(tmp_path / "x", meta_text='{\n  "terrain": "dry_sand",\n  "maneuver": go_stop\n}')
    expect_error(folder, "meta.json", "invalid JSON", "line 3")


@pytest.mark.parametrize(
    "meta, fragments",
    [
        ([1, 2], ["JSON object"]),
        ({"maneuver": "go_stop", "current_sensor": "absolute"}, ["'terrain'", "missing required key"]),
        ({"terrain": "dry_sand", "current_sensor": "absolute"}, ["'maneuver'"]),
        ({"terrain": "dry_sand", "maneuver": "go_stop"}, ["'current_sensor'"]),
        (dict(META, terrain="mud"), ["'terrain'", "'mud'", "asphalt", "dry_sand"]),
        (dict(META, maneuver=""), ["'maneuver'"]),
        (dict(META, current_sensor="rms"), ["'current_sensor'", "'rms'"]),
        (dict(META, vehicle="talon"), ["'vehicle'", "'talon'", "packbot"]),
        (dict(META, notes=3), ["'notes'"]),
    ],
)
def test_bad_meta(tmp_path, meta, fragments):
    folder = make_log(tmp_path / "x", meta=meta)
    expect_error(folder, str(folder / "meta.json"), *fragments)


def test_missing_required_column(tmp_path):
    header = HEADER.replace(",yaw_rate", "")
    rows = [r.rsplit(",", 1)[0] for r in ROWS]
    folder = make_log(tmp_path / "x", rows, header)
    expect_error(folder, str(folder / "log.csv"), "'yaw_rate'", "line 1 (header)")


@pytest.mark.parametrize(
    "row, col, value, fragments",
    [
        (3, "speed_ideal", "fast", ["'fast' is not a finite number"]),
        (2, "i_left", "1.5A", ["not a finite number"]),
        (4, "yaw_rate", "inf", ["not a finite number"]),
        (2, "v_left", "", ["voltage is missing"]),
        (5, "v_right", "nan", ["voltage is missing"]),
        (3, "t", "", ["time is missing"]),
        (4, "v_right", "24.5", ["24.5 V exceeds", "24 V"]),
        (2, "v_left", "-30", ["30 V exceeds"]),
        (3, "t", "0.02", ["duplicate time", "strictly increasing", "line 3"]),
        (3, "t", "0.01", ["goes backwards"]),
        (5, "i_right", "-0.4", ["negative", "absolute", "signed"]),
    ],
)
def test_bad_cell_names_file_column_row(tmp_path, row, col, value, fragments):
    folder = make_log(tmp_path / "x", with_cell(row, col, value))
    msg = expect_error(folder, str(folder / "log.csv"), f"column '{col}'", f"line {row + 1} (data row {row})",
                       *fragments)
    assert re.search(r"line \d+ \(data row \d+\)", msg)


def test_wrong_field_count_names_line(tmp_path):
    rows = list(ROWS)
    rows[2] += ",7"
    expect_error(make_log(tmp_path / "x", rows), "log.csv", "line 4 (data row 3)", "8 fields", "header has 7")


def test_too_short(tmp_path):
    expect_error(make_log(tmp_path / "x", ROWS[:1]), "log.csv", "column 't'", "at least 2 samples")


def test_empty_file(tmp_path):
    folder = make_log(tmp_path / "x")
    (folder / "log.csv").write_text("")
    expect_error(folder, "log.csv", "empty file")


def test_duplicate_header_column(tmp_path):
    rows = [r + ",1" for r in ROWS]
    expect_error(make_log(tmp_path / "x", rows, HEADER + ",t"), "log.csv", "column 't' appears twice", "line 1")


# ---------------------------------------------------------------------------------------------- writing


def fake_trajectory(n=41, dt=0.05):
    """A hand-made single-vehicle Trajectory (float32 times, as simulate makes them)."""
    t = jnp.arange(n, dtype=jnp.float32) * dt
    s = np.sin(np.asarray(t, np.float64))
    ch = {"speed_ideal": s, "yaw_rate": -s, "i_left": 3 * s, "i_right": -3 * s, "x": s, "y": 2 * s, "heading": s,
          "u": s, "v": 0 * s, "omega_left": s, "omega_right": s}
    volts = np.stack([10 * s, -10 * s], axis=1)
    return Trajectory(t=t, state=None, channels={k: jnp.asarray(v, jnp.float32) for k, v in ch.items()},
                      voltage=jnp.asarray(volts, jnp.float32), diverged=jnp.asarray(False),
                      t_diverged=jnp.asarray(jnp.nan))


@pytest.mark.parametrize("sensor", ["absolute", "signed"])
def test_write_field_log_ammeter_and_labels(tmp_path, sensor):
    traj = fake_trajectory()
    log = write_field_log(tmp_path / sensor, traj, {"terrain": "asphalt", "maneuver": "zero_radius_turn"},
                          current_sensor=sensor)
    assert log.meta["synthetic"] is True and log.meta["source"] and log.meta["current_sensor"] == sensor
    assert list(log.data.columns) == list(LOG_COLUMNS)
    i_r = np.asarray(traj.channels["i_right"], np.float64)
    expect = np.abs(i_r) if sensor == "absolute" else i_r
    np.testing.assert_allclose(log.data["i_right"], expect, rtol=1e-6, atol=1e-7)
    text = (tmp_path / sensor / "log.csv").read_text().splitlines()
    assert text[0] == ",".join(LOG_COLUMNS)
    assert text[3].startswith("0.1,")  # float32 noise removed from the uniform time grid


def test_write_field_log_times_and_no_pose(tmp_path):
    traj = fake_trajectory()
    times = np.array([0.0, 0.05, 0.125, 1.0, 1.7])
    log = write_field_log(tmp_path / "x", traj, {"terrain": "dry_sand", "maneuver": "go_stop", "source": "unit test"},
                          current_sensor="signed", channels_optional=False, times=times, t_offset=5.0)
    np.testing.assert_allclose(log.t, times + 5.0)
    assert "x" not in log.data.columns and log.meta["source"] == "unit test"
    tg = np.arange(41) * 0.05
    np.testing.assert_allclose(log.data["yaw_rate"], np.interp(times, tg, -np.sin(tg)), atol=1e-6)


def test_write_field_log_rejects(tmp_path):
    traj = fake_trajectory()
    meta = {"terrain": "dry_sand", "maneuver": "go_stop"}
    with pytest.raises(ValueError, match="current_sensor"):
        write_field_log(tmp_path / "a", traj, meta, current_sensor="rms")
    with pytest.raises(ValueError, match="current_sensor"):
        write_field_log(tmp_path / "a", traj, dict(meta, current_sensor="signed"), current_sensor="absolute")
    with pytest.raises(FieldLogError, match="terrain"):
        write_field_log(tmp_path / "a", traj, {"maneuver": "go_stop"})
    with pytest.raises(ValueError, match="outside"):
        write_field_log(tmp_path / "a", traj, meta, times=[0.0, 9.0])
    batched = Trajectory(t=traj.t, state=None, channels=traj.channels, voltage=traj.voltage[..., None],
                         diverged=traj.diverged, t_diverged=traj.t_diverged)
    with pytest.raises(ValueError, match="single-vehicle"):
        write_field_log(tmp_path / "a", batched, meta)


def test_write_log_columns_round_trip(tmp_path):
    cols = {"t": [0.0, 0.1, 0.25], "v_left": [0, 1.5, 2], "v_right": [0, -1.5, -2], "i_left": [0, np.nan, 1],
            "i_right": [0, 1, np.nan], "speed_ideal": [np.nan] * 3, "yaw_rate": [0, 0.1, 0.2]}
    write_log_columns(tmp_path / "x", cols, dict(META, notes="hand-made"))
    log = read_field_log(tmp_path / "x")
    assert "speed_ideal" not in log.measured()
    np.testing.assert_array_equal(np.isnan(log.data["i_left"]), [False, True, False])
    assert validate_meta(log.meta) == log.meta
