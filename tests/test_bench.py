"""Lifted-track bench test (thesis §4.3.2-4.3.3, Fig. 4.8): drive train and motor alone.

With the tracks off the ground ("lifted" terrain: no shear strength, no compaction, no internal
track resistance) the steady state is the thesis's friction law (4.3)-(4.5) plus the motor circuit
(4.2), solved by hand here:

    alpha i = b_eff omega + tau_stick,   V = R_m i + alpha_v omega
    => omega = (alpha V / R_m - tau_stick) / (b_eff + alpha alpha_v / R_m)

Voltages are chosen so that omega = 12.4 and 22.5 rad/s, the two bench tests of Fig. 4.8.
The transient is checked against the exact solution of the linear 2-state system (J_eff, L_m).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.linalg import expm

import trackenv as te

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def drive_constants():
    """alpha, alpha_v, R_m, b_eff, tau_stick, J_eff, L_m from the raw YAML (own unit conversions)."""
    v = {k: e["value"] for k, e in yaml.safe_load((CONFIGS / "vehicle" / "packbot.yaml").read_text()).items()
         if isinstance(e, dict)}
    alpha = v["torque_constant"] * v["gear_ratio"]
    alpha_v = v["gear_ratio"] * 60.0 / (2.0 * math.pi * v["speed_constant"])
    return (alpha, alpha_v, v["motor_resistance"], v["drive_damping"], v["stiction_torque"],
            v["drive_inertia"], v["motor_inductance"])


def bench_steady(volts):
    alpha, alpha_v, R, b, tau, _, _ = drive_constants()
    omega = (alpha * volts / R - tau) / (b + alpha * alpha_v / R)
    return omega, (volts - alpha_v * omega) / R


def volts_for(omega):
    alpha, alpha_v, R, b, tau, _, _ = drive_constants()
    return round(((b + alpha * alpha_v / R) * omega + tau) * R / alpha, 2)


V_124, V_225 = volts_for(12.4), volts_for(22.5)  # 11.46 V, 20.63 V


def run(v_left, v_right, t_end=8.0, dt=0.05, ramp=0.3):
    p = te.load_params("lifted")
    prof = te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [ramp, v_left, v_right], [t_end, v_left, v_right]])
    return te.simulate(p, prof, t_end, dt=dt, substep=0.001)


@pytest.mark.parametrize("volts,omega_thesis", [(V_124, 12.4), (V_225, 22.5)])
def test_bench_steady_state(volts, omega_thesis):
    traj = run(volts, volts)
    ch = {k: np.asarray(v) for k, v in traj.channels.items()}
    last = np.asarray(traj.t) >= 7.0 - 1e-6
    omega_ref, i_ref = bench_steady(volts)
    for side in ("left", "right"):
        omega = float(np.mean(ch[f"omega_{side}"][last]))
        current = float(np.mean(ch[f"i_{side}"][last]))
        assert omega == pytest.approx(omega_ref, rel=5e-3)
        assert current == pytest.approx(i_ref, rel=5e-3)
        assert omega == pytest.approx(omega_thesis, rel=5e-3)  # Fig. 4.8's operating points
        # the thesis's regression line (4.5): alpha i = b_eff omega + tau_stick
        alpha, _, _, b, tau, _, _ = drive_constants()
        assert alpha * current == pytest.approx(b * omega + tau, rel=5e-3)
    # nothing touches the ground: the body does not move
    for key in ("u", "v", "yaw_rate", "x", "y", "heading"):
        assert np.max(np.abs(ch[key])) < 1e-6, key


def test_bench_sides_are_independent():
    """Different voltages per side: each sprocket reaches its own bench steady state."""
    traj = run(V_124, V_225)
    last = np.asarray(traj.t) >= 7.0 - 1e-6
    ch = {k: np.asarray(v)[last].mean() for k, v in traj.channels.items()}
    w_l, i_l = bench_steady(V_124)
    w_r, i_r = bench_steady(V_225)
    assert ch["omega_left"] == pytest.approx(w_l, rel=5e-3)
    assert ch["omega_right"] == pytest.approx(w_r, rel=5e-3)
    assert ch["i_left"] == pytest.approx(i_l, rel=5e-3)
    assert ch["i_right"] == pytest.approx(i_r, rel=5e-3)
    # and the distinction matters (negative control)
    assert abs(w_r / w_l - 1.0) > 0.5
    # reversed voltage: the same speed backwards (stiction and friction are odd in omega)
    traj = run(-V_124, V_124)
    ch = {k: np.asarray(v)[last].mean() for k, v in traj.channels.items()}
    assert ch["omega_left"] == pytest.approx(-w_l, rel=5e-3)
    assert ch["i_left"] == pytest.approx(-i_l, rel=5e-3)
    assert ch["omega_right"] == pytest.approx(w_l, rel=5e-3)


def test_bench_transient_matches_linear_solution():
    """Voltage step at t = 0: omega(t), i(t) vs the exact solution of the linear system

        J domega/dt = alpha i - b omega - tau_stick,   L di/dt = V - R i - alpha_v omega

    (stiction taken as constant: the model's smoothsign(omega; 0.05) differs only for the first
    ~0.05 rad/s). The time constants (~0.25 ms electrical, ~6.6 ms mechanical) make this a check of
    J_eff and L_m, which the steady state cannot see.
    """
    alpha, alpha_v, R, b, tau, J, L = drive_constants()
    volts = V_225
    p = te.load_params("lifted")
    prof = te.VoltageProfile.constant(volts, volts)
    traj = te.simulate(p, prof, 0.05, dt=0.001, substep=0.001)
    t = np.asarray(traj.t, np.float64)
    # x = [omega, i]; dx/dt = A x + c
    A = np.array([[-b / J, alpha / J], [-alpha_v / L, -R / L]])
    c = np.array([-tau / J, volts / L])
    x_inf = -np.linalg.solve(A, c)
    ref = np.array([x_inf + expm(A * tk) @ (np.zeros(2) - x_inf) for tk in t])
    omega = np.asarray(traj.channels["omega_left"], np.float64)
    current = np.asarray(traj.channels["i_left"], np.float64)
    late = t >= 0.002
    assert np.max(np.abs(omega[late] - ref[late, 0])) < 0.01 * x_inf[0]
    # current peaks near V/R ~ 65 A at the step: compare on that scale, after the first ms
    assert np.max(np.abs(current[late] - ref[late, 1])) < 0.01 * volts / R
    # the mechanical time constant is visible: omega at 5 ms is ~50 % of its final value
    k5 = int(round(0.005 / 0.001))
    assert 0.3 < omega[k5] / x_inf[0] < 0.7
