"""Property-based tests of the physics (hypothesis) over random parameters and random voltage profiles.

Parameters are drawn inside the domain-randomisation ranges (trackenv/envs/randomization.py: Tables
5.4-5.6 and mass +-10 %), which lie inside the bounds table of trackenv/params.py; the sinkage exponent
and k_phi are drawn as well on sand. Voltage profiles have a fixed number of breakpoints (so every
example reuses one compiled program) with random times and voltages in [-24, 24] V.

Properties: no NaN (and no divergence), mirror symmetry (swapping the voltages mirrors the motion),
determinism (the same inputs give a bit-identical trajectory), energy balance (float64: the electrical
energy equals the losses plus the change of stored energy, as in tests/test_energy.py) and the App. D
straight-line steady state (tests/test_steady_state.py's independent algebraic solution, for the drawn
parameters).

Budgets: the ``ci`` hypothesis profile (tests/conftest.py, a few examples per property) runs in CI;
``HYPOTHESIS_PROFILE=thorough`` runs 200 examples per property (README "Reliability").
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import trackenv as te  # noqa: E402
from trackenv.physics.model import power_balance  # noqa: E402

HERE = Path(__file__).resolve().parent
N_BREAKS = 5
T_END = 2.0
BUDGET = settings().max_examples


def budget(factor: float = 1.0) -> int:
    return max(2, int(round(BUDGET * factor)))


# ----------------------------------------------------------------------------------------------
# strategies

SAND_RANGES = {  # dotted path: (low, high), SI; inside params.BOUNDS
    "terrain.cohesion": (0.0, 3040.0),
    "terrain.friction_angle": (math.radians(23.0), math.radians(38.0)),
    "terrain.shear_modulus": (0.010, 0.0508),
    "terrain.sinkage_exponent": (0.8, 1.3),
    "terrain.k_phi": (0.7e6, 3.0e6),
    "internal.constant": (0.73, 1.17),
    "vehicle.mass": (16.3, 20.0),
}
ASPHALT_RANGES = {
    "terrain.friction_angle": (0.85 * math.radians(37.0), 1.15 * math.radians(37.0)),
    "internal.constant": (0.69, 1.09),
    "vehicle.mass": (16.3, 20.0),
}


@st.composite
def param_changes(draw, terrain):
    ranges = SAND_RANGES if terrain == "dry_sand" else ASPHALT_RANGES
    return {k: draw(st.floats(lo, hi, allow_nan=False)) for k, (lo, hi) in ranges.items()}


@st.composite
def profiles(draw, t_end=T_END, vmax=24.0):
    """(N_BREAKS, 3) rows [t, v_left, v_right]: starts at rest at t = 0, random times (gaps >= 5 % of t_end)."""
    gaps = draw(st.lists(st.floats(0.05, 1.0), min_size=N_BREAKS - 1, max_size=N_BREAKS - 1))
    times = np.cumsum(gaps) / np.sum(gaps) * t_end
    volts = draw(st.lists(st.tuples(st.floats(-vmax, vmax), st.floats(-vmax, vmax)), min_size=N_BREAKS - 1,
                          max_size=N_BREAKS - 1))
    return [[0.0, 0.0, 0.0]] + [[float(t), vl, vr] for t, (vl, vr) in zip(times, volts)]


_BASE: dict = {}


def base(terrain, dtype=jnp.float32):
    key = (terrain, jnp.dtype(dtype).name)
    if key not in _BASE:
        _BASE[key] = te.load_params(terrain, dtype=dtype)
    return _BASE[key]


def run(params, rows, t_end=T_END, dt=0.05, substep=0.001, dtype=jnp.float32):
    prof = te.VoltageProfile.from_breakpoints(rows, dtype=dtype)
    return te.simulate(params, prof, t_end, dt=dt, substep=substep, on_divergence="flag")


def channels(traj):
    return {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}


TERRAINS = st.sampled_from(["dry_sand", "asphalt"])


# ----------------------------------------------------------------------------------------------
# properties


@settings(max_examples=budget(1.0))
@given(data=st.data(), terrain=TERRAINS)
def test_no_nan_and_no_divergence(data, terrain):
    changes = data.draw(param_changes(terrain))
    rows = data.draw(profiles())
    traj = run(te.replace(base(terrain), **changes), rows)
    assert not bool(np.asarray(traj.diverged)), (changes, rows, float(traj.t_diverged))
    leaves = jax.tree.leaves(traj.state) + list(traj.channels.values())
    assert all(np.isfinite(np.asarray(x)).all() for x in leaves), (changes, rows)
    ch = channels(traj)
    # physically bounded: speeds below the no-load speed at 24 V, currents below the stall current
    v = base(terrain).vehicle
    assert np.max(np.abs(ch["speed_ideal"])) < 24.0 / float(v.alpha_v) * float(v.sprocket_radius) * 1.05
    assert np.max(np.abs(ch["i_left"])) < 24.0 / float(v.motor_resistance) * 1.05


@settings(max_examples=budget(1.0))
@given(data=st.data(), terrain=TERRAINS)
def test_mirror_symmetry(data, terrain):
    """Swapping the voltages mirrors the motion; float64, to 1e-2 of each channel's scale (5e-2 on asphalt).

    The model is mirror-symmetric, but near rest on asphalt the stick-slip chatter amplifies rounding: the
    thorough profile found, in float32, a heading mismatch of 1.8 % of its scale at 1 ms substeps (0.3 % at
    0.5 ms) for 1-3 V, where the vehicle barely leaves stiction (1e-11 for that case in float64), and in
    float64 3e-6 of v's scale after a 10 V pulse that stops, 3.7e-4 of y's scale on sand for a 9 V pulse on
    one track that comes to rest, and 1.8e-3 of the yaw rate's scale on asphalt for 15/1 V, then 0/11 V,
    then 0/-16 V (steering reversals: the z-bar resets of (3.29)-(3.30) are discontinuous, so a comparison
    that rounding tips one way on one side and the other way on the mirrored side gives a visible jump).
    On asphalt with steering reversals it reached 1.5e-2 of v's scale (4/-14 V, then 21/0 V, then 4/0 V),
    hence 5e-2 there. A sign or a swapped term in the model breaks the property by O(1)
    (tests/test_symmetry.py's control).
    """
    changes = data.draw(param_changes(terrain))
    rows = data.draw(profiles())
    with jax.enable_x64(True):
        p = te.replace(base(terrain, jnp.float64), **changes)
        a = channels(run(p, rows, dtype=jnp.float64))
        b = channels(run(p, [[t, vr, vl] for t, vl, vr in rows], dtype=jnp.float64))
    pairs = [("x", 1, "x"), ("y", -1, "y"), ("heading", -1, "heading"), ("yaw_rate", -1, "yaw_rate"),
             ("u", 1, "u"), ("v", -1, "v"), ("i_left", 1, "i_right"), ("omega_left", 1, "omega_right")]
    for ka, sign, kb in pairs:
        scale = np.max(np.abs(a[ka]))
        err = np.max(np.abs(a[ka] - sign * b[kb]))
        tol = 1e-2 if terrain == "dry_sand" else 5e-2
        assert err < tol * scale + 1e-9, (ka, err, scale, changes, rows)


@settings(max_examples=budget(0.5))
@given(data=st.data(), terrain=TERRAINS)
def test_determinism_bit_identical(data, terrain):
    changes = data.draw(param_changes(terrain))
    rows = data.draw(profiles())
    p = te.replace(base(terrain), **changes)
    a, b = run(p, rows), run(te.replace(base(terrain), **changes), [list(r) for r in rows])
    for x, y in zip(jax.tree.leaves(a.state) + list(a.channels.values()),
                    jax.tree.leaves(b.state) + list(b.channels.values())):
        assert np.array_equal(np.asarray(x), np.asarray(y)), "two runs of the same inputs differ"


LOSSES = ("copper", "friction", "internal", "shear_slip", "compaction", "external")


@settings(max_examples=budget(0.5))
@given(data=st.data(), terrain=TERRAINS)
def test_energy_balance(data, terrain):
    """float64, 1 ms output: int V i dt = losses - conversion + Delta stored, within 0.5 %."""
    changes = data.draw(param_changes(terrain))
    rows = data.draw(profiles(t_end=1.5))
    with jax.enable_x64(True):
        p = te.replace(base(terrain, jnp.float64), **changes)
        traj = run(p, rows, t_end=1.5, dt=0.001, substep=0.001, dtype=jnp.float64)
        assert not bool(np.asarray(traj.diverged))
        pb = _power(traj.state, traj.voltage, p)
    pb = {k: np.asarray(v, np.float64) for k, v in pb._asdict().items()}
    t = np.asarray(traj.t, np.float64)
    e = {k: np.trapezoid(v, t) for k, v in pb.items() if k != "stored"}
    e["delta_stored"] = pb["stored"][-1] - pb["stored"][0]
    hypothesis.assume(e["electrical"] > 5.0)  # J: a maneuver that moves (not a near-zero profile)
    rhs = sum(e[k] for k in LOSSES) - e["conversion"] + e["delta_stored"]
    err = (e["electrical"] - rhs) / e["electrical"]
    # the project's bound (tests/test_energy.py: < 1 %); the thorough profile found 0.53 % for a 10 V pulse
    # on one track followed by stick-slip at rest on asphalt (1 ms steps through the chatter)
    assert abs(err) < 1e-2, (err, changes, rows)


@jax.jit
def _power(states, volts, p):
    return jax.vmap(lambda s, v: power_balance(s, v, p))(states, volts)


def _steady_module():
    spec = importlib.util.spec_from_file_location("_steady_state_reference", HERE / "test_steady_state.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


_REF = _steady_module()
_FSOLVE = _REF.fsolve


def _fsolve_restarts(fun, x0, **kw):
    """The reference's own fsolve, restarted from other slip guesses when it makes no progress (it starts at
    a slip of 1 cm/s, which fails e.g. for c = 0, phi = 29 deg at 8 V); the first converged root is taken."""
    out = None
    for s0 in (x0[2], 0.003, 0.03, 0.1, 0.3):
        out = _FSOLVE(fun, [x0[0], x0[1], s0], **kw)
        if out[2] == 1 and out[0][2] > 1e-3:
            return out
    return out


_REF.fsolve = _fsolve_restarts
_RAW = {kind: {name: _REF.raw_config(kind, name)} for kind, name in (("vehicle", "packbot"), ("terrain", "dry_sand"))}


@settings(max_examples=budget(0.5))
@given(data=st.data(), volts=st.floats(8.0, 22.0))
def test_app_d_steady_state(data, volts):
    """Straight run at constant voltage on sand, drawn parameters: speed, omega, currents within 0.5 %."""
    changes = data.draw(param_changes("dry_sand"))
    veh = dict(_RAW["vehicle"]["packbot"], mass=changes["vehicle.mass"])
    ter = dict(_RAW["terrain"]["dry_sand"], cohesion=changes["terrain.cohesion"],
               friction_angle=math.degrees(changes["terrain.friction_angle"]),
               shear_modulus=changes["terrain.shear_modulus"], sinkage_exponent=changes["terrain.sinkage_exponent"],
               k_phi=changes["terrain.k_phi"], internal_resistance_constant=changes["internal.constant"])
    raw = {"vehicle": veh, "terrain": ter}
    original = _REF.raw_config
    _REF.raw_config = lambda kind, name: raw[kind]
    try:
        ref = _REF.reference_steady_state("dry_sand", "constant", volts)
    finally:
        _REF.raw_config = original
    t_end = 8.0
    traj = run(te.replace(base("dry_sand"), **changes), [[0.0, 0.0, 0.0], [0.3, volts, volts], [t_end, volts, volts]],
               t_end=t_end)
    ch = channels(traj)
    last = np.asarray(traj.t) >= t_end - 1.0 - 1e-6
    mean = {k: float(np.mean(v[last])) for k, v in ch.items()}
    assert np.ptp(ch["speed_ideal"][last]) < 1e-3 * abs(mean["speed_ideal"]), "not steady"
    for key, want in (("speed_ideal", ref["speed_ideal"]), ("omega_left", ref["omega"]), ("i_left", ref["current"]),
                      ("i_right", ref["current"]), ("u", ref["u"])):
        assert mean[key] == pytest.approx(want, rel=5e-3), (key, mean[key], want, changes, volts)
    assert abs(mean["yaw_rate"]) < 1e-5
