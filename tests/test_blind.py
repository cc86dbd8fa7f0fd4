"""The blind-case generator (trackenv.diagnose.blind): the alternative force laws against hand-computed values,
random maneuvers within their bounds, valid §9 case folders with no label leaked, balanced labels, and every
non-null case's effect visible above the noise against an independent effect-free simulation."""

from __future__ import annotations

import dataclasses
import json
import math
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.diagnose import blind
from trackenv.effects import EFFECT_IDS
from trackenv.fieldlog import read_field_log
from trackenv.physics import contact
from trackenv.physics.model import Context, initial_state

f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731


# ---------------------------------------------------------------------------------------------- force laws


def test_slip_sinkage_laws():
    e = blind.BlindSlipSinkage(f32(0.01), f32(1.0), f32(1.0), f32(1.0))
    # Lyasko: (1 + i)/(1 - 0.5 i) - 1
    np.testing.assert_allclose(e.lyasko(jnp.array([0.0, 0.5, 1.0])), [0.0, 1.0, 3.0], rtol=1e-6)
    p = te.load_params("dry_sand")
    k = 990.0 / 0.0762 + 1528e3
    n = 1.1
    z0 = (18.144 * 9.81 / (2 * 0.0762 * 0.508) / k) ** (1 / n)
    assert float(e.static_sinkage(p)) == pytest.approx(z0, rel=1e-4)
    z = 0.02
    expected = 0.0762 * k * ((z0 + z) ** (n + 1) - z0 ** (n + 1)) / (n + 1)  # Bekker R_c of the extra sinkage
    assert float(e.resistance(p, jnp.array([z, 0.0]))[0]) == pytest.approx(expected, rel=1e-4)
    assert float(e.resistance(p, jnp.array([z, 0.0]))[1]) == 0.0


def _ctx(terrain, effect, vel, omega):
    p = te.load_params(terrain, effects=(effect,))
    s = initial_state(p, (), vel=vel)
    s = s.__class__(s.pose, s.vel, jnp.asarray(omega, jnp.float32), s.current, s.jz, s.jx, s.extra)
    kin = contact.kinematics(p.vehicle, p.terrain, s.vel, s.omega, 0)
    return p, s, Context(p, s, jnp.zeros(2), kin, 0)


def _forces(ctx, seed=0):
    """Arbitrary contact forces of the right shapes (the hooks' input)."""
    r = np.random.default_rng(seed)
    el = lambda: jnp.asarray(r.uniform(1.0, 20.0, (2, 14)), jnp.float32)  # noqa: E731
    z = jnp.zeros(())
    return contact.ContactForces(el(), el(), el() - 10.0, jnp.asarray([-3.0, -4.0]), z, z, z, jnp.zeros(2))


def test_slip_sinkage_rate_and_terrain_gate():
    e = blind.BlindSlipSinkage(f32(0.01), f32(2.0), f32(1.0), f32(1.0))
    # straight, belt 1 m/s, ground 0.8 m/s: slip ratio 0.2, no lateral sliding
    omega = 1.0 / 0.0889
    p, s, ctx = _ctx("dry_sand", e, [0.8, 0.0, 0.0], [omega, omega])
    i = float(e.slip_ratio(ctx.kin)[0])
    assert i == pytest.approx(0.2, abs=2e-3)
    rate = e.state_rate(ctx, None)
    assert float(rate[0]) == pytest.approx(0.01 * (1.2 / 0.9 - 1.0) / 2.0, rel=2e-2)  # z_t / τ from z = 0
    p2, s2, ctx2 = _ctx("asphalt", e, [0.8, 0.0, 0.0], [omega, omega])
    assert float(jnp.abs(e.state_rate(ctx2, None)).max()) == 0.0  # deformable terrain only


