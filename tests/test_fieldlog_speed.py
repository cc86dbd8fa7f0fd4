"""Field logs in speed mode (docs/model.md §9.1): a speed pair instead of the voltages; meta.json's
``measured``, ``sensors`` and ``data`` keys. Fast: no simulation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackenv.fieldlog import FieldLogError, input_mode_of, read_field_log, validate_meta, write_log_columns

META = {"terrain": "asphalt", "maneuver": "straight", "current_sensor": "absolute", "vehicle": "husky"}
TRACK_HEADER = "t,track_speed_left,track_speed_right,i_left,i_right,yaw_rate"
TRACK_ROWS = ["0,0.1,0.1,1.2,1.3,0.0", "0.15,0.2,0.25,2.0,2.1,", "0.3,0.3,0.3,2.5,2.4,0.01", "0.45,0.3,-0.3,3,3,0.5"]


def make_log(folder, header, rows, meta=None):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "log.csv").write_text("\n".join([header] + rows) + "\n")
    (folder / "meta.json").write_text(json.dumps(META if meta is None else meta))
    return folder


def expect_error(folder, *fragments):
    with pytest.raises(FieldLogError) as exc:
        read_field_log(folder)
    msg = str(exc.value)
    for f in fragments:
        assert f in msg, (f, msg)
    return msg


def test_track_speed_log_parses(tmp_path):
    log = read_field_log(make_log(tmp_path / "x", TRACK_HEADER, TRACK_ROWS))
    assert log.input_mode == "speed"
    assert log.input_mode_reason == "speed mode: columns track_speed_left/right present, no v_left/v_right"
    kind, speeds = log.speed_input
    assert kind == "track_speed" and speeds.shape == (4, 2) and speeds.dtype == np.float64
    np.testing.assert_array_equal(speeds[:, 1], [0.1, 0.25, 0.3, -0.3])
    assert set(log.measured()) == {"i_left", "i_right", "yaw_rate"}  # speed_ideal may be absent in speed mode
    assert np.isnan(log.measured()["yaw_rate"][1])
    assert set(log.speeds()) == {"track_speed_left", "track_speed_right"}
    assert log.vehicle == "husky" and "input='speed'" in repr(log)


def test_omega_log_parses_with_speed_ideal(tmp_path):
    header = "t,omega_left,omega_right,i_left,i_right,speed_ideal,yaw_rate"
    rows = ["0,1,1,0.5,0.5,,0", "0.1,2,3,0.5,0.6,0.2,0.1"]
    log = read_field_log(make_log(tmp_path / "x", header, rows))
    assert log.input_mode == "speed" and log.speed_input[0] == "omega"
    assert "omega_left/right" in log.input_mode_reason
    np.testing.assert_array_equal(log.speed_input[1], [[1, 1], [2, 3]])


def test_volts_raises_in_speed_mode(tmp_path):
    log = read_field_log(make_log(tmp_path / "x", TRACK_HEADER, TRACK_ROWS))
    with pytest.raises(FieldLogError, match="speed-mode log"):
        _ = log.volts


def test_both_speed_pairs_is_an_error(tmp_path):
    header = "t,omega_left,omega_right,track_speed_left,track_speed_right,i_left,i_right,yaw_rate"
    rows = ["0,1,1,0.1,0.1,1,1,0", "0.1,1,1,0.1,0.1,1,1,0"]
    expect_error(make_log(tmp_path / "x", header, rows), "log.csv", "line 1 (header)", "both speed pairs",
                 "omega_left/omega_right", "track_speed_left/track_speed_right")


def test_half_speed_pair_is_an_error(tmp_path):
    header = "t,track_speed_left,i_left,i_right,yaw_rate"
    rows = ["0,0.1,1,1,0", "0.1,0.1,1,1,0"]
    expect_error(make_log(tmp_path / "x", header, rows), "log.csv", "'track_speed_left'", "'track_speed_right'")


def test_no_input_pair_names_both_options(tmp_path):
    header = "t,i_left,i_right,speed_ideal,yaw_rate"
    rows = ["0,1,1,0,0", "0.1,1,1,0,0"]
    expect_error(make_log(tmp_path / "x", header, rows), "'v_left'", "'v_right'", "omega_left/omega_right",
                 "track_speed_left/track_speed_right")


def test_speed_mode_still_needs_yaw_rate(tmp_path):
    header = "t,track_speed_left,track_speed_right,i_left,i_right"
    rows = ["0,0.1,0.1,1,1", "0.1,0.1,0.1,1,1"]
    expect_error(make_log(tmp_path / "x", header, rows), "'yaw_rate'", "speed mode")


@pytest.mark.parametrize("value, fragment", [("", "the speed is missing"), ("nan", "the speed is missing"),
                                             ("fast", "not a finite number"), ("inf", "not a finite number")])
def test_bad_speed_cell_names_column_and_line(tmp_path, value, fragment):
    rows = list(TRACK_ROWS)
    cells = rows[2].split(",")
    cells[2] = value
    rows[2] = ",".join(cells)
    folder = make_log(tmp_path / "x", TRACK_HEADER, rows)
    expect_error(folder, str(folder / "log.csv"), "column 'track_speed_right'", "line 4 (data row 3)", fragment)


def test_voltage_log_with_speed_columns_stays_voltage(tmp_path):
    header = "t,v_left,v_right,i_left,i_right,speed_ideal,yaw_rate,omega_left,omega_right,track_speed_left"
    rows = ["0,0,0,0,0,0,0,0,,0.1", "0.1,1,1,1,1,0.1,0,5,6,", "0.2,2,2,1,1,0.2,0,,,"]
    log = read_field_log(make_log(tmp_path / "x", header, rows, dict(META, vehicle="packbot")))
    assert log.input_mode == "voltage" and log.speed_input is None
    assert log.input_mode_reason.startswith("voltage mode: columns v_left/v_right present")
    assert "kept as measurements" in log.input_mode_reason
    np.testing.assert_array_equal(log.volts, [[0, 0], [1, 1], [2, 2]])
    sp = log.speeds()
    assert set(sp) == {"omega_left", "omega_right", "track_speed_left"}  # empty cells allowed: measurements
    assert np.isnan(sp["omega_right"][0]) and sp["omega_left"][1] == 5
    assert set(log.measured()) == {"i_left", "i_right", "speed_ideal", "yaw_rate"}


def test_half_voltage_pair_is_still_a_missing_column(tmp_path):
    header = "t,v_left,track_speed_left,track_speed_right,i_left,i_right,yaw_rate,speed_ideal"
    rows = ["0,0,0.1,0.1,1,1,0,0", "0.1,0,0.1,0.1,1,1,0,0"]
    expect_error(make_log(tmp_path / "x", header, rows), "missing required column(s) 'v_right'")


def test_input_mode_of():
    assert input_mode_of(["t", "v_left", "v_right"])[0] == "voltage"
    assert input_mode_of(["t", "omega_left", "omega_right"])[:2] == ("speed", "omega")
    assert input_mode_of(["t"])[0] is None


def test_write_speed_log_round_trip_exact(tmp_path):
    t = np.arange(5) * (2 / 13)
    v = np.array([0.1968503937007874, 0.2362204724409448, 0.2204724409448819, 0.0, -0.1102362204724409])
    cols = {"t": t, "track_speed_left": v, "track_speed_right": -v, "i_left": [0.86, 10.18, np.nan, 5.32, 0.59],
            "i_right": [0.59] * 5, "yaw_rate": [0.0, 0.1, np.nan, 0.2, 0.3]}
    write_log_columns(tmp_path / "x", cols, dict(META, measured=True), digits=None)
    log = read_field_log(tmp_path / "x")
    assert list(log.data.columns) == ["t", "track_speed_left", "track_speed_right", "i_left", "i_right", "yaw_rate"]
    np.testing.assert_array_equal(log.t, t)
    np.testing.assert_array_equal(log.speed_input[1], np.stack([v, -v], 1))
    assert np.isnan(log.data["i_left"][2]) and log.is_measured and not log.synthetic
    with pytest.raises(ValueError, match="non-finite"):
        write_log_columns(tmp_path / "y", dict(cols, track_speed_left=[0, np.nan, 0, 0, 0]), META)
    with pytest.raises(ValueError, match="no input pair"):
        write_log_columns(tmp_path / "z", {"t": t, "i_left": t, "i_right": t, "yaw_rate": t}, META)


@pytest.mark.parametrize("extra, fragment", [
    ({"measured": "yes"}, "'measured' must be true or false"),
    ({"measured": True, "synthetic": True}, "both true"),
    ({"sensors": [1, 2]}, "'sensors' must be an object"),
    ({"sensors": {"yaw_rate": 100}}, "'yaw_rate' must be an object"),
    ({"sensors": {"yaw_rate": {"rate_hz": "fast"}}}, "'rate_hz' must be a number > 0"),
    ({"sensors": {"i_left": {"quantisation": -0.1}}}, "'quantisation' must be a number > 0"),
    ({"sensors": {"i_left": {"resolution": True}}}, "'resolution' must be a number > 0"),
    ({"data": 3}, "'data' must be a string"),
])
def test_bad_new_meta_keys(extra, fragment):
    with pytest.raises(FieldLogError, match="meta.json") as exc:
        validate_meta(dict(META, **extra))
    assert fragment in str(exc.value)


def test_good_new_meta_keys():
    meta = dict(META, measured=True, synthetic=False, data="MEASURED",
                sensors={"yaw_rate": {"rate_hz": 100.0, "filter": "box"}, "i_left": {"quantisation": 0.13,
                                                                                     "resolution": 0.01}})
    assert validate_meta(meta)["sensors"]["yaw_rate"]["filter"] == "box"


hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

CELLS = ["", "nan", "inf", "-1e400", "x", "0.5", "-0.3", "1e3", " 2 ", "NA"]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.integers(0, 4), st.integers(0, 5), st.sampled_from(CELLS)), min_size=1,
                      max_size=4),
       drop=st.sampled_from([None, "track_speed_left", "track_speed_right", "yaw_rate", "i_left"]))
def test_mutated_speed_logs_parse_or_name_the_file(tmp_path, edits, drop):
    """A mutated speed log either parses with a finite speed input on every row or raises a FieldLogError
    naming log.csv (never another exception)."""
    header = TRACK_HEADER.split(",")
    rows = [header] + [r.split(",") for r in TRACK_ROWS]
    for line, col, value in edits:
        rows[line][col] = value
    if drop is not None and drop in rows[0]:
        j = rows[0].index(drop)
        rows = [r[:j] + r[j + 1:] for r in rows]
    folder = tmp_path / f"f{abs(hash((tuple(edits), drop)))}"
    make_log(folder, ",".join(rows[0]), [",".join(r) for r in rows[1:]])
    try:
        log = read_field_log(folder)
    except FieldLogError as exc:
        assert str(folder / "log.csv") in str(exc)
    else:
        if log.input_mode == "speed":
            assert np.all(np.isfinite(log.speed_input[1])) and np.all(np.diff(log.t) > 0)
        else:
            assert log.input_mode == "voltage"
