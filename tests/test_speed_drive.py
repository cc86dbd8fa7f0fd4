"""Speed-prescribed drive (``SpeedProfile``): the model driven by measured sprocket speeds.

The check is a round trip: drive the model with voltages, record its sprocket speeds, drive it again
with those speeds prescribed. The body (yaw rate, pose), the motor currents from the torque balance
(4.1) and the drive voltage from (4.2) must come back, up to the error of interpolating the recorded
speeds linearly between samples, which must shrink as the speeds are recorded more often.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te


@pytest.fixture(autouse=True)
def _float64():
    """float64 for this file's tests only (jax_enable_x64 is process-global; the suite runs float32)."""
    with jax.enable_x64(True):
        yield

PROFILE = [[0, 0, 0], [0.3, 11.8, 11.8], [3.0, 11.8, 11.8], [3.3, 14.0, 6.0], [6.0, 14.0, 6.0]]


def _round_trip(terrain: str, record_dt: float):
    p = te.load_params(terrain, dtype=jnp.float64)
    prof = te.VoltageProfile.from_breakpoints(PROFILE, dtype=jnp.float64)
    ref = te.simulate(p, prof, t_end=6.0, dt=0.01)
    step = int(round(record_dt / 0.01))
    t_rec, w_rec = np.asarray(ref.t)[::step], np.asarray(ref.state.omega)[::step]
    sp = te.SpeedProfile.from_arrays(t_rec, w_rec, dtype=jnp.float64)
    out = te.simulate(p, sp, t_end=6.0, dt=0.01)
    return ref, out


def _nrmse(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.ptp(a))


@pytest.mark.parametrize("terrain", ["dry_sand", "asphalt"])
def test_prescribed_speeds_reproduce_the_voltage_driven_run(terrain):
    ref, out = _round_trip(terrain, 0.01)
    # the prescribed speeds are followed exactly at the samples
    assert np.allclose(np.asarray(out.state.omega), np.asarray(ref.state.omega), atol=1e-9)
    for ch, tol in [("yaw_rate", 5e-3), ("x", 2e-3), ("y", 2e-3), ("u", 1e-2), ("i_left", 1e-2), ("i_right", 1e-2)]:
        assert _nrmse(ref.channels[ch], out.channels[ch]) < tol, ch
    # the drive voltage (4.2) returns the applied voltage once the step transients have passed
    t = np.asarray(ref.t)
    calm = ((t > 1.0) & (t < 2.9)) | (t > 4.0)
    assert np.max(np.abs(np.asarray(out.voltage) - np.asarray(ref.voltage))[calm]) < 0.1


def test_speed_interpolation_error_shrinks_with_the_record_rate():
    errs = []
    for record_dt in (0.1, 0.05, 0.02):
        ref, out = _round_trip("dry_sand", record_dt)
        errs.append(_nrmse(ref.channels["i_left"], out.channels["i_left"]))
    assert errs[0] > errs[1] > errs[2], errs


def test_swapped_speeds_mirror_the_run():
    p = te.load_params("dry_sand", dtype=jnp.float64)
    t = np.array([0.0, 0.5, 3.0])
    w = np.array([[0.0, 0.0], [8.0, 4.0], [8.0, 4.0]])
    a = te.simulate(p, te.SpeedProfile.from_arrays(t, w, dtype=jnp.float64), t_end=3.0)
    b = te.simulate(p, te.SpeedProfile.from_arrays(t, w[:, ::-1], dtype=jnp.float64), t_end=3.0)
    scale = np.ptp(np.asarray(a.channels["yaw_rate"]))
    assert np.max(np.abs(np.asarray(a.channels["yaw_rate"]) + np.asarray(b.channels["yaw_rate"]))) < 1e-6 * scale
    assert np.allclose(np.asarray(a.channels["i_left"]), np.asarray(b.channels["i_right"]), atol=1e-6)


def test_bad_speed_profiles_are_refused():
    p = te.load_params("dry_sand")
    with pytest.raises(ValueError, match="omega_right.*not finite at sample 1"):
        te.SpeedProfile.from_arrays([0.0, 1.0], [[0.0, 0.0], [1.0, np.nan]])
    with pytest.raises(ValueError, match="omega_left.*exceeds the physical bound"):
        te.simulate(p, te.SpeedProfile.from_arrays([0.0, 1.0], [[0.0, 0.0], [1e5, 0.0]]), t_end=1.0)


def test_the_diagnosis_simulates_speed_mode_logs_as_replay_does(tmp_path):
    """A speed-mode log: the diagnosis's batch and replay give the same predictions (one comparison layer)."""
    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.candidates import NONE, candidate_set
    from trackenv.diagnose.data import load_tests
    from trackenv.fieldlog import write_log_columns
    from trackenv.replay import replay

    t = np.arange(0, 6.0, 0.1)
    v = np.stack([np.interp(t, [0, 1, 6], [0, 0.3, 0.3]), np.interp(t, [0, 1, 3, 6], [0, 0.3, 0.5, 0.5])], 1)
    cols = {"t": t, "track_speed_left": v[:, 0], "track_speed_right": v[:, 1], "i_left": 2 + 0.5 * np.sin(t),
            "i_right": 2 + t / 6, "yaw_rate": 0.1 * np.sin(t), "speed_ideal": v.mean(axis=1)}
    write_log_columns(tmp_path / "logs" / "a", cols, {"terrain": "dry_sand", "maneuver": "turn",
                                                      "current_sensor": "absolute", "vehicle": "husky",
                                                      "synthetic": True, "source": "test"})
    (test,), _ = load_tests(tmp_path / "logs")
    assert test.drive_kind == "speed" and "speed_ideal" not in test.measured
    assert any("drive input" in n for n in test.notes)
    none = next(c for c in candidate_set() if c.name == NONE)
    pred, div = BatchSimulator([test], substep=0.0005).run(none, {})
    rep = replay(tmp_path / "logs" / "a", tmp_path / "r", figure=False)
    assert not div.any() and rep.metrics["input_mode"] == "speed"
    for sig in ("i_left", "i_right", "yaw_rate"):
        scale = np.ptp(rep.simulated[sig]) + 1e-3
        assert np.max(np.abs(pred[0][sig][:, 0] - rep.simulated[sig])) < 0.02 * scale, sig
