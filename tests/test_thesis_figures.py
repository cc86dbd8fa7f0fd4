"""Anchors from the thesis text (docs/model.md §8; thesis §5.4.1, eqs. 5.8-5.12).

- Go-stop on dry sand at 1.1 m/s: measured steady current 1.98 A (mean over 1-3 s). The constant
  internal-resistance model (Table 5.4, tuned on it) must reproduce it within 10 %.
- At 2 m/s the measured current is 2.23 A: the current hardly changes with speed (+0.25 A for
  +0.9 m/s), which the constant model reproduces and the viscous model (3.41) does not: the latter
  predicts about 3.1 A at 2 m/s.
- r_s/alpha = 0.099 (5.11): 10 V of motor voltage is about 1 m/s of ideal speed.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackenv as te

T_END = 8.0


def hold(internal, volts, window=(1.0, 3.0)):
    p = te.load_params("dry_sand", internal_resistance=internal)
    prof = te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [0.3, volts, volts], [T_END, volts, volts]])
    traj = te.simulate(p, prof, T_END, dt=0.05, substep=0.001)
    t = np.asarray(traj.t)
    sel = (t >= window[0] - 1e-6) & (t <= window[1] + 1e-6)
    ch = traj.channels
    speed = float(np.mean(np.asarray(ch["speed_ideal"])[sel]))
    # the field ammeter reports |i| (docs/model.md §7), averaged over both motors
    current = float(np.mean(0.5 * (np.abs(np.asarray(ch["i_left"])) + np.abs(np.asarray(ch["i_right"])))[sel]))
    return speed, current


def test_rs_over_alpha():
    p = te.load_params("dry_sand")
    ratio = float(p.vehicle.sprocket_radius / p.vehicle.alpha)
    assert ratio == pytest.approx(0.099, rel=0.01)


def test_sand_go_stop_current_at_1p1_mps():
    speed, current = hold("constant", 11.8)
    assert speed == pytest.approx(1.1, rel=0.01)
    assert current == pytest.approx(1.98, rel=0.10)  # measured, Fig. 5.2(b); sim 1.85 A (-6.5 %)


def test_current_insensitive_to_speed_with_constant_model():
    s1, i1 = hold("constant", 11.8)
    s2, i2 = hold("constant", 21.0, window=(1.0, 2.3))
    assert s2 == pytest.approx(2.0, rel=0.01)
    assert i2 == pytest.approx(2.23, rel=0.10)  # measured, Fig. 5.10(b); sim 2.12 A (-4.7 %)
    assert 0.0 < i2 - i1 < 0.5  # measured: +0.25 A


def test_viscous_model_current_at_2_mps():
    speed, current = hold("viscous", 21.25, window=(1.0, 2.3))
    assert speed == pytest.approx(2.0, rel=0.01)
    assert current == pytest.approx(3.1, rel=0.05)
    # ... and its current grows with speed by ~1 A, unlike the field data (the thesis's reason for 5.10)
    _, i1 = hold("viscous", 11.8)
    assert current - i1 > 0.8


def test_ten_volts_is_about_one_metre_per_second():
    s10, _ = hold("constant", 10.0)
    assert s10 == pytest.approx(1.0, rel=0.10)  # sim 0.93 m/s: the losses eat ~0.7 V
    s1, _ = hold("constant", 11.8)
    s2, _ = hold("constant", 21.0)
    slope = (s2 - s1) / (21.0 - 11.8)
    assert slope == pytest.approx(0.099, rel=0.02)  # (5.11): d v_i / d V = r_s / alpha