def test_lateral_friction_coefficient():
    e = blind.BlindLateralFriction(f32(0.8), f32(0.2), f32(0.5))
    r = jnp.array([0.0, 0.5, 1.0, 100.0])
    expected = [0.8, 0.2 + 0.6 / math.e, 0.2 + 0.6 / math.e**2, 0.2]
    np.testing.assert_allclose(e.coefficient(r), expected, rtol=1e-5)
    # radius from speeds: |(u, v)| / sqrt(r² + r_eps²)
    assert float(e.turning_radius(jnp.array([1.0, 0.0, 2.0]))) == pytest.approx(1 / math.sqrt(4 + 1e-4), rel=1e-5)
    # the forces replace the lateral shear forces: -μ F_n tanh(v_y / v_s)
    p, s, ctx = _ctx("asphalt", e, [0.0, 0.0, 1.0], [0.0, 0.0])
    f = _forces(ctx)
    out, _ = e.forces(ctx, f, None)
    mu = 0.8  # R = 0 in a turn on the spot
    exp_lat = -mu * f.normal * np.tanh(np.asarray(ctx.kin.lateral_velocity) / 0.02)
    np.testing.assert_allclose(out.lateral, exp_lat, rtol=1e-5, atol=1e-5)
    off = blind.BlindLateralFriction(f32(0.8), f32(0.2), f32(0.5), gate=f32(0.0))  # batching gate: base forces
    np.testing.assert_allclose(off.forces(ctx, f, None)[0].lateral, f.lateral)


def test_internal_resistance_torque():
    e = blind.BlindInternalResistance(f32(0.6), f32(1.0), f32(2e-3))
    w = jnp.array([-20.0, -1.0, 0.0, 1.0, 20.0])
    expected = [-0.6 * math.tanh(20) - 0.8, -0.6 * math.tanh(1) - 2e-3, 0.0, 0.6 * math.tanh(1) + 2e-3,
                0.6 * math.tanh(20) + 0.8]
    np.testing.assert_allclose(e.torque(w), expected, rtol=1e-5)
    off = blind.BlindInternalResistance(f32(0.6), f32(1.0), f32(2e-3), gate=f32(0.0))
    ctx = SimpleNamespace(state=SimpleNamespace(omega=jnp.asarray([1.0, -20.0])))
    np.testing.assert_allclose(e.forces(ctx, None, jnp.zeros(2))[1], [expected[3], expected[0]], rtol=1e-5)
    np.testing.assert_allclose(off.forces(ctx, None, jnp.asarray([0.7, -0.7]))[1], [0.7, -0.7])  # batching gate


def test_grouser_stribeck_factor():
    e = blind.BlindGrouserStiction(f32(0.8), f32(0.2))
    v = jnp.array([0.0, 0.2, 0.4, 2.0])
    np.testing.assert_allclose(e.factor(v), [1.8, 1 + 0.8 / math.e, 1 + 0.8 * math.exp(-4), 1.0], rtol=1e-5)
    np.testing.assert_allclose(e.factor(v, 0.0), 1.0)  # deformable ground: no stiction
    # hook: lateral forces scaled on asphalt, untouched on sand
    for terrain, hard in (("asphalt", 1.0), ("dry_sand", 0.0)):
        p, s, ctx = _ctx(terrain, e, [0.0, 0.0, 0.5], [0.0, 0.0])
        f = _forces(ctx)
        out, _ = e.forces(ctx, f, None)
        np.testing.assert_allclose(out.lateral, f.lateral * e.factor(ctx.kin.lateral_velocity, hard), rtol=1e-6)


