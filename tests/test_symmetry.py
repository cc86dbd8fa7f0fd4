"""Symmetries of the model (docs/model.md §1-5): exact properties any correct implementation must have.

- Left/right mirror (y -> -y): swapping V_left and V_right mirrors the trajectory: y, heading, yaw
  rate and v change sign; x, u and the ideal speed are unchanged; the two tracks swap.
- Fore/aft mirror (x -> -x): negating both voltages drives the same path backwards mirrored:
  X, u, psi, r, omega, i change sign; Y and v are unchanged. This exercises the leading-edge logic
  (z* from the rear in reverse, §3.4.2.2) and the z-bar logic of the lateral displacement (3.28-3.32):
  a wrong edge breaks it.
- A straight run (equal voltages) never yaws or drifts sideways.

Tolerance: 1e-4 of each channel's scale (float32; measured ~5e-6).
"""

from __future__ import annotations

import numpy as np
import pytest

import trackenv as te

T_END = 8.0
J_TURN = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [2.0, 12.0, 12.0], [2.3, 16.0, 6.0], [8.0, 16.0, 6.0]]
TOL = 1e-4


def run(terrain, rows):
    p = te.load_params(terrain)
    traj = te.simulate(p, te.VoltageProfile.from_breakpoints(rows), T_END, dt=0.05, substep=0.001)
    return traj, {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}


def assert_mirror(a, b, pairs):
    for key_a, sign, key_b in pairs:
        scale = np.max(np.abs(a[key_a]))
        assert scale > 1e-2, f"{key_a} is trivially small ({scale}): the maneuver tests nothing"
        err = np.max(np.abs(a[key_a] - sign * b[key_b]))
        assert err < TOL * scale, f"{key_a} vs {sign:+d}*{key_b}: max diff {err} (scale {scale})"


@pytest.fixture(scope="module", params=["dry_sand", "asphalt"])
def jturn(request):
    return request.param, run(request.param, J_TURN)


def test_left_right_mirror(jturn):
    terrain, (traj_a, a) = jturn
    traj_b, b = run(terrain, [[r[0], r[2], r[1]] for r in J_TURN])
    assert_mirror(a, b, [
        ("x", 1, "x"), ("y", -1, "y"), ("heading", -1, "heading"), ("yaw_rate", -1, "yaw_rate"),
        ("v", -1, "v"), ("u", 1, "u"), ("speed_ideal", 1, "speed_ideal"),
        ("i_left", 1, "i_right"), ("i_right", 1, "i_left"),
        ("omega_left", 1, "omega_right"), ("omega_right", 1, "omega_left"),
    ])
    # shear states: tracks swap, lateral displacement changes sign
    jz_a, jz_b = np.asarray(traj_a.state.jz), np.asarray(traj_b.state.jz)
    jx_a, jx_b = np.asarray(traj_a.state.jx), np.asarray(traj_b.state.jx)
    assert np.max(np.abs(jz_a - jz_b[:, ::-1])) < TOL * np.max(np.abs(jz_a))
    assert np.max(np.abs(jx_a + jx_b[:, ::-1])) < TOL * np.max(np.abs(jx_a))
    # negative control: the turn is not symmetric by itself
    assert np.max(np.abs(a["y"] - b["y"])) > 0.1


def test_fore_aft_mirror(jturn):
    terrain, (_, a) = jturn
    _, b = run(terrain, [[r[0], -r[1], -r[2]] for r in J_TURN])
    assert_mirror(a, b, [
        ("x", -1, "x"), ("y", 1, "y"), ("heading", -1, "heading"), ("yaw_rate", -1, "yaw_rate"),
        ("v", 1, "v"), ("u", -1, "u"), ("speed_ideal", -1, "speed_ideal"),
        ("i_left", -1, "i_left"), ("i_right", -1, "i_right"),
        ("omega_left", -1, "omega_left"), ("omega_right", -1, "omega_right"),
    ])


@pytest.mark.parametrize("terrain", ["dry_sand", "asphalt"])
def test_straight_run_does_not_yaw(terrain):
    rows = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [2.0, 12.0, 12.0], [2.3, 0.0, 0.0], [8.0, 0.0, 0.0]]
    traj, ch = run(terrain, rows)
    assert np.max(np.abs(ch["yaw_rate"])) < 1e-6
    assert np.max(np.abs(ch["heading"])) < 1e-6
    assert np.max(np.abs(ch["v"])) < 1e-6
    assert np.max(np.abs(ch["y"])) < 1e-6
    assert np.max(np.abs(np.asarray(traj.state.jx))) < 1e-6  # round-off only (turns: ~1e-2 m)
    np.testing.assert_allclose(ch["i_left"], ch["i_right"], atol=1e-5)
    assert np.max(ch["x"]) > 1.0  # it did drive
