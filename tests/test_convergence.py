"""Convergence: at the default substep every instrument channel of each maneuver stays close to a
tight-tolerance adaptive reference (diffrax Kvaerno5, rtol 1e-7), in float64.

Metric, per channel: the error relative to the channel's peak magnitude, both as NRMSE over the
maneuver and as the maximum pointwise error. The pointwise maximum sits where a stopping track's
slip crosses the saturation band of (3.17) in well under a millisecond (README, "Numerics").

The comparison window ends 0.2 s after the voltages reach zero: once a vehicle that was turning has
stopped on asphalt, the smoothed model (Table C.1) chatters in stick-slip around zero track speed
(about ±0.1 m/s, ±4 A, in the adaptive reference as well) and trajectories from different step
sizes separate there; that phase is checked for boundedness only.
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import trackenv as te  # noqa: E402
from trackenv import instruments  # noqa: E402
from trackenv.reference import reference_solution  # noqa: E402
from trackenv.simulate import DEFAULT_SUBSTEP  # noqa: E402

CHANNELS = ("speed_ideal", "yaw_rate", "i_left", "i_right", "x", "y", "heading")
MANEUVERS = {
    # id: (terrain, breakpoints [t, vL, vR], t_end)
    "go_stop_sand": ("dry_sand", [[0, 0, 0], [0.3, 11.8, 11.8], [3.0, 11.8, 11.8], [3.1, 0, 0]], 4.5),
    "j_turn_asphalt": ("asphalt", [[0, 0, 0], [0.3, 11.8, 11.8], [1.5, 11.8, 11.8], [1.7, 16, 6], [2.6, 16, 6],
                                   [2.7, 0, 0]], 4.0),
    "lane_change_sand": ("dry_sand", [[0, 0, 0], [0.3, 11.8, 11.8], [1.0, 11.8, 11.8], [1.1, 9, 14.6],
                                      [1.6, 9, 14.6], [1.7, 14.6, 9], [2.2, 14.6, 9], [2.3, 11.8, 11.8],
                                      [2.8, 11.8, 11.8], [2.9, 0, 0]], 4.0),
    "zero_radius_turn_asphalt": ("asphalt", [[0, 0, 0], [0.3, 12, -12], [2.0, 12, -12], [2.1, 0, 0]], 3.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MANEUVERS))
def test_default_substep_matches_reference(name):
    terrain, rows, t_end = MANEUVERS[name]
    params = te.load_params(terrain, dtype=jnp.float64)
    profile = te.VoltageProfile.from_breakpoints(rows, dtype=jnp.float64)
    ts, ys, _ = reference_solution(params, profile, t_end, dt=0.01, rtol=1e-7, atol=1e-10)
    ref = jax.vmap(lambda s: instruments.channels(s, params))(ys)
    traj = te.simulate(params, profile, t_end, dt=0.01, substep=DEFAULT_SUBSTEP)
    window = np.asarray(ts) <= rows[-1][0] + 0.2
    for ch in ("speed_ideal", "u"):
        assert np.max(np.abs(np.asarray(traj.channels[ch])[~window])) < 0.25, f"{name}/{ch} after the stop"
    for ch in CHANNELS:
        a, b = np.asarray(traj.channels[ch])[window], np.asarray(ref[ch])[window]
        scale = np.max(np.abs(b))
        if scale < 1e-6:  # a channel that stays at zero (yaw in a straight run) must stay there
            assert np.max(np.abs(a)) < 1e-6, ch
            continue
        nrmse = np.sqrt(np.mean((a - b) ** 2)) / scale
        worst = np.max(np.abs(a - b)) / scale
        assert nrmse < 0.01, f"{name}/{ch}: NRMSE {nrmse:.2%} of peak vs reference"
        assert worst < 0.03, f"{name}/{ch}: max error {worst:.2%} of peak vs reference"


@pytest.mark.slow
def test_error_shrinks_with_substep():
    """Halving the substep reduces the error (the integrator converges; order >= 2 here)."""
    terrain, rows, t_end = MANEUVERS["j_turn_asphalt"]
    params = te.load_params(terrain, dtype=jnp.float64)
    profile = te.VoltageProfile.from_breakpoints(rows, dtype=jnp.float64)
    ts, ys, _ = reference_solution(params, profile, t_end, dt=0.01, rtol=1e-9, atol=1e-12)
    window = np.asarray(ts) <= rows[-1][0]
    ref = np.asarray(ys.omega)[window]
    errs = []
    for h in (0.002, 0.001, 0.0005):
        traj = te.simulate(params, profile, t_end, dt=0.01, substep=h)
        errs.append(np.sqrt(np.mean((np.asarray(traj.state.omega)[window] - ref) ** 2)))
    assert errs[1] < errs[0] / 4 and errs[2] < errs[1] / 4, errs