def test_pitch_weights_and_rate():
    e = blind.BlindPitchLoadTransfer(f32(2.0), f32(0.3), f32(2.0), f32(3.0))
    p, s, ctx = _ctx("dry_sand", e, [0.0, 0.0, 0.0], [0.0, 0.0])
    w = e.weights(ctx.kin, p.vehicle.contact_length)
    x = ctx.kin.x
    assert float(2 * (w * x).sum()) == pytest.approx(1.0, rel=1e-5)  # Σ_k,i w_i x_i = 1: moment M
    assert abs(float(w.sum())) < 1e-6  # no net vertical force
    # q = 3: end elements carry (L/2)^3 / (L/2 - Δ)^3 times the weight per area of the next ones
    a = np.asarray(ctx.kin.area)[0]
    ratio = (w[0, 0] / a[0]) / (w[0, 1] / a[1])
    assert float(ratio) == pytest.approx((0.254 / (0.254 - 0.508 / 13)) ** 3, rel=1e-4)
    # rate: d²M/dt² = ω²(M_ss - M) - 2ζω dM/dt with M_ss = -κ h Σ F_x
    forces = _forces(ctx)._replace(body_x=f32(10.0))
    st = s.__class__(s.pose, s.vel, s.omega, s.current, s.jz, s.jx, {e.id: jnp.array([1.0, 2.0])})
    ctx = ctx._replace(state=st)
    rate = e.state_rate(ctx, forces)
    fx = float(forces.longitudinal.sum() + forces.compaction.sum()) + 10.0
    om = 2 * math.pi * 2.0
    target = -2.0 * 0.08 * fx
    np.testing.assert_allclose(rate, [2.0, om**2 * (target - 1.0) - 2 * 0.3 * om * 2.0], rtol=1e-4)


def test_sensor_low_pass_step_and_gyro_ammeter():
    tau, dt = 0.3, 0.02
    t = jnp.arange(0, 2.0, dt)
    x = jnp.where(t > 0.0, 1.0, 0.0)  # step at the first sample after t = 0
    y = blind.BlindSensorArtifacts.low_pass(t, x, tau)
    np.testing.assert_allclose(y, 1.0 - np.exp(-np.asarray(t) / tau), atol=2e-5)
    np.testing.assert_allclose(blind.BlindSensorArtifacts.low_pass(t, x, 0.0), x)  # τ = 0: off
    e = blind.BlindSensorArtifacts(f32(0.0), f32(0.05), f32(0.1), f32(0.3), f32(-0.2))
    ones = jnp.ones(t.shape)
    ch = {"speed_ideal": x, "yaw_rate": 2.0 * ones, "i_left": ones, "i_right": ones}
    out = e.instruments(ch, t, None)
    np.testing.assert_allclose(out["yaw_rate"], 1.1 * 2.0 + 0.05, rtol=1e-6)
    np.testing.assert_allclose(out["i_left"], 1.3, rtol=1e-6)
    np.testing.assert_allclose(out["i_right"], 0.8, rtol=1e-6)
    np.testing.assert_allclose(out["speed_ideal"], x)


def test_effect_ids_and_labels_differ_from_library():
    assert set(blind.BLIND_EFFECTS) == set(EFFECT_IDS)
    for label, cls in blind.BLIND_EFFECTS.items():
        assert cls.label == label and cls.id != label and cls.id.startswith("blind_")
        e = cls.sample(np.random.default_rng(0), "asphalt" if label == "grouser_stiction" else "dry_sand")
        assert all(np.isfinite(v) for v in blind.effect_params(e).values())


# ---------------------------------------------------------------------------------------------- maneuvers


@pytest.mark.parametrize("maneuver", blind.MANEUVERS)
def test_random_profile_bounds(maneuver):
    rng = np.random.default_rng(1)
    for k in range(40):
        rate = [20, 50, 100][k % 3]
        t, v = blind.random_profile(rng, maneuver, grid=1.0 / rate)
        assert v.shape == (t.size, 2) and np.all(np.diff(t) > 0)
        assert 4.0 - 1e-9 <= t[-1] <= blind.T_SIM + 1e-9
        assert np.abs(v).max() <= 22.0 + 1e-9
        assert np.all(v[0] == 0) and np.all(v[-1] == 0) and np.all(v[-2] == 0)  # rest, release, coast
        np.testing.assert_allclose(t * rate, np.round(t * rate), atol=1e-6)  # on the sample grid
        if maneuver == "zero_radius_turn":
            assert np.allclose(v[:, 0], -v[:, 1]) and 6.0 <= np.abs(v).max() <= 16.0
        if maneuver == "go_stop":
            assert np.allclose(v[:, 0], v[:, 1]) and 5.0 <= np.abs(v).max()
        if maneuver in ("j_turn", "lane_change", "step_steer"):
            assert np.abs(v[:, 0] - v[:, 1]).max() >= 3.0 - 1e-9
        if maneuver == "accel_steps":
            assert np.allclose(v[:, 0], v[:, 1]) and len(set(np.round(np.abs(v[:, 0]), 6)) - {0.0}) >= 2


