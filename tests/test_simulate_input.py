"""``te.simulate`` and ``te.VoltageProfile``: bad input is rejected with a useful message, divergence
is reported (raised, or flagged with the state frozen at its last finite value), and the core works
under ``jax.vmap`` over parameters and ``jax.grad`` (checked against central finite differences in
float64).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.integrate import is_physical, physical_bounds
from trackenv.simulate import MAX_SUBSTEP

GO = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [2.0, 12.0, 12.0]]
J_TURN = [[0.0, 0.0, 0.0], [0.3, 12.0, 12.0], [1.0, 12.0, 12.0], [1.3, 16.0, 6.0], [3.0, 16.0, 6.0]]


@pytest.fixture(scope="module")
def sand():
    return te.load_params("dry_sand")


# ---------------------------------------------------------------------------------------------
# profiles


@pytest.mark.parametrize("rows", [[[0.0, 1.0], [1.0, 2.0]], [[0.0, 1.0, 2.0, 3.0]], [0.0, 1.0, 2.0]])
def test_wrong_shape_rows(rows):
    with pytest.raises(ValueError, match="shape"):
        te.VoltageProfile.from_breakpoints(rows)


def test_wrong_shape_arrays():
    with pytest.raises(ValueError, match="shape"):
        te.VoltageProfile.from_arrays([0.0, 1.0], np.zeros((2, 3)))
    with pytest.raises(ValueError, match="shape"):
        te.VoltageProfile.from_arrays([0.0, 1.0, 2.0], np.zeros((2, 2)))
    with pytest.raises(ValueError, match="shape"):
        te.VoltageProfile.from_arrays(np.zeros((2, 2)), np.zeros((2, 2)))


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("channel", [0, 1])
def test_non_finite_voltage_names_channel_and_sample(bad, channel):
    rows = [[0.0, 0.0, 0.0], [0.5, 1.0, 1.0], [1.0, 2.0, 2.0]]
    rows[2][1 + channel] = bad
    with pytest.raises(ValueError) as info:
        te.VoltageProfile.from_breakpoints(rows)
    msg = str(info.value)
    assert ("v_left", "v_right")[channel] in msg, msg
    assert "sample 2" in msg, msg


def test_non_finite_time():
    with pytest.raises(ValueError, match="sample 1"):
        te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [float("nan"), 1.0, 1.0]])


@pytest.mark.parametrize("v", [24.5, -30.0])
def test_voltage_beyond_bus_limit_rejected(v):
    with pytest.raises(ValueError) as info:
        te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [1.0, 0.0, v]])
    msg = str(info.value)
    assert "v_right" in msg and "24" in msg and "sample 1" in msg, msg
    # exactly at the limit is fine
    te.VoltageProfile.from_breakpoints([[0.0, 0.0, 0.0], [1.0, 24.0, -24.0]])


def test_simulate_checks_the_vehicle_voltage_limit(sand):
    # a profile built without validation is still checked by simulate
    raw = te.VoltageProfile(jnp.asarray([0.0, 1.0]), jnp.asarray([[0.0, 0.0], [30.0, 0.0]]))
    with pytest.raises(ValueError, match="v_left"):
        te.simulate(sand, raw, 1.0, dt=0.05, substep=0.001)
    # and against the vehicle's own limit
    low = te.replace(sand, **{"vehicle.voltage_limit": 12.0})
    with pytest.raises(ValueError, match="12"):
        te.simulate(low, te.VoltageProfile.constant(15.0, 15.0), 1.0, dt=0.05, substep=0.001)


@pytest.mark.parametrize("times,sample", [([0.0, 1.0, 0.5], 2), ([0.0, 1.0, 1.0], 2), ([1.0, 0.0, 2.0], 1)])
def test_non_monotonic_time_grid(times, sample):
    rows = [[t, 1.0, 1.0] for t in times]
    with pytest.raises(ValueError) as info:
        te.VoltageProfile.from_breakpoints(rows)
    assert "increasing" in str(info.value) and f"sample {sample}" in str(info.value)


def test_profile_interpolates_linearly_and_holds_ends():
    prof = te.VoltageProfile.from_breakpoints([[1.0, 0.0, 10.0], [3.0, 4.0, -10.0]])
    v = np.asarray(prof(jnp.asarray([0.0, 1.0, 2.0, 2.5, 3.0, 9.0])))
    np.testing.assert_allclose(v[:, 0], [0.0, 0.0, 2.0, 3.0, 4.0, 4.0], atol=1e-6)
    np.testing.assert_allclose(v[:, 1], [10.0, 10.0, 0.0, -5.0, -10.0, -10.0], atol=1e-5)


# ---------------------------------------------------------------------------------------------
# time grid


@pytest.mark.parametrize("t_end", [1.01, 0.07, 0.025])
def test_t_end_not_multiple_of_dt(sand, t_end):
    with pytest.raises(ValueError, match="dt"):
        te.simulate(sand, te.VoltageProfile.constant(5.0, 5.0), t_end, dt=0.05, substep=0.001)


@pytest.mark.parametrize("t_end", [0.0, -1.0, float("nan"), float("inf")])
def test_non_positive_t_end(sand, t_end):
    with pytest.raises(ValueError, match="t_end"):
        te.simulate(sand, te.VoltageProfile.constant(5.0, 5.0), t_end, dt=0.05, substep=0.001)


def test_bad_dt_substep_profile_and_mode(sand):
    prof = te.VoltageProfile.constant(5.0, 5.0)
    with pytest.raises(ValueError, match="dt"):
        te.simulate(sand, prof, 1.0, dt=0.0)
    with pytest.raises(ValueError, match="substep"):
        te.simulate(sand, prof, 1.0, dt=0.05, substep=-0.001)
    with pytest.raises(TypeError, match="VoltageProfile"):
        te.simulate(sand, [[0.0, 5.0, 5.0]], 1.0, dt=0.05, substep=0.001)
    with pytest.raises(ValueError, match="on_divergence"):
        te.simulate(sand, te.VoltageProfile.from_breakpoints(GO), 2.0, dt=0.05, substep=0.001, on_divergence="ignore")


# ---------------------------------------------------------------------------------------------
# divergence


@pytest.mark.parametrize("case", ["tiny_inertia", "small_inertia_at_limit"])
def test_divergence_is_raised_and_flagged(sand, case):
    if case == "tiny_inertia":  # J_eff = 1e-9 kg m^2: the sprocket equation is hopelessly stiff at 1 ms
        params, substep = te.replace(sand, **{"vehicle.drive_inertia": 1e-9}), 0.001
    else:  # J_eff / 100 at the largest accepted substep: unstable
        params, substep = te.replace(sand, **{"vehicle.drive_inertia": 1.7e-4}), MAX_SUBSTEP
    prof = te.VoltageProfile.from_breakpoints(GO)
    with pytest.raises(te.SimulationDiverged) as info:
        te.simulate(params, prof, 2.0, dt=0.05, substep=substep)
    msg = str(info.value)
    assert "t = " in msg and " s" in msg, msg

    traj = te.simulate(params, prof, 2.0, dt=0.05, substep=substep, on_divergence="flag")
    assert bool(traj.diverged)
    t_div = float(traj.t_diverged)
    assert math.isfinite(t_div) and 0.0 < t_div <= 2.0
    assert f"{t_div:.3f}" in msg  # the raised message names the same time
    t = np.asarray(traj.t)
    for name, ch in traj.channels.items():
        ch = np.asarray(ch)
        assert np.all(np.isfinite(ch)), name
        # frozen at the last finite value: every sample from t_div on equals the one before t_div
        k = int(np.argmin(np.abs(t - t_div)))
        assert np.all(ch[k:] == ch[k - 1]), name
    for leaf in jax.tree.leaves(traj.state):
        assert np.all(np.isfinite(np.asarray(leaf)))
    # flagged as soon as the state left the physical bounds, not after it overflowed: the frozen
    # state is a physical one
    i_max, w_max = (float(b) for b in physical_bounds(params))
    assert np.max(np.abs(np.asarray(traj.state.current))) <= i_max
    assert np.max(np.abs(np.asarray(traj.state.omega))) <= w_max


@pytest.mark.parametrize("substep", [MAX_SUBSTEP * 1.5, 0.03, 0.05])
def test_substep_above_stable_limit_is_rejected(sand, substep):
    with pytest.raises(ValueError, match=r"substep = .* exceeds the stable limit MAX_SUBSTEP"):
        te.simulate(sand, te.VoltageProfile.from_breakpoints(GO), 2.0, dt=0.05, substep=substep)


def test_substep_above_dt_is_rejected(sand):
    with pytest.raises(ValueError, match=r"substep = 0.008 s exceeds dt = 0.005 s"):
        te.simulate(sand, te.VoltageProfile.from_breakpoints(GO), 1.0, dt=0.005, substep=0.008)


def test_physical_bounds_flag_finite_blow_ups(sand):
    """A finite state beyond 10x the stall current or the no-load speed counts as diverged."""
    i_max, w_max = (float(b) for b in physical_bounds(sand))
    assert i_max == pytest.approx(10 * 24.0 / 0.316, rel=1e-5)  # stall current at the 24 V bus
    alpha_v = 60.0 / (2 * math.pi * 317.0) * 29.866667
    assert w_max == pytest.approx(10 * 24.0 / alpha_v, rel=1e-4)  # no-load sprocket speed
    s = te.initial_state(sand)
    assert bool(is_physical(s, sand, 0))
    assert bool(is_physical(te.State(s.pose, s.vel, s.omega, s.current.at[1].set(0.99 * i_max), s.jz, s.jx, {}), sand, 0))
    assert not bool(is_physical(te.State(s.pose, s.vel, s.omega, s.current.at[1].set(1.01 * i_max), s.jz, s.jx, {}), sand, 0))
    assert not bool(is_physical(te.State(s.pose, s.vel, s.omega.at[0].set(-1.01 * w_max), s.current, s.jz, s.jx, {}), sand, 0))
    assert not bool(is_physical(te.State(s.pose, s.vel.at[0].set(jnp.nan), s.omega, s.current, s.jz, s.jx, {}), sand, 0))


def test_healthy_run_is_not_flagged(sand):
    traj = te.simulate(sand, te.VoltageProfile.from_breakpoints(GO), 2.0, dt=0.05, substep=0.001, on_divergence="flag")
    assert not bool(traj.diverged)
    assert math.isnan(float(traj.t_diverged))


# ---------------------------------------------------------------------------------------------
# transformations


def test_vmap_over_cohesion_matches_individual_runs(sand):
    prof = te.VoltageProfile.from_breakpoints(J_TURN)
    cohesions = jnp.asarray([0.0, 1040.0, 4000.0])

    def final(c):
        ch = te.simulate(te.replace(sand, **{"terrain.cohesion": c}), prof, 3.0, dt=0.05, substep=0.001).channels
        return jnp.stack([ch["x"][-1], ch["y"][-1], ch["heading"][-1]])

    batched = np.asarray(jax.vmap(final)(cohesions))
    assert np.all(np.isfinite(batched))
    for k, c in enumerate(np.asarray(cohesions)):
        single = np.asarray(final(float(c)))
        np.testing.assert_allclose(batched[k], single, rtol=1e-4, atol=1e-5)
    # the cohesion matters (the batch is not one vehicle repeated)
    assert np.ptp(batched[:, 2]) > 1e-2


def test_grad_matches_finite_differences_float64():
    """d x(t_end)/d(c, b*_int) by reverse-mode AD vs central differences, float64 (measured: 2e-5)."""
    with jax.enable_x64(True):
        p = te.load_params("dry_sand", dtype=jnp.float64)
        prof = te.VoltageProfile.from_breakpoints(J_TURN, dtype=jnp.float64)

        def final_x(c, b_int):
            q = te.replace(p, **{"terrain.cohesion": c, "internal.constant": b_int})
            return te.simulate(q, prof, 3.0, dt=0.05, substep=0.001).channels["x"][-1]

        c0, b0 = 1040.0, 0.78
        g_c, g_b = jax.grad(final_x, argnums=(0, 1))(jnp.float64(c0), jnp.float64(b0))
        g_c, g_b = float(g_c), float(g_b)
        assert math.isfinite(g_c) and math.isfinite(g_b)
        hc, hb = 5.0, 5e-3
        fd_c = (float(final_x(c0 + hc, b0)) - float(final_x(c0 - hc, b0))) / (2 * hc)
        fd_b = (float(final_x(c0, b0 + hb)) - float(final_x(c0, b0 - hb))) / (2 * hb)
        assert abs(fd_c) > 1e-5 and abs(fd_b) > 1e-3  # both genuinely non-zero
        assert g_c == pytest.approx(fd_c, rel=0.05)
        assert g_b == pytest.approx(fd_b, rel=0.05)
        assert g_b < 0.0  # more internal resistance, less distance
