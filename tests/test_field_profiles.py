"""Tests of the reconstructed field-test voltage profiles (configs/field/) and their loader."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from trackenv.field_profiles import (
    FIELD_DIR,
    V_LIMIT,
    FieldProfile,
    list_field_tests,
    load_field_profile,
)

EXPECTED_IDS = sorted(
    [
        "go_stop_dry_sand",
        "go_stop_asphalt",
        "j_turn_dry_sand",
        "j_turn_asphalt",
        "lane_change_dry_sand",
        "lane_change_asphalt",
        "zero_radius_turn_dry_sand",
        "zero_radius_turn_asphalt",
        "go_stop_2ms_dry_sand",
    ]
)

RS_OVER_ALPHA = 0.099  # §5.4.1: 10 V ≈ 1 m/s


def _dense(p: FieldProfile, t0: float, t1: float, n: int = 401) -> np.ndarray:
    return p.voltages_at(np.linspace(t0, t1, n))


# ------------------------------------------------------------------ the shipped data


def test_all_nine_tests_present_and_load():
    assert list_field_tests() == EXPECTED_IDS
    for tid in EXPECTED_IDS:
        p = load_field_profile(tid)
        assert p.id == tid
        assert p.t.dtype == np.float64 and p.volts.dtype == np.float64
        assert p.t.shape == (p.volts.shape[0],) and p.volts.shape[1] == 2
        assert p.t[0] == 0.0 and np.all(np.diff(p.t) > 0)
        assert p.t_end >= p.t[-1]
        assert np.all(np.abs(p.volts) <= V_LIMIT)
        assert p.internal_resistance == "constant"
        assert len(p.reconstruction) > 200  # a real provenance note, not a placeholder
        assert p.source.startswith("thesis")
        # the id encodes maneuver and terrain
        assert tid.startswith(p.maneuver)
        assert tid.endswith(p.terrain)


def test_files_are_marked_reconstructed():
    import yaml

    for tid in EXPECTED_IDS:
        doc = yaml.safe_load((FIELD_DIR / f"{tid}.yaml").read_text(encoding="utf-8"))
        assert doc["reconstructed"] is True


@pytest.mark.parametrize("tid", EXPECTED_IDS)
def test_starts_and_ends_at_rest(tid):
    """Every test starts with the vehicle at rest (0 V) and ends with it stopped (0 V held)."""
    p = load_field_profile(tid)
    np.testing.assert_array_equal(p.volts[0], [0.0, 0.0])
    np.testing.assert_array_equal(p.volts[-1], [0.0, 0.0])
    np.testing.assert_array_equal(p.voltages_at(p.t_end), [0.0, 0.0])
    # at least 1.5 s at 0 V after the release, so a simulator sees the vehicle come to rest
    assert p.t_end - p.t[-1] >= 1.5
    # the profile actually drives: some voltage of several volts somewhere
    assert np.abs(p.volts).max() >= 10.0


def _cruise_check(tid: str, t0: float, t1: float, speed: float):
    p = load_field_profile(tid)
    v = _dense(p, t0, t1)
    # constant over the averaging window, equal on both motors (straight line)
    assert np.ptp(v[:, 0]) == 0.0 and np.ptp(v[:, 1]) == 0.0
    assert v[0, 0] == v[0, 1]
    level = v[0, 0]
    nominal = speed / RS_OVER_ALPHA
    assert 0.85 * nominal <= level <= 1.15 * nominal, (level, nominal)
    # the level is above the pure back-emf value (R_m i drop), as §10's 11.8 / 21.0 V are
    assert level >= nominal
    return p, level


def test_go_stop_sand_cruise_level():
    p, level = _cruise_check("go_stop_dry_sand", 1.0, 3.0, 1.1)
    assert level == pytest.approx(11.8)
    means = [a for a in p.anchors if a["signal"] == "current" and a["stat"] == "mean"]
    assert len(means) == 1
    assert (means[0]["t0"], means[0]["t1"], means[0]["value"]) == (1.0, 3.0, 1.98)


def test_go_stop_asphalt_cruise_level():
    _cruise_check("go_stop_asphalt", 1.0, 3.0, 1.1)


def test_go_stop_2ms_cruise_level_and_stop():
    p, level = _cruise_check("go_stop_2ms_dry_sand", 1.0, 2.3, 2.0)
    assert level == pytest.approx(21.0)
    means = [a for a in p.anchors if a["signal"] == "current" and a["stat"] == "mean"]
    assert (means[0]["t0"], means[0]["t1"], means[0]["value"]) == (1.0, 2.3, 2.23)
    # "cruise spans 1-2.3 s then stop": the voltage falls soon after 2.3 s
    assert np.all(p.voltages_at(2.6) == 0.0)
    # "an approximate change of 10 V results in doubling the ideal speed" (§5.4.1)
    slow = load_field_profile("go_stop_dry_sand").voltages_at(2.0)[0]
    assert 8.0 <= level - slow <= 12.0


def test_other_straight_phases_run_at_1_1_m_s():
    for tid in ("j_turn_dry_sand", "j_turn_asphalt", "lane_change_dry_sand", "lane_change_asphalt"):
        _cruise_check(tid, 1.0, 2.0, 1.1)


@pytest.mark.parametrize("tid", ["zero_radius_turn_dry_sand", "zero_radius_turn_asphalt"])
def test_zero_radius_turn_equal_and_opposite(tid):
    p = load_field_profile(tid)
    np.testing.assert_array_equal(p.volts[:, 0], -p.volts[:, 1])
    v = _dense(p, 0.0, p.t_end, 2001)
    np.testing.assert_array_equal(v[:, 0], -v[:, 1])
    # documented direction: left forward, right backward (clockwise, negative yaw rate)
    assert p.volts[:, 0].max() > 0 and p.volts[:, 1].min() < 0
    assert np.all(p.volts[:, 0] >= 0)


def test_zero_radius_turn_sand_outlasts_the_stall():
    """The field vehicle stalled after ~20 s of turning on sand: the record must cover that."""
    p = load_field_profile("zero_radius_turn_dry_sand")
    turning = p.t[np.abs(p.volts[:, 0]) > 0]
    assert turning.max() - 0.0 >= 22.0
    # held at full voltage from the end of the ramp to past 20 s
    v = _dense(p, 1.0, 22.0)
    assert np.ptp(v[:, 0]) == 0.0 and v[0, 0] >= 10.0
    stall = [a for a in p.anchors if a["stat"] == "stall_after"]
    assert stall and stall[0]["value"] == 20.0
    ratio = [a for a in p.anchors if a["stat"] == "sim_over_field"]
    assert ratio and ratio[0]["value"] == pytest.approx(11.0)


@pytest.mark.parametrize("tid", ["j_turn_dry_sand", "j_turn_asphalt"])
def test_j_turn_left_above_right_during_turn(tid):
    p = load_field_profile(tid)
    straight = _dense(p, 0.0, 2.0)
    np.testing.assert_array_equal(straight[:, 0], straight[:, 1])
    turn = _dense(p, 2.15, 3.0)  # "turning during 2-3 s" (after the 0.1 s joystick move)
    assert np.all(turn[:, 0] > turn[:, 1])
    cruise = straight[-1, 0]
    assert np.all(turn[:, 0] > cruise) and np.all(turn[:, 1] < cruise)  # left up, right down
    # right motor generating: its voltage well below the cruise back-emf (≈ 11.1 V at 1.1 m/s)
    assert turn[:, 1].max() < 1.1 / RS_OVER_ALPHA - 2.0
    # then both removed
    np.testing.assert_array_equal(p.voltages_at(3.5), [0.0, 0.0])


@pytest.mark.parametrize("tid", ["lane_change_dry_sand", "lane_change_asphalt"])
def test_lane_change_right_then_left_and_balanced(tid):
    p = load_field_profile(tid)
    tt = np.linspace(0.0, p.t_end, 20001)
    v = p.voltages_at(tt)
    steer = v[:, 0] - v[:, 1]  # > 0: turning right
    right = np.where(steer > 1e-9)[0]
    left = np.where(steer < -1e-9)[0]
    assert right.size and left.size
    assert tt[right[0]] < tt[left[0]], "the first turn is to the right"
    # steering integrates to zero (heading restored) and its double integral, a proxy for the
    # lateral offset, returns to zero: the vehicle ends on the original line and heading
    dt = tt[1] - tt[0]
    heading_proxy = np.cumsum(steer) * dt
    assert abs(heading_proxy[-1]) < 1e-6 * np.abs(heading_proxy).max() + 1e-9
    lateral_proxy = np.cumsum(heading_proxy) * dt
    assert abs(lateral_proxy[-1]) < 1e-3 * np.abs(lateral_proxy).max()
    # mean track command stays at the cruise level while steering (speed constant in the turns)
    mean = 0.5 * (v[:, 0] + v[:, 1])
    moving = (tt > 0.3) & (tt < 8.0)
    assert np.allclose(mean[moving], mean[moving][0])


def test_sand_and_asphalt_share_profiles():
    for man in ("go_stop", "j_turn", "lane_change", "zero_radius_turn"):
        a = load_field_profile(f"{man}_dry_sand")
        b = load_field_profile(f"{man}_asphalt")
        if man == "zero_radius_turn":
            continue  # the sand spin is longer (~20 s stall); levels checked elsewhere
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.volts, b.volts)


def test_voltages_at_interpolates_and_holds():
    p = load_field_profile("go_stop_dry_sand")
    assert p.voltages_at(0.15) == pytest.approx([5.9, 5.9])  # half-way up the 0.3 s ramp
    assert p.voltages_at([0.0, 2.0]).shape == (2, 2)
    np.testing.assert_array_equal(p.voltages_at(p.t_end + 10.0), p.volts[-1])
    ts, vs = p.sample(0.05)
    assert ts[0] == 0.0 and ts[-1] == pytest.approx(p.t_end) and vs.shape == (ts.size, 2)
    with pytest.raises(ValueError):
        p.t[0] = 1.0  # read-only


def test_anchor_windows_inside_the_record():
    for tid in EXPECTED_IDS:
        p = load_field_profile(tid)
        for a in p.anchors:
            assert math.isfinite(a["value"]) and a["unit"] and a["source"].startswith("§")
            if a["t0"] is not None and a["t1"] is not None:
                assert 0.0 <= a["t0"] < a["t1"] <= p.t_end


# ------------------------------------------------------------------ loader validation

GOOD = """\
id: {id}
maneuver: go_stop
terrain: dry_sand
internal_resistance: constant
t_end: 4.0
source: "test"
reconstructed: true
reconstruction: "a test file"
anchors: []
breakpoints:
{rows}
"""

GOOD_ROWS = ["[0.0, 0.0, 0.0]", "[0.3, 11.8, 11.8]", "[3.0, 11.8, 11.8]", "[3.1, 0.0, 0.0]"]


def _write(tmp_path: Path, name: str, rows=None, text: str | None = None) -> Path:
    path = tmp_path / f"{name}.yaml"
    if text is None:
        rows = GOOD_ROWS if rows is None else rows
        text = GOOD.format(id=name, rows="\n".join(f"  - {r}" for r in rows))
    path.write_text(text, encoding="utf-8")
    return path


def test_good_temp_file_loads(tmp_path):
    p = load_field_profile(_write(tmp_path, "ok_profile"))
    assert p.id == "ok_profile" and p.t.shape == (4,)
    # a str path works too
    assert load_field_profile(str(_write(tmp_path, "ok2"))).id == "ok2"


def _raises(path: Path, *needles: str):
    with pytest.raises(ValueError) as exc:
        load_field_profile(path)
    msg = str(exc.value)
    assert str(path) in msg, msg
    for n in needles:
        assert re.search(n, msg), (n, msg)
    return msg


def test_non_monotonic_t(tmp_path):
    rows = ["[0.0, 0.0, 0.0]", "[0.3, 11.8, 11.8]", "[0.3, 11.8, 11.8]", "[3.1, 0.0, 0.0]"]
    _raises(_write(tmp_path, "nonmono", rows), r"row 2\b", "strictly")
    rows = ["[0.0, 0.0, 0.0]", "[2.0, 11.8, 11.8]", "[1.0, 11.8, 11.8]", "[3.1, 0.0, 0.0]"]
    _raises(_write(tmp_path, "decreasing", rows), r"row 2\b")


def test_t_not_starting_at_zero(tmp_path):
    rows = ["[0.1, 0.0, 0.0]", "[0.3, 11.8, 11.8]"]
    _raises(_write(tmp_path, "late_start", rows), r"row 0\b")


def test_nan_and_inf(tmp_path):
    rows = ["[0.0, 0.0, 0.0]", "[0.3, .nan, 11.8]", "[3.1, 0.0, 0.0]"]
    _raises(_write(tmp_path, "nan_v", rows), r"row 1\b", r"column 1\b", "v_left", "finite")
    rows = ["[0.0, 0.0, 0.0]", "[.inf, 11.8, 11.8]"]
    _raises(_write(tmp_path, "inf_t", rows), r"row 1\b", r"column 0\b")
    rows = ["[0.0, 0.0, 0.0]", "[0.3, 11.8, \"12\"]"]
    _raises(_write(tmp_path, "str_v", rows), r"row 1\b", r"column 2\b")


def test_over_voltage(tmp_path):
    rows = ["[0.0, 0.0, 0.0]", "[0.3, 11.8, -24.5]", "[3.1, 0.0, 0.0]"]
    _raises(_write(tmp_path, "overvolt", rows), r"row 1\b", r"column 2\b", "v_right", "24")
    rows = ["[0.0, 0.0, 0.0]", "[0.3, 24.0, -24.0]", "[3.1, 0.0, 0.0]"]
    load_field_profile(_write(tmp_path, "at_limit", rows))  # exactly 24 V is allowed


def test_bad_row_shape(tmp_path):
    rows = ["[0.0, 0.0, 0.0]", "[0.3, 11.8]"]
    _raises(_write(tmp_path, "short_row", rows), r"row 1\b")


def test_unknown_key(tmp_path):
    text = GOOD.format(id="extra", rows="\n".join(f"  - {r}" for r in GOOD_ROWS))
    text += "voltage_scale: 1.0\n"
    _raises(_write(tmp_path, "extra", text=text), "voltage_scale", "unknown")


def test_missing_key(tmp_path):
    text = GOOD.format(id="nokey", rows="\n".join(f"  - {r}" for r in GOOD_ROWS))
    text = "\n".join(line for line in text.splitlines() if not line.startswith("t_end"))
    _raises(_write(tmp_path, "nokey", text=text), "t_end", "missing")


def test_t_end_before_last_breakpoint(tmp_path):
    text = GOOD.format(id="short", rows="\n".join(f"  - {r}" for r in GOOD_ROWS))
    text = text.replace("t_end: 4.0", "t_end: 3.0")
    _raises(_write(tmp_path, "short", text=text), "t_end")


def test_id_must_match_file_name(tmp_path):
    text = GOOD.format(id="other_name", rows="\n".join(f"  - {r}" for r in GOOD_ROWS))
    _raises(_write(tmp_path, "file_name", text=text), "id")


def test_bad_anchor(tmp_path):
    text = GOOD.format(id="anch", rows="\n".join(f"  - {r}" for r in GOOD_ROWS))
    text = text.replace(
        "anchors: []",
        "anchors:\n  - {signal: current, stat: mean, t0: 1.0, t1: 3.0, value: 1.98, unit: A}",
    )
    _raises(_write(tmp_path, "anch", text=text), "anchors entry 0", "source")


def test_unknown_id_lists_known_ids():
    with pytest.raises(ValueError) as exc:
        load_field_profile("go_stop_on_the_moon")
    msg = str(exc.value)
    assert "go_stop_on_the_moon" in msg
    for tid in EXPECTED_IDS:
        assert tid in msg