def test_balanced_labels():
    rng = np.random.default_rng(0)
    for n, frac in ((70, 0.2), (60, 0.1), (12, 0.0)):
        labels = blind.balanced_labels(n, rng, frac)
        assert len(labels) == n
        counts = {lab: labels.count(lab) for lab in blind.LABELS}
        assert counts["none"] >= n / 6 - 1e-9 and counts["none"] >= round(n * frac)
        ids = [counts[lab] for lab in blind.CANONICAL_IDS]
        assert max(ids) - min(ids) <= 1


# ---------------------------------------------------------------------------------------------- cases


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """Seven cases (each label once). To keep this test fast the simulated span is cut from 15 s to 5 s (profiles
    are shortened to fit) and cases hold 3 tests; everything else is as in production."""
    out = tmp_path_factory.mktemp("blind")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(blind, "T_SIM", 5.0)
        mp.setattr(blind, "MAX_TESTS", 3)  # 3 tests per case: batches of 6 vehicles
        mp.setattr(blind, "N_COLS", 6)
        answers = blind.make_cases(out, n=7, seed=3)
        yield out, answers


def _folded_mean(mu, sigma):
    """E|X| for X ~ N(mu, sigma²) (the absolute ammeter's expected reading)."""
    from scipy.stats import norm

    return sigma * np.sqrt(2 / np.pi) * np.exp(-mu**2 / (2 * sigma**2)) + mu * (1 - 2 * norm.cdf(-mu / sigma))


def test_cases_valid_and_no_label_leaked(bench):
    out, answers = bench
    assert sorted(a["label"] for a in answers) == sorted(blind.LABELS)  # n = 7: each label once
    key = json.loads((out / "answers.json").read_text())
    assert [a["label"] for a in key] == [a["label"] for a in answers]
    forbidden = set(blind.CANONICAL_IDS) | {c.id for c in blind.BLIND_EFFECTS.values()} | {
        "sinkage", "stiction", "friction", "pitch", "artifact", "label", "effect\""}
    for a in answers:
        case = out / "cases" / a["case"]
        folders = sorted(p for p in case.iterdir())
        assert 3 <= len(folders) <= 6 and all(p.is_dir() for p in folders)
        mans = [t["maneuver"] for t in a["tests"]]
        assert set(mans) & set(blind.TURNING)
        if a["label"] in ("slip_sinkage", "grouser_stiction"):
            assert {"zero_radius_turn", "random_steer"} & set(mans)
        if a["label"] == "slip_sinkage":
            assert a["terrain"] in blind.DEFORMABLE_TERRAINS
        if a["label"] == "grouser_stiction":
            assert a["terrain"] in blind.HARD_TERRAINS
        for folder, tst in zip(folders, a["tests"]):
            assert sorted(p.name for p in folder.iterdir()) == ["log.csv", "meta.json"]
            log = read_field_log(folder)
            assert log.synthetic and "SYNTHETIC" in log.meta["notes"]
            assert log.meta["maneuver"] == tst["maneuver"] and log.terrain == a["terrain"]
            assert log.current_sensor == a["nuisance"]["current_sensor"]
            assert np.allclose(np.diff(log.t), 1.0 / tst["sample_rate_hz"])
            text = (folder / "meta.json").read_text().lower()
            assert not any(w in text for w in forbidden), text
            assert set(log.meta) <= {"terrain", "maneuver", "current_sensor", "vehicle", "synthetic", "sample_rate_hz",
                                     "notes"}
            assert ("x" in log.data.columns) == tst["pose"]
            # logged voltages reproduce the breakpoint profile exactly (breakpoints on the sample grid)
            bp = np.asarray(tst["breakpoints"])
            np.testing.assert_allclose(log.volts[:, 0], np.interp(log.t, bp[:, 0], bp[:, 1]), atol=1e-5)
        if a["label"] == "none":
            assert a["effect"] is None and a["params"] == {}
        else:
            assert a["effect"] == blind.BLIND_EFFECTS[a["label"]].id and a["visible"]


