"""Calibration on field logs (``trackenv.calibrate``): recovers a known parameter from a synthetic
speed-mode log, and the naive baseline recovers a known linear law."""

import numpy as np
import pytest

import trackenv as te
from trackenv.calibrate import NaiveBaseline, calibrate, evaluate
from trackenv.fieldlog import write_log_columns
from trackenv.params import ConfigError

RATE = 6.5  # Hz, the BorealTC wheel service


def _speeds(t):
    left = np.interp(t, [0, 1, 4, 5, 8], [0, 0.4, 0.4, 0.2, 0.2])
    right = np.interp(t, [0, 1, 4, 5, 8], [0, 0.4, 0.4, 0.5, 0.5])
    return np.stack([left, right], 1)


def _synthetic_log(folder, stiction: float):
    p = te.replace(te.load_params("asphalt", vehicle="husky"), **{"vehicle.stiction_torque": stiction})
    t = np.arange(0, 8.0 + 1e-9, 1 / RATE)
    v = _speeds(t)
    traj = te.simulate(p, te.SpeedProfile.from_arrays(t, v / float(p.vehicle.sprocket_radius)), t_end=8.0)
    tt = np.asarray(traj.t)
    cols = {"t": t, "track_speed_left": v[:, 0], "track_speed_right": v[:, 1],
            "i_left": np.abs(np.interp(t, tt, np.asarray(traj.channels["i_left"]))),
            "i_right": np.abs(np.interp(t, tt, np.asarray(traj.channels["i_right"]))),
            "yaw_rate": np.interp(t, tt, np.asarray(traj.channels["yaw_rate"]))}
    write_log_columns(folder, cols, {"terrain": "asphalt", "maneuver": "turn", "current_sensor": "absolute",
                                     "vehicle": "husky", "synthetic": True, "source": "test: simulated"})
    return folder


def test_calibration_recovers_a_known_stiction_torque(tmp_path):
    log = _synthetic_log(tmp_path / "log", stiction=6.0)
    cal = calibrate([log], {"vehicle.stiction_torque": (0.0, 20.0)}, max_nfev=8, progress=False)
    assert cal.values["vehicle.stiction_torque"] == pytest.approx(6.0, rel=0.03)
    assert cal.after.cost < 0.05 * cal.before.cost
    held = evaluate([log], cal.values)
    assert held.nrmse["log"]["i_left"] < 0.03


def test_naive_baseline_recovers_a_linear_law(tmp_path):
    t = np.arange(0, 20.0, 1 / RATE)
    v = np.stack([0.3 + 0.2 * np.sin(0.7 * t), 0.3 + 0.2 * np.sin(1.1 * t + 1.0)], 1)
    turn = np.abs(v[:, 1] - v[:, 0])
    cols = {"t": t, "track_speed_left": v[:, 0], "track_speed_right": v[:, 1],
            "i_left": 1.5 + 4.0 * np.abs(v[:, 0]) + 10.0 * turn, "i_right": 1.5 + 4.0 * np.abs(v[:, 1]) + 10.0 * turn,
            "yaw_rate": 0.6 * (v[:, 1] - v[:, 0]) / 0.5708}
    write_log_columns(tmp_path / "lin", cols, {"terrain": "asphalt", "maneuver": "turn", "current_sensor": "absolute",
                                               "vehicle": "husky", "synthetic": True, "source": "test"})
    base = NaiveBaseline.fit([tmp_path / "lin"])
    assert base.current == pytest.approx([1.5, 4.0, 10.0], rel=1e-4)
    assert base.chi == pytest.approx(0.6, rel=1e-4)
    assert all(e < 1e-4 for e in base.evaluate([tmp_path / "lin"]).nrmse["lin"].values())


def test_bad_calibration_requests_name_the_parameter(tmp_path):
    log = _synthetic_log(tmp_path / "log", stiction=4.0)
    with pytest.raises(ConfigError, match="unknown parameter 'vehicle.stiction'"):
        calibrate([log], {"vehicle.stiction": (0.0, 1.0)}, progress=False)
    with pytest.raises(ConfigError, match="'vehicle.mass'.*high 10 must exceed low 20"):
        calibrate([log], {"vehicle.mass": (20.0, 10.0)}, progress=False)
    with pytest.raises(ConfigError, match="vehicle.mass"):
        calibrate([log], {"vehicle.mass": (-5.0, 10.0)}, progress=False)