def test_effects_visible_against_effect_free_replay(bench):
    """Residual of the written (noisy) logs against an effect-free simulation with the case's nuisance parameters:
    above the noise for every effect case, at the noise level for the null case. Compared while driven (up to the
    end of the release ramp): the base model's coast to rest after a turn is too sensitive to compare."""
    out, answers = bench
    stats = {}
    for pair in (answers[k:k + 2] for k in range(0, len(answers), 2)):  # two cases per batch
        columns, profiles = [], []
        for a in pair + pair[:1] * (2 - len(pair)):
            prof = [(np.asarray(t["breakpoints"])[:, 0], np.asarray(t["breakpoints"])[:, 1:]) for t in a["tests"]]
            columns += [(a["terrain"], a["nuisance"]["params"], None)] * blind.MAX_TESTS
            profiles += [prof[j % len(prof)] for j in range(blind.MAX_TESTS)]
        ch2, div = blind._simulate_columns(columns, profiles)  # effect-free, independent of the generator's run
        assert not div.any()
        for h, a in enumerate(pair):
            ch = blind._half(ch2, h)
            nz = a["nuisance"]
            best = 0.0
            for j, tst in enumerate(a["tests"]):
                log = read_field_log(out / "cases" / a["case"] / tst["name"])
                idx = np.round(log.t / blind.SIM_DT).astype(int)
                w = max(1, int(round(0.25 * tst["sample_rate_hz"])))
                for s in blind.SIGNALS:
                    sig = nz["noise_std"][s]
                    ref = ch[s][idx, j]
                    if s.startswith("i_") and nz["current_sensor"] == "absolute":
                        ref = _folded_mean(ref, sig)
                    res = np.nan_to_num(log.data[s].to_numpy() - ref)[log.t <= tst["drive_end"] + 1e-9]
                    ma = np.convolve(res, np.ones(w) / w, mode="valid")
                    best = max(best, float(np.abs(ma).max() / sig))
            stats[a["label"]] = best
    for label, v in stats.items():
        if label == "none":
            assert v < 3.0, stats
        else:
            assert v > 3.0, stats


# ---------------------------------------------------------------------------------------------- near the limit


def test_scaled_multiplies_the_amplitude_only():
    rng = np.random.default_rng(5)
    for cls in blind.BLIND_EFFECTS.values():
        e = cls.sample(rng)
        half = blind.scaled(e, 0.5)
        for name in (f.name for f in dataclasses.fields(e)):
            a, b = float(getattr(e, name)), float(getattr(half, name))
            if name in cls.AMPLITUDE:
                assert b == pytest.approx(0.5 * a, rel=1e-6), (cls.__name__, name)
                assert float(getattr(cls.neutral(), name)) == 0.0  # an amplitude is what neutral() sets to 0
            else:
                assert b == a, (cls.__name__, name)
    gated = blind.BlindInternalResistance.sample(rng)
    assert float(blind.scaled(gated, 3.0).gate) == 1.0  # a blend of two laws stops at the alternative law


def test_near_limit_case_is_scaled_into_the_window(tmp_path):
    """The 40-case benchmark's case_000 (seed 0): the closest of 7 draws of the lateral-friction law shows 30 sigma;
    scaled (its gate, the blend with the base law), the case lands in the 1-3 sigma window."""
    truth = blind.make_case(tmp_path / "c", np.random.default_rng([0, 0]), label="lateral_friction_radius", n_tests=2,
                            t_max=6.0, near_limit=True)
    assert truth["near_limit"] and truth["magnitude_scale"] < 0.5
    assert blind.NEAR_LIMIT[0] <= truth["max_visibility"] <= blind.NEAR_LIMIT[1]
    assert min(truth["mobility"]) >= blind.MOBILITY_MIN
