"""Sim-to-real gap diagnosis (trackenv.diagnose): phases, noise, bad input, folds, and verdicts that
could fail — an effect found where the SYNTHETIC field twin has one, ``none`` where the logs are the
base model plus noise."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

import trackenv as te
from trackenv.diagnose import DiagnosisError, candidate_set, diagnose
from trackenv.diagnose.candidates import effect_of
from trackenv.diagnose.data import load_tests, noise_level
from trackenv.diagnose.fit import heldout_mask, make_folds
from trackenv.diagnose.phases import phase_spans, segment_phases
from trackenv.diagnose.stats import (
    ar1_form,
    centred_interval,
    gap_test,
    max_t_pvalue,
    noise_ar1,
    paired_test,
)
from trackenv.fieldlog import write_log_columns

TWIN = te.__file__.rsplit("/", 2)[0] + "/data/field/thesis"


def test_phases_from_voltages():
    t = np.arange(0, 10.001, 0.02)
    rows = [[0, 0, 0], [0.5, 0, 0], [0.8, 12, 12], [3, 12, 12], [3.2, 7, 17], [5, 7, 17], [5.3, 0, 0], [10, 0, 0]]
    rows = np.array(rows, float)
    volts = np.stack([np.interp(t, rows[:, 0], rows[:, 1]), np.interp(t, rows[:, 0], rows[:, 2])], 1)
    spans = [p for p, a, b in phase_spans(t, segment_phases(t, volts))]
    assert spans == ["idle", "ramp", "cruise", "ramp", "turn", "brake", "coast"]
    # zero-radius spin (V_l = -V_r) is a turn
    v = np.stack([np.full_like(t, -12.0), np.full_like(t, 12.0)], 1)
    assert set(segment_phases(t, v)) == {"turn"}


def test_noise_level_is_robust_to_the_signal():
    rng = np.random.default_rng(0)
    t = np.arange(0, 10, 0.02)
    sig = np.clip(t, 0, 1) * 2.0 + 0.3 * np.sin(t)  # ramp + slow wave
    est = noise_level(sig + rng.normal(0, 0.05, t.size))
    assert est == pytest.approx(0.05, rel=0.15)


def test_folds_hold_out_repeated_tests_and_forward_chain_unique_ones():
    tests, _ = load_tests(TWIN, ["go_stop_dry_sand", "go_stop_2ms_dry_sand", "zero_radius_turn_dry_sand"])
    # the 1.1 m/s and 2 m/s go-stops are the same maneuver at different operating points: not repeats
    assert {f.kind for f in make_folds(tests)} == {"forward"}
    import copy

    rep = copy.copy(next(t for t in tests if t.name == "go_stop_dry_sand"))
    rep.name = "go_stop_again"
    tests = tests + [rep]
    folds = make_folds(tests)
    kinds = {tests[f.held].name: f.kind for f in folds}
    assert kinds == {"go_stop_dry_sand": "test", "go_stop_again": "test", "go_stop_2ms_dry_sand": "forward",
                     "zero_radius_turn_dry_sand": "forward"}
    for f in folds:
        assert f.weights.shape == (4, 2)
        if f.kind == "test":
            assert np.all(f.weights[f.held] == 0)  # nothing of the held-out test in the calibration
        else:  # head fitted, tail predicted
            assert tuple(f.weights[f.held]) == (1.0, 0.0)
            mask = heldout_mask(tests[f.held], f)
            t = tests[f.held].t
            assert mask.any() and t[mask].min() > t[tests[f.held].fit_mask & ~mask].max()
    single = make_folds(tests[:1])
    assert len(single) == 1 and single[0].kind == "forward"


def test_candidate_anchors_reproduce_the_base_model():
    """Every candidate contains the base model (so a fit can only improve on ``none`` in-sample)."""
    from trackenv.diagnose.batch import BatchSimulator

    tests, _ = load_tests(TWIN, ["go_stop_dry_sand", "j_turn_asphalt"])
    sim = BatchSimulator(tests)
    base, _ = sim.run(candidate_set()[-1], {})
    for cand in candidate_set():
        if cand.name in ("none", "slip_sinkage"):
            continue  # no exactly neutral point (tiny but non-zero values)
        pred, div = sim.run(cand, cand.physical(cand.anchor_unit()[None]))
        assert not div.any()
        for j in range(len(tests)):
            # Compared until 0.2 s after the voltages reach zero, as in the convergence test: once a turned
            # vehicle has stopped on asphalt the tracks chatter in stick-slip around zero speed, where float32
            # rounding differences grow (README, Numerics); that phase is checked for boundedness only.
            driven = np.abs(tests[j].volts).max(axis=1) > 0.05
            window = tests[j].t <= tests[j].t[driven].max() + 0.2
            for sig in base[j]:
                # equal up to float32 rounding: RMS difference ≤ 0.2 % and largest ≤ 2 % of the signal's range
                d = pred[j][sig][:, 0] - base[j][sig][:, 0]
                span = tests[j].span[sig]
                assert np.sqrt(np.mean(d[window] ** 2)) <= 2e-3 * span + 1e-4, (cand.name, sig)
                assert np.max(np.abs(d[window])) <= 2e-2 * span + 1e-4, (cand.name, sig)
                assert np.all(np.abs(d[~window]) <= 0.25 * span), (cand.name, sig)


def test_tests_of_different_lengths_share_a_padded_batch_with_the_same_predictions(monkeypatch):
    """A 5 s test is padded into the batch of a 10 s one (``BUCKET_FILL`` = 0.5: one batch, the cheaper
    layout), or given its own batch with a stricter rule; the base model's predictions at the logs' samples
    are the same either way (float32 rounding, driven window)."""
    from trackenv.diagnose import batch

    tests, _ = load_tests(TWIN, ["go_stop_dry_sand", "lane_change_dry_sand"])
    shared = batch.BatchSimulator(tests)
    assert len(shared.buckets) == 1 and shared.buckets[0].n_steps * shared.buckets[0].dt == pytest.approx(10.0, abs=0.05)
    monkeypatch.setattr(batch, "BUCKET_FILL", 0.75)
    split = batch.BatchSimulator(tests)
    assert sorted(b.n_steps * b.dt for b in split.buckets) == pytest.approx([5.0, 10.0], abs=0.05)
    none = candidate_set()[-1]
    a, _ = split.run(none, {})
    b, _ = shared.run(none, {})
    for j, t in enumerate(tests):
        driven = np.abs(t.volts).max(axis=1) > 0.05
        window = t.t <= t.t[driven].max() + 0.2
        for sig in a[j]:
            d = (a[j][sig][:, 0] - b[j][sig][:, 0])[window]
            assert np.max(np.abs(d)) <= 1e-3 * t.span[sig] + 1e-5, (t.name, sig)


def test_a_log_range_with_a_knee_starts_at_zero_and_maps_back():
    """A parameter fitted on a logarithmic scale whose range starts at zero (``ParamSpec.knee``): u = 0 is exactly
    zero, u = 1 the upper bound, values well above the knee are spaced logarithmically, the map and its inverse
    agree, and the jax form (the polish's) gives the numpy form's values."""
    import jax.numpy as jnp

    from trackenv.diagnose.candidates import ParamSpec

    spec = ParamSpec("yaw_moment", 0.0, 30.0, True, "N m", knee=0.5)
    u = np.linspace(0.0, 1.0, 41)
    x = spec.to_physical(u)
    assert x[0] == 0.0 and x[-1] == pytest.approx(30.0, rel=1e-12)
    assert np.all(np.diff(x) > 0)
    np.testing.assert_allclose(spec.to_unit(x), u, atol=1e-12)
    np.testing.assert_allclose(np.asarray(spec.to_physical_jnp(jnp.asarray(u, jnp.float32))), x, rtol=2e-6, atol=1e-7)
    # far above the knee a step in u multiplies the value by a constant factor, as on a log scale
    big = x[x > 10 * spec.knee]
    ratios = big[1:] / big[:-1]
    assert ratios.max() / ratios.min() < 1.05
    with pytest.raises(ValueError, match="knee"):
        ParamSpec("bad", 0.0, 1.0, False, knee=0.1)
    # the grouser family's anchor is now exactly the base model (no breakaway moment)
    grouser = {c.name: c for c in candidate_set()}["grouser_stiction"]
    assert grouser.physical(grouser.anchor_unit()[None])["yaw_moment"][0] == 0.0


def test_an_effect_on_the_control_contains_the_fitted_control():
    """An effect fitted on top of ``recalibrate_base`` (:meth:`Candidate.standing_on`) reproduces the control
    at its anchor, whatever the control's fitted factors: through the batched search (simulated effects, among
    them the lateral law whose anchor blends it out, the internal-resistance family whose anchor absorbs the
    factor on b*_int, and the instruments-only candidate)
    and through the polish's residuals."""
    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.candidates import ON
    from trackenv.diagnose.fit import full_fold
    from trackenv.diagnose.polish import polish_folds

    tests, _ = load_tests(TWIN, ["go_stop_dry_sand", "j_turn_asphalt"])
    sim = BatchSimulator(tests)
    cands = {c.name: c for c in candidate_set()}
    recal = cands["recalibrate_base"]
    fitted = {"internal_resistance_factor": 1.3, "cohesion_factor": 0.7, "friction_angle_factor": 1.05,
              "shear_modulus_factor": 1.6}
    ctrl, _ = sim.run(recal, {k: np.array([v]) for k, v in fitted.items()})
    base, _ = sim.run(cands["none"], {})
    for name in ("pitch_load_transfer", "internal_resistance", "sensor_artifacts", "lateral_friction_radius",
                 "grouser_stiction"):
        cand = cands[name].standing_on(recal)
        vals = cand.physical(cand.anchor_unit(fitted)[None]) | {ON + k: np.array([v]) for k, v in fitted.items()}
        pred, div = sim.run(cand, vals)
        assert not div.any()
        for j, t in enumerate(tests):
            for sig in ctrl[j]:
                span = t.span[sig]
                d = pred[j][sig][:, 0] - ctrl[j][sig][:, 0]
                assert np.sqrt(np.mean(d**2)) <= 5e-3 * span + 1e-4, (name, sig)
            # and the control's factors matter: the prediction is not the unfitted base model's
            moved = max(np.sqrt(np.mean((pred[j][s][:, 0] - base[j][s][:, 0]) ** 2)) / t.span[s] for s in ctrl[j])
            assert moved > 0.01, name
    fd = full_fold(tests)
    on_recal = cands["sensor_artifacts"].standing_on(recal)
    start = {}
    for cand, unit, below in ((recal, np.array([s.to_unit(fitted[s.name]) for s in recal.specs]), None),
                              (on_recal, on_recal.anchor_unit(fitted), [fitted])):
        res = polish_folds(sim, cand, [fd], [unit], [None], [np.inf], iters=0, below=below)
        start[cand.name] = res["info"][0]["start_loss"]
    assert start["sensor_artifacts"] == pytest.approx(start["recalibrate_base"], rel=0.02), start


def test_gap_test_detects_a_small_systematic_bias_and_passes_pure_noise():
    """A 0.1 A bias under 0.05 A noise over 3000 samples is a 2-sigma-per-sample, systematic gap: z >> 3.
    Pure white or AR(1) noise is not flagged at the 5 % level more often than 5 % of the time."""
    rng = np.random.default_rng(0)
    e = rng.normal(0, 0.05, 3000)
    sigma, rho = noise_ar1(np.linspace(0, 3, 3000) + e)  # a ramp: the differences see the noise only
    assert sigma == pytest.approx(0.05, rel=0.1) and rho < 0.1
    z, p = gap_test(e + 0.1, sigma, rho)
    assert z > 30 and p < 1e-10
    z_small, p_small = gap_test(e + 0.02, sigma, rho)  # 0.4 sigma per sample, still systematic: detected
    assert p_small < 0.05
    false = 0
    for k in range(200):
        w = rng.normal(0, 1, 1001)
        x = np.empty_like(w)
        x[0] = w[0]
        phi = 0.6 if k % 2 else 0.0
        for i in range(1, len(w)):
            x[i] = phi * x[i - 1] + w[i] * np.sqrt(1 - phi**2)
        s_hat, r_hat = noise_ar1(x)
        false += gap_test(x, s_hat, r_hat)[1] < 0.05
    assert false / 200 <= 0.05


def _ar1(rng, n, rho, sigma):
    w = rng.normal(0.0, sigma * np.sqrt(1 - rho**2), n)
    x = np.empty(n)
    x[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        x[i] = rho * x[i - 1] + w[i]
    return x


def test_ar1_form_matches_the_dense_correlation_matrix():
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=50), rng.normal(size=50)
    for rho in (0.0, 0.4, 0.9):
        R = rho ** np.abs(np.subtract.outer(np.arange(50), np.arange(50)))
        assert ar1_form(x, y, rho) == pytest.approx(x @ R @ y, rel=1e-10)


def test_paired_test_controls_the_null_and_finds_a_better_model():
    """Two models equally far from the truth on average (errors of opposite sign in two halves), AR(1)
    noise: the fixed-design test rejects at about its level; a model that removes a small systematic
    bias (0.5 sigma over 1500 samples, z ≈ 4.8 expected) is found."""
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 1.0, 1500)
    bias = 0.3 * np.sin(2 * np.pi * t)
    hits = 0
    for _ in range(300):
        n = _ar1(rng, t.size, 0.6, 1.0)
        ea, eb = bias - n, -bias - n  # |e_a| and |e_b| equal in expectation
        hits += paired_test([{"x": ea}], [{"x": eb}], [{"x": (1.0, 0.6)}], [{"x": 1.0}])["p"] < 0.05
    assert hits / 300 <= 0.08
    n = _ar1(rng, t.size, 0.6, 1.0)
    better = paired_test([{"x": -n}], [{"x": 0.5 - n}], [{"x": (1.0, 0.6)}], [{"x": 1.0}])
    assert better["p"] < 1e-3 and better["diff"] > 0
    worse = paired_test([{"x": 0.5 - n}], [{"x": -n}], [{"x": (1.0, 0.6)}], [{"x": 1.0}])
    assert worse["p"] > 0.99


def _evidence(errors: dict, sigma: float = 0.1, insample: dict | None = None) -> dict:
    """Verdict evidence (:func:`trackenv.diagnose.core.evidence`'s layout) for one test, one channel of white
    noise σ, from each candidate's signed held-out errors (and in-sample errors, by default the held-out ones)."""
    w = 1.0 / sigma**2
    ws = {n: [w * e**2] for n, e in errors.items()}
    ws_full = ws if insample is None else {n: [w * e**2] for n, e in insample.items()}
    loss = {n: float(np.mean(x[0])) for n, x in ws.items()}
    return {"gap_p": 1e-10, "noise": [{"speed": (sigma, 0.0)}], "weights": [{"speed": w}],
            "err_held": {n: [{"speed": e}] for n, e in errors.items()}, "ws_held": ws, "ws_full": ws_full,
            "candidates": {n: {"heldout_loss": loss[n], "n_params": 0 if n == "none" else 3,
                               "is_effect": n not in ("none", "recalibrate_base"),
                               "heldout_gap": float(np.sqrt(max(loss[n] - 1, 0))),
                               "heldout_shrink": 1.0 - np.sqrt(max(loss[n] - 1, 0) / max(loss["none"] - 1, 1e-12))}
                           for n in errors}}


def test_the_rule_tries_the_next_effect_when_the_best_scoring_one_fails():
    """The best-scoring effect removes a short burst of error (a large loss reduction, but too concentrated in
    time to pass the Diebold-Mariano test against the control); the next one removes a small bias
    everywhere, which passes every test. The rule names the second; without it, ``none``."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(0)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    burst = np.zeros(K)
    burst[1000:1060] = 1.0
    errors = {"none": 0.1 + burst + n, "recalibrate_base": 0.1 + burst + n,
              "grouser_stiction": 0.1 + n, "internal_resistance": burst + n}
    v = decide(_evidence(errors, sigma))
    assert v["best"] == "grouser_stiction"
    assert v["effect"] == "internal_resistance", v
    # the burst alone passes the fixed-design tests but not the Diebold-Mariano test against the control
    assert v["tests"]["grouser_stiction vs recalibrate_base (Diebold-Mariano)"] >= 0.05
    del errors["internal_resistance"]
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "none" and "recalibrating" in v["reason"], v


def test_one_bifurcation_in_an_effects_prediction_does_not_decide_the_test_against_the_control():
    """The effect removes a 1-noise-σ bias on every held-out sample, but its prediction also caught one short
    oscillation of 11 σ that the control's did not (the rocking after a stop, which float rounding can switch
    on or off). On squared errors the oscillation's variance drowns the Diebold-Mariano test against the
    control (p ≈ 0.18) although the effect is better on average; on Huber losses it passes, and the effect
    is named. Without the bias to remove, the oscillation alone names nothing."""
    from trackenv.diagnose.core import decide
    from trackenv.diagnose.stats import dm_test

    rng = np.random.default_rng(3)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    rocking = np.zeros(K)
    rocking[2000:2030] = 1.1 * np.sin(np.linspace(0.0, 6.0 * np.pi, 30))
    errors = {"none": 0.1 + n, "recalibrate_base": 0.1 + n, "internal_resistance": rocking + n}
    ev = _evidence(errors, sigma)
    v = decide(ev)
    assert v["effect"] == "internal_resistance", v
    assert v["tests"]["internal_resistance vs recalibrate_base (Diebold-Mariano)"] < 1e-3
    assert dm_test(ev["ws_held"]["internal_resistance"], ev["ws_held"]["recalibrate_base"])["p"] > 0.1
    errors = {"none": n, "recalibrate_base": n, "internal_resistance": rocking + n}
    assert decide(_evidence(errors, sigma))["effect"] == "none"


def test_the_diebold_mariano_test_on_huber_losses_keeps_the_squared_losses_level():
    """Two predictions equally good on average (each off by its own AR(1) wiggle of 1 noise σ, correlation
    0.9 per sample, plus the shared noise): over 400 draws the one-sided test at α = 0.05 rejects on Huber
    losses about as often as on squared errors (8-9 %; the Newey-West variance is somewhat liberal for
    correlated differentials, with or without the Huber loss), and on white wiggles in about 5 %."""
    from scipy.signal import lfilter

    from trackenv.diagnose.core import robust_losses
    from trackenv.diagnose.stats import dm_test

    K, sigma = 1500, 0.1
    for phi, at_most in ((0.0, 0.09), (0.9, 0.12)):
        rng = np.random.default_rng(11)
        huber = squared = 0
        for _ in range(400):
            n = sigma * rng.standard_normal(K)
            a, b = (sigma * np.sqrt(1 - phi**2) * lfilter([1.0], [1.0, -phi], rng.standard_normal(K)) for _ in "ab")
            ev = {"err_held": {"a": [{"speed": a + n}], "b": [{"speed": b + n}]}, "weights": [{"speed": 1 / sigma**2}]}
            huber += dm_test(robust_losses(ev, "a"), robust_losses(ev, "b"))["p"] < 0.05
            squared += dm_test([(a + n) ** 2 / sigma**2], [(b + n) ** 2 / sigma**2])["p"] < 0.05
        assert 0.02 <= huber / 400 <= at_most, (phi, huber, squared)
        assert huber <= squared + 8, (phi, huber, squared)


def test_an_effect_on_the_base_is_named_where_its_fit_on_the_control_inherits_a_bad_extrapolation():
    """The control, fitted on a test's head, drifts away on its tail; the effect fitted on top of it inherits
    the drift and loses to the base model, while the same effect fitted on the base itself (the
    ``@base`` member) removes the bias. The rule names the effect (not the member) and reports which fit
    carried it; without the ``@base`` member, ``none``."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(2)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    drift = np.linspace(0.0, 0.6, K)
    errors = {"none": 0.1 + n, "recalibrate_base": 0.1 + drift + n, "internal_resistance": 0.05 + drift + n,
              "internal_resistance@base": 0.02 + n}
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "internal_resistance" and v["member"] == "internal_resistance@base", v
    assert v["own_shrink"] > 0.5, v
    del errors["internal_resistance@base"]
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "none" and "does not beat the base model" in v["reason"], v
    # the instruments alone, fitted on the base, explain it as well: the physical effect gives way (condition 4)
    errors["internal_resistance@base"] = 0.02 + n
    errors["sensor_artifacts@base"] = 0.02 + n
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "sensor_artifacts" and v["member"] == "sensor_artifacts@base", v


def test_an_effect_that_only_beats_a_badly_extrapolating_control_is_not_named():
    """Null case: the control's family holds the truth and fits all the data as well as the effect does, but its
    fit on a test's head drifts on the tail, so the effect beats it on the held-out samples (conditions 2-3 on
    held-out data pass). It does not fit all the data better (3b), so nothing is named. Where the effect also
    removes a bias that the control leaves in-sample, it is named."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(5)
    K, sigma = 3000, 0.1
    n, m = sigma * rng.standard_normal(K), sigma * rng.standard_normal(K)
    drift = np.linspace(0.0, 0.5, K)
    held = {"none": 0.1 + n, "recalibrate_base": drift + n, "slip_sinkage": 0.01 + n}
    tied = {"none": 0.1 + m, "recalibrate_base": 0.005 * np.sin(np.arange(K) / 50) + m, "slip_sinkage": 0.01 + m}
    v = decide(_evidence(held, sigma, insample=tied))
    assert v["tests"]["slip_sinkage vs recalibrate_base (Diebold-Mariano)"] < 0.05
    assert v["tests"]["slip_sinkage vs recalibrate_base (in-sample)"] >= 0.05
    assert v["effect"] == "none" and "does not fit all the data better" in v["reason"], v
    better = {**tied, "recalibrate_base": 0.05 + m}
    v = decide(_evidence(held, sigma, insample=better))
    assert v["effect"] == "slip_sinkage", v
    assert v["tests"]["slip_sinkage vs recalibrate_base (in-sample)"] < 1e-3


def test_a_physical_effect_that_predicts_better_does_not_hand_the_verdict_to_the_instruments():
    """A physical effect and the instruments alone remove the same bias; the instruments' prediction also
    carries a small zero-mean wiggle, so it scores worse, yet the paired test cannot separate the two. Neither
    is named (condition 4: the data do not separate them). With the wiggle on the physical effect instead,
    the instruments alone predict at least as well and are named."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(3)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    wiggle = 0.002 * np.where(np.arange(K) % 2 == 0, 1.0, -1.0)
    errors = {"none": 0.1 + n, "recalibrate_base": 0.1 + n, "internal_resistance": 0.02 + n,
              "sensor_artifacts": 0.02 + wiggle + n}
    v = decide(_evidence(errors, sigma))
    assert v["tests"]["internal_resistance vs sensor_artifacts"] >= 0.05  # not separated ...
    assert v["tests"]["sensor_artifacts vs none"] < 0.05  # ... though the instruments alone pass (2)-(3)
    assert v["best"] == "internal_resistance"
    assert v["effect"] == "none" and "do not separate" in v["reason"], v
    errors["internal_resistance"], errors["sensor_artifacts"] = errors["sensor_artifacts"], errors["internal_resistance"]
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "sensor_artifacts", v


def test_an_effect_first_by_score_that_another_predicts_as_well_is_not_named():
    """Two physical effects remove the same bias; the one with more parameters predicts the held-out samples
    a little better but comes later in the order (the complexity term). The paired test cannot separate them,
    so the first by score is not named and the better predictor is (condition 4b). Where the first also
    predicts clearly better, it is named."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(4)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    errors = {"none": 0.1 + n, "recalibrate_base": 0.1 + n, "lateral_friction_radius": 0.02 + n,
              "grouser_stiction": 0.0195 + n}
    ev = _evidence(errors, sigma)
    ev["candidates"]["grouser_stiction"]["n_params"] = 5
    v = decide(ev)
    assert v["best"] == "lateral_friction_radius"  # first by score ...
    assert v["tests"]["lateral_friction_radius vs grouser_stiction"] >= 0.05  # ... not separated ...
    assert v["effect"] == "grouser_stiction", v  # ... so the better predictor is named
    errors["grouser_stiction"] = 0.06 + n
    ev = _evidence(errors, sigma)
    ev["candidates"]["grouser_stiction"]["n_params"] = 5
    v = decide(ev)
    assert v["effect"] == "lateral_friction_radius", v
    assert "lateral_friction_radius vs grouser_stiction" not in v["tests"]  # a worse predictor is no rival


def test_the_shrink_threshold_counts_only_what_the_effect_adds_to_the_control():
    """The control closes most of the gap; an effect on top of it that adds a tiny but systematic improvement
    passes the significance tests, yet is not named: it closes < 15% of the gap the control leaves (1% and 12%)."""
    from trackenv.diagnose.core import decide

    rng = np.random.default_rng(1)
    K, sigma = 3000, 0.1
    n = sigma * rng.standard_normal(K)
    errors = {"none": 0.3 + n, "recalibrate_base": 0.1 + n, "internal_resistance": 0.097 + n}
    ev = _evidence(errors, sigma)
    v = decide(ev)
    assert ev["candidates"]["internal_resistance"]["heldout_shrink"] > 0.6  # counted from the base model
    assert v["tests"]["internal_resistance vs recalibrate_base"] < 0.05  # significant beyond the control ...
    assert v["effect"] == "none" and "recalibrating the base leaves" in v["reason"], v  # ... but too small
    errors["internal_resistance"] = 0.088 + n  # 12 % of what the control leaves
    v = decide(_evidence(errors, sigma))
    assert v["tests"]["internal_resistance vs recalibrate_base (in-sample)"] < 1e-6
    assert v["effect"] == "none" and "closes only 12%" in v["reason"], v
    errors["internal_resistance"] = 0.05 + n  # half of what the control leaves: named
    v = decide(_evidence(errors, sigma))
    assert v["effect"] == "internal_resistance" and v["own_shrink"] > 0.1, v


def test_max_t_lies_between_the_single_test_and_bonferroni():
    z = 2.2
    single = max_t_pvalue(z, np.eye(1))
    ident = max_t_pvalue(z, np.ones((4, 4)))  # four copies of one statistic: no correction
    indep = max_t_pvalue(z, np.eye(4))  # four independent ones: 1 - (1 - p)^4
    assert ident == pytest.approx(single, rel=0.05)
    assert indep == pytest.approx(1 - (1 - single) ** 4, rel=0.05)
    assert single < indep <= 4 * single


def test_centred_interval_contains_its_point_estimate():
    rng = np.random.default_rng(2)
    boot = rng.normal(0.9, 0.1, 300) ** 2  # skewed, biased resamples
    for point in (0.32, 0.8, 1.0):
        lo, hi = centred_interval(point, boot)
        assert lo <= point <= hi and hi - lo > 0.1


def _copy(names, dst):
    for n in names:
        shutil.copytree(f"{TWIN}/{n}", dst / n)
    return dst


def test_bad_input_is_excluded_or_refused(tmp_path):
    _copy(["go_stop_dry_sand"], tmp_path)
    short = {"t": np.arange(5) * 0.02, "v_left": np.zeros(5), "v_right": np.zeros(5), "i_left": np.zeros(5),
             "i_right": np.zeros(5), "speed_ideal": np.zeros(5), "yaw_rate": np.zeros(5)}
    write_log_columns(tmp_path / "too_short", short, {"terrain": "dry_sand", "maneuver": "x", "current_sensor": "signed"})
    (tmp_path / "no_volts").mkdir()
    (tmp_path / "no_volts" / "log.csv").write_text("t,i_left,i_right,speed_ideal,yaw_rate\n0,1,1,0,0\n")
    (tmp_path / "no_volts" / "meta.json").write_text(json.dumps({"terrain": "dry_sand", "maneuver": "x",
                                                                 "current_sensor": "signed"}))
    tests, excluded = load_tests(tmp_path)
    assert [t.name for t in tests] == ["go_stop_dry_sand"]
    why = {e["test"]: e["reason"] for e in excluded}
    assert "too_short" in why and "samples" in why["too_short"]
    assert "no_volts" in why and "v_left" in why["no_volts"]
    with pytest.raises(DiagnosisError, match="no usable field test"):
        load_tests(tmp_path, ["too_short", "no_volts"])
    with pytest.raises(DiagnosisError, match="no such folder"):
        load_tests(tmp_path / "nope")
    with pytest.raises(DiagnosisError, match="unknown candidate"):
        diagnose(tmp_path, None, candidates=["magic"], progress=False)


def test_nan_runs_are_noted_not_fatal(tmp_path):
    _copy(["go_stop_dry_sand"], tmp_path)
    p = tmp_path / "go_stop_dry_sand" / "log.csv"
    lines = p.read_text().splitlines()
    head = lines[0].split(",")
    k = head.index("yaw_rate")
    for i in range(20, 60):
        cells = lines[i].split(",")
        cells[k] = ""
        lines[i] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    tests, _ = load_tests(tmp_path)
    assert np.isnan(tests[0].measured["yaw_rate"]).sum() == 40
    assert any("missing samples" in n for n in tests[0].notes)


@pytest.fixture(scope="module")
def viscous_go_stop(tmp_path_factory):
    out = tmp_path_factory.mktemp("diag_visc")
    d = diagnose(TWIN, out, tests=["go_stop_dry_sand", "go_stop_2ms_dry_sand"], internal_resistance="viscous",
                 candidates=["internal_resistance", "recalibrate_base", "sensor_artifacts", "lateral_friction_radius"],
                 progress=False, rounds=2, polish_iters=2)
    return d, out


def test_viscous_base_gap_is_internal_resistance_in_cruise_current(viscous_go_stop):
    """Thesis §5.4.1: the viscous model over-predicts the 2 m/s current (~3.1 A vs 2.23 A)."""
    d, out = viscous_go_stop
    v = d.verdict
    top_effect = next(r for r in d.report["ranking"] if r["effect"] != "none")
    assert effect_of(top_effect["effect"]) == "internal_resistance"  # ranked first on held-out data (either fit)
    assert top_effect["heldout_gap_shrink"] > 0.3 and top_effect["p_beats_none"] < 0.1
    lo, hi = v["best_candidate_shrink_ci"]
    assert lo <= v["best_candidate_shrink"] <= hi
    ilo, ihi = v["insample_gap_shrink_ci"]
    assert ilo <= v["insample_gap_shrink"] <= ihi
    top = d.report["gap_cells"][0]
    assert top["test"] == "go_stop_2ms_dry_sand" and top["phase"] == "cruise" and top["signal"] in ("i_left", "i_right")
    assert top["bias_before"] > 0.5  # the viscous model draws too much current
    rep = json.loads((out / "report.json").read_text())
    assert {"effect", "confidence", "heldout_gap_shrink"} <= set(rep["verdict"])
    assert {"effect", "heldout_nrmse", "params", "score"} <= set(rep["ranking"][0])
    assert {"test", "signal", "phase", "nrmse_before", "nrmse_after"} <= set(rep["cells"][0])
    assert 0.0 <= rep["verdict"]["confidence"] <= 1.0
    assert "SYNTHETIC" in rep["data_label"] and "SYNTHETIC" in (out / "report.md").read_text()
    for f in ("heatmap.png", "ranking.png", "overlay_go_stop_2ms_dry_sand.png"):
        assert (out / f).stat().st_size > 10_000


def test_viscous_base_gap_is_internal_resistance_or_silence(viscous_go_stop):
    """The thesis's viscous law is the wrong form: the twin's truth is a constant internal resistance. The
    diagnosis names it (measured: through its fit on the base, confidence 0.77), or stays silent for a
    stated reason (ammeter zero offsets also shift the cruise current); it never names another effect."""
    d, _ = viscous_go_stop
    v = d.verdict
    if v["effect"] == "internal_resistance":
        assert v["heldout_gap_shrink"] > 0.3
    else:
        assert v["effect"] == "none", v["verdict_line"]
        assert effect_of(v["best_candidate"]) == "internal_resistance" or "internal_resistance" in v["reason"], \
            v["verdict_line"]
        assert "sensor_artifacts" in v["reason"] or "recalibrating" in v["reason"], v["verdict_line"]


def _base_case(folder, seed=0):
    """Two tests simulated with the base model + white noise: nothing unmodelled."""
    rng = np.random.default_rng(seed)
    specs = {"go": [[0, 0, 0], [0.3, 11.8, 11.8], [3, 11.8, 11.8], [3.1, 0, 0], [5, 0, 0]],
             "turn": [[0, 0, 0], [0.3, 10, 10], [1.5, 10, 10], [1.7, 5, 15], [3.5, 5, 15], [3.7, 0, 0], [5, 0, 0]]}
    params = te.load_params("dry_sand")
    for name, rows in specs.items():
        traj = te.simulate(params, te.VoltageProfile.from_breakpoints(rows), 5.0, dt=0.02)
        ch = {k: np.asarray(v, float) for k, v in traj.channels.items()}
        noise = {"i_left": 0.08, "i_right": 0.08, "speed_ideal": 0.008, "yaw_rate": 0.015}
        cols = {"t": np.asarray(traj.t, float), "v_left": np.asarray(traj.voltage[:, 0], float),
                "v_right": np.asarray(traj.voltage[:, 1], float)}
        cols.update({k: ch[k] + rng.normal(0, s, ch[k].shape) for k, s in noise.items()})
        write_log_columns(folder / name, cols, {"terrain": "dry_sand", "maneuver": name, "current_sensor": "signed",
                                                "synthetic": True, "notes": "SYNTHETIC test case: base model + noise"})
    return folder


class _Bar:
    """A stand-in for tqdm that records what a progress bar is told."""

    bars: list = []

    def __init__(self, total=None, disable=False, **kw):
        self.total, self.disable, self.n, self.postfix, self.updates, self.closed_at = total, disable, 0, "", [], None
        _Bar.bars.append(self)

    def update(self, k=1):
        self.n += k
        self.updates.append((self.postfix, k))

    def set_postfix_str(self, s):
        self.postfix = s

    def close(self):
        self.closed_at = self.n


def test_base_model_plus_noise_gives_none(tmp_path, monkeypatch):
    import tqdm.auto

    monkeypatch.setattr(tqdm.auto, "tqdm", _Bar)
    _Bar.bars.clear()
    d = diagnose(_base_case(tmp_path / "case"), None,
                 candidates=["internal_resistance", "slip_sinkage", "recalibrate_base", "sensor_artifacts"],
                 progress=True, rounds=1, polish_iters=2)
    assert d.verdict["effect"] == "none", d.verdict
    # the progress bar ends full (the candidates' fit plans), and it moves while the polish runs: after the
    # search's two updates (its design and its one round, one bucket) each fitted candidate reports its polish
    (bar,) = _Bar.bars
    assert bar.closed_at == bar.total > 0, (bar.closed_at, bar.total)
    for name in ("recalibrate_base", "internal_resistance", "slip_sinkage", "sensor_artifacts"):
        assert len([k for c, k in bar.updates if c == name and k > 0]) >= 3, (name, bar.updates)
    checked = {c["fit"]: c for c in d.report["rounding_check"]}  # the verdict's references, each checked once
    assert {"none", "recalibrate_base"} <= set(checked) and len(checked) == len(d.report["rounding_check"])
    assert all(c["moved_fraction"] is not None for c in checked.values()), checked
    # no effect passes the rule; the gap test itself may find the small systematic difference between the logs'
    # 0.5 ms integration and the fit's 1 ms one (measured: one brake-phase current cell)
    # the polish ran and reports its convergence honestly; it never makes a fit worse
    for r in d.report["ranking"]:
        for info in [r["polish"]["full"]] + r["polish"]["folds"]:
            if info.get("used_gradient"):
                assert info["grad_norm"] is not None and info["stop"]
                assert info["polished_loss"] <= info["start_loss"] * 1.001 + 1e-9
    ins, ci = d.verdict["insample_gap_shrink"], d.verdict["insample_gap_shrink_ci"]
    assert ci[0] <= ins <= ci[1]


def test_rounding_check_finds_the_stop_while_turning(tmp_path):
    """The rounding check simulates one parameter set alone and as 16 copies: two batch layouts whose float
    additions differ. The base model on a go-stop moves by rounding only (< 0.001 noise σ); the turn, whose
    voltages drop to zero at 3.7 s while the vehicle is turning, moves by more (1.2e-3 σ measured; 0.6 σ
    while j_x's decay rate took z-tilde* at each substep's start), and only after that stop, where the stored
    lateral shear displacements spring back. Neither reaches the report's 1 σ."""
    from types import SimpleNamespace

    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.sensitivity import rounding_check, summary_lines

    tests, _ = load_tests(_base_case(tmp_path / "case", seed=6))
    sim = BatchSimulator(tests)
    cands = {c.name: c for c in candidate_set()}
    fits = {n: SimpleNamespace(candidate=cands[n]) for n in ("none", "recalibrate_base")}
    check = rounding_check(sim, tests, "none", fits)
    assert check["moved_fraction"] == 0.0 and check["cells"] == [], check
    assert 0.0 < check["max_sigma"] < 1.0, check
    (line,) = summary_lines([check])
    assert "`none`" in line and "same predictions" in line
    fine = rounding_check(sim, tests, "none", fits, threshold=0.001)
    assert fine["cells"] and {c["test"] for c in fine["cells"]} == {"turn"}, fine["cells"]
    assert min(c["first_t"] for c in fine["cells"]) > 3.7, fine["cells"]
    assert fine["max_sigma"] > 0.001, fine


def test_rounding_check_runs_on_a_family_with_its_own_state(tmp_path):
    """The check simulates a fit's full-data point as (S,) = (1,) parameter values. A family with a state of
    its own (the pitch load transfer's first-order lag, here on the fitted control) runs like the others,
    and values of any other shape are refused by name, not sent into the simulator's loop."""
    from types import SimpleNamespace

    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.candidates import ON
    from trackenv.diagnose.sensitivity import rounding_check

    tests, _ = load_tests(_base_case(tmp_path / "case", seed=6))
    sim = BatchSimulator(tests)
    cands = {c.name: c for c in candidate_set()}
    recal = cands["recalibrate_base"]
    pitch = cands["pitch_load_transfer"].standing_on(recal)
    control = {"internal_resistance_factor": 1.1, "cohesion_factor": 0.9, "friction_angle_factor": 1.0,
               "shear_modulus_factor": 1.2}
    unit = pitch.anchor_unit(control)
    unit[0] = 0.5  # height factor 1.5: a load transfer the lag acts on
    fits = {"recalibrate_base": SimpleNamespace(candidate=recal, full=SimpleNamespace(params=control)),
            "pitch_load_transfer": SimpleNamespace(candidate=pitch, full=SimpleNamespace(  # a fit records what it stands on
                unit=unit, params={f"recalibrate_base.{k}": v for k, v in control.items()}))}
    check = rounding_check(sim, tests, "pitch_load_transfer", fits)
    assert "note" not in check and 0.0 <= check["moved_fraction"] <= 1.0 and np.isfinite(check["max_sigma"]), check
    values = {k: np.array([[float(v[0])]]) for k, v in pitch.physical(unit[None]).items()}
    values |= {ON + k: np.array([[v]]) for k, v in control.items()}
    with pytest.raises(ValueError, match="pitch_load_transfer: parameter values must be"):
        sim.run(pitch, values)


def test_polish_lowers_the_loss_and_reports_convergence(tmp_path):
    """Logs of the base model + noise; the LM polish of ``recalibrate_base`` started off the truth (internal
    resistance factor 1.3 instead of 1) lowers the calibration loss through the batched simulator (secant Jacobian), moves
    back toward the truth, says how it stopped, and counts its simulations."""
    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.fit import full_fold
    from trackenv.diagnose.polish import polish_folds

    folder = _base_case(tmp_path / "case", seed=4)
    tests, _ = load_tests(folder)
    sim = BatchSimulator(tests)
    cand = {c.name: c for c in candidate_set()}["recalibrate_base"]
    fd = full_fold(tests)
    start = cand.anchor_unit()
    start[0] = 0.9  # internal-resistance factor 1.3 instead of 1.0
    res = polish_folds(sim, cand, [fd], [cand.anchor_unit()], [None], [np.inf], iters=4)
    info = res["info"][0]
    assert info["used_gradient"], info
    assert info["end_loss"] <= info["start_loss"]
    assert info["grad_norm"] is not None and np.isfinite(info["grad_norm"])
    assert info["stop"] in ("small step", "small gradient", "small improvement", "iteration limit")
    assert "internal_resistance_factor" not in info["held_still"]  # the go-stops feel it
    before = sim.n_vehicle_seconds
    calls = []
    res2 = polish_folds(sim, cand, [fd], [start], [None], [np.inf], iters=4, progress=calls.append)
    # its simulations count in the report's vehicle-seconds (both tests are 5 s long: one bucket), and each
    # batched evaluation reports its own to the progress bar as it ends
    (b,) = sim.buckets
    assert sim.n_vehicle_seconds - before == pytest.approx(res2["n_simulations"] * b.n_steps * b.dt)
    i2 = res2["info"][0]
    assert sum(calls) == res2["n_simulations"] and len(calls) == 1 + i2["iterations"], (calls, i2)
    assert i2["end_loss"] < 0.8 * i2["start_loss"], i2  # from the wrong start the polish closes most of the way
    assert abs(res2["units"][0][0] - cand.anchor_unit()[0]) < abs(start[0] - cand.anchor_unit()[0])


def test_marquardt_step_holds_an_inert_parameter_still():
    """A parameter whose Jacobian column is rounding (1e-7 of the others) gets no step, and the others get the
    least-squares step they would get without it; a weak but real column (1 % of the others) still moves."""
    from trackenv.diagnose.polish import marquardt_step

    rng = np.random.default_rng(0)
    J = rng.normal(size=(200, 3))
    z_true = np.array([0.4, -0.7, 0.3])
    r = -(J @ z_true)  # residuals at z = 0 of r(z) = J z + r0 with its zero at z_true
    J_inert = J.copy()
    J_inert[:, 2] = 1e-7 * rng.normal(size=200)
    d, moved = marquardt_step(J_inert, r, 1e-9)
    assert d[2] == 0.0 and moved.tolist() == [True, True, False]
    ls = np.linalg.lstsq(J_inert[:, :2], -r, rcond=None)[0]
    np.testing.assert_allclose(d[:2], ls, rtol=1e-6)
    J_weak = J.copy()
    J_weak[:, 2] *= 0.01
    r_weak = -(J_weak @ z_true)
    d_weak, moved_weak = marquardt_step(J_weak, r_weak, 1e-9)
    np.testing.assert_allclose(d_weak, z_true, rtol=1e-4)
    assert moved_weak.all()


def test_the_fit_on_all_the_data_is_the_best_point_any_fold_found_for_them(tmp_path):
    """Where the loss is rough (stick-slip after a stop), a fold's point can fit all the data better than the
    full fit's own search and polish found. The full fit then takes that point, its encoder window and the
    values it stands on, records where it came from, and its loss is the point's loss on all the data; a full
    fit that is already the best keeps its own point."""
    from trackenv.diagnose.fit import _best_point_for_all_data, _Pool, full_fold, point_loss_parts

    tests, _ = load_tests(_base_case(tmp_path / "case", seed=6))
    folds = make_folds(tests)
    fold_defs = [*folds, full_fold(tests)]
    F = len(fold_defs)
    exact = [dict(t.measured) for t in tests]  # a point that predicts the logs exactly
    off = [{s: x + 3 * t.noise[s] for s, x in t.measured.items()} for t in tests]  # 3 sigma off everywhere
    preds = [off] * (F - 1) + [off]
    preds[0] = exact
    units = [np.full(2, 0.1 * f) for f in range(F)]
    wins = [0.05 * f for f in range(F)]
    chosen = [{"k": float(f)} for f in range(F)]
    loss_off = float(np.sum(point_loss_parts(tests, off) * fold_defs[-1].weights))
    scores = [5.0] * (F - 1) + [loss_off]  # calibration losses of the folds: not what the full fit compares
    info = [{} for _ in range(F)]
    parts = [point_loss_parts(tests, p) for p in preds]
    _best_point_for_all_data(fold_defs, parts, units, chosen, wins, preds, scores, info)
    assert info[-1] == {"from_fold": 0, "own_loss": loss_off}
    assert units[-1] is units[0] and wins[-1] == wins[0] and chosen[-1] == {"k": 0.0} and preds[-1] is exact
    assert parts[-1] is parts[0]  # the loss parts follow the point
    assert scores[-1] == 0.0 < loss_off  # its loss on all the data, not the fold's calibration loss (0 too)
    # a full fit that is the best already is kept, with nothing recorded
    units2, preds2, scores2, info2 = [np.zeros(2)] * F, [off] * F, [0.0] * (F - 1) + [0.9 * loss_off], [{}] * F
    parts2 = [point_loss_parts(tests, off)] * F
    _best_point_for_all_data(fold_defs, parts2, units2, None, [None] * F, preds2, scores2, info2)
    assert scores2[-1] == 0.9 * loss_off and info2[-1] == {}
    # the search's pool offers the full fit every point, a fold only the shared ones and its own
    pool = _Pool()
    owners = [-1, 0, 1, F - 1]
    pool.add(np.zeros((4, 1)), np.stack([np.full((len(tests), 2), 1.0 + o) for o in owners], axis=-1),
             [{s: np.zeros((len(t.t), 4)) for s in t.measured} for t in tests], owners)
    assert sorted(pool.select(F - 1, fold_defs[-1].weights, F)[0]) == [0, 1, 2, 3]
    assert sorted(pool.select(0, fold_defs[0].weights, F)[0]) == [0, 1]


def test_single_test_without_controls_says_so(tmp_path):
    """One test and a candidate list without the controls: the verdict line and report.json carry both flags,
    and the confidence is lowered accordingly."""
    folder = _base_case(tmp_path / "case", seed=5)
    d = diagnose(folder, tmp_path / "out", tests=["go"], candidates=["internal_resistance"], progress=False,
                 rounds=1, polish_iters=1, figures=False)
    v = d.verdict
    assert any(f.startswith("single test") for f in v["flags"]) and any(f.startswith("controls") for f in v["flags"])
    assert "single test" in v["verdict_line"] and "controls not fitted" in v["verdict_line"]
    assert v["confidence"] <= 0.35 + 1e-9
    rep = json.loads((tmp_path / "out" / "report.json").read_text())
    assert rep["verdict"]["flags"] == v["flags"]
    assert rep["method"]["folds"][0]["kind"] == "forward"  # held out: the later half of the test, not in-sample


def test_tests_on_several_terrains_are_flagged():
    """One effect fitted to tests on two terrains cannot tell an effect of one terrain from another's: the
    analysis says so and lowers the confidence; one terrain, or evidence cached without terrains, is not flagged."""
    from trackenv.diagnose.core import analysis_flags, flag_penalty

    fitted = {"converged": True}
    ev = {"n_tests": 3, "terrains": ["dry_sand", "asphalt", "dry_sand"],
          "candidates": {"recalibrate_base": fitted, "sensor_artifacts": fitted, "pitch_load_transfer": fitted}}
    flags = analysis_flags(ev, "pitch_load_transfer", restricted=False)
    assert len(flags) == 1 and flags[0].startswith("tests on 2 terrains (asphalt, dry_sand)")
    assert flag_penalty(flags) == pytest.approx(0.8)
    assert analysis_flags(ev | {"terrains": ["asphalt"] * 3}, "pitch_load_transfer", restricted=False) == []
    assert analysis_flags({k: v for k, v in ev.items() if k != "terrains"}, "pitch_load_transfer", False) == []


def test_cli_bad_folder_exits_2(tmp_path, capsys):
    from trackenv.cli import main

    assert main(["diagnose", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_cli_passes_after_on_and_points_to_it_when_an_effect_is_named(tmp_path, capsys, monkeypatch):
    """The command line hands ``--after`` to the diagnosis, and after a named effect says how to look further;
    after ``none`` it does not (a stand-in diagnosis: this checks the command line, not the fits)."""
    from types import SimpleNamespace

    import trackenv.diagnose
    from trackenv.cli import main

    calls = []

    def fake(folder, out, **kw):
        calls.append(kw)
        effect = "none" if kw["after"] else "slip_sinkage"
        return SimpleNamespace(verdict={"effect": effect, "verdict_line": effect},
                               report={"data_label": "SYNTHETIC", "gap_cells": [], "timing": {"wall_s": 1.0}})

    monkeypatch.setattr(trackenv.diagnose, "diagnose", fake)
    assert main(["diagnose", TWIN, "--out", str(tmp_path / "first"), "--terrains", "pooled"]) == 0
    assert f"--after {tmp_path / 'first' / 'report.json'}" in capsys.readouterr().out
    report = _report_naming(tmp_path / "first")
    assert main(["diagnose", TWIN, "--out", str(tmp_path / "second"), "--after", str(report)]) == 0
    assert calls[-1]["after"] == str(report) and "--after" not in capsys.readouterr().out


# The withheld-effect check, small CI version (3 tests of at most 6 s, 8 search points, 1 cross-entropy round,
# no polish). Threshold: at least 2 of these 3 blind cases (effects in forms the
# candidate library does not have; labels withheld) get the right verdict, and the null case is not flagged.
# The 40-case benchmark (top-1 0.625) is in docs/diagnose_benchmark.md.
CI_LABELS = ["lateral_friction_radius", "slip_sinkage", "none"]


def test_near_limit_summary_counts_only_cases_in_the_window(tmp_path):
    """A case drawn near the limit whose visibility missed the 1-3 sigma window is counted as near-limit, but not
    as in the window; the report states both."""
    from trackenv.diagnose.benchmark import _write, near_limit_summary

    def row(case, label, verdict, vis, near):
        return {"case": case, "label": label, "verdict": verdict, "confidence": 0.8, "shrink": 0.5, "own_shrink": 0.4,
                "insample_shrink": 0.5, "true_effect_shrink": 0.5, "visibility": vis, "near_limit": near,
                "maneuvers": ["go_stop"], "terrain": "asphalt", "reason": "r", "wall_s": 1.0}

    rows = [row("c0", "slip_sinkage", "slip_sinkage", 2.0, True),   # in the window, named
            row("c1", "slip_sinkage", "none", 1.5, True),           # in the window, missed
            row("c2", "grouser_stiction", "grouser_stiction", 40.0, True),  # drawn near the limit, landed at 40 sigma
            row("c3", "grouser_stiction", "grouser_stiction", 3.5, False),
            row("c4", "none", "none", None, False)]
    s = near_limit_summary(rows)
    assert (s["near_limit_cases"], s["near_limit_named"], s["near_limit_in_window"], s["near_limit_in_window_named"]) \
        == (3, 2, 2, 1)
    _write(tmp_path, rows, 0, {})
    md = (tmp_path / "benchmark.md").read_text()
    assert "near-limit effect cases named correctly: 2 / 3; of them 2 landed in the 1-3 σ window" in md
    assert "named 1 / 2" in md and "null cases flagged: **0 / 1** (the false-positive rate is below 0.950" in md and "(4 / 5)" in md


def test_the_null_false_positive_bound_is_clopper_pearson():
    """The benchmark bounds the null false-positive rate one-sided at 95 %: with none flagged, n = 59 null cases are
    the fewest that bound it at 0.05 (0.95^59 < 0.05 < 0.95^58); one flagged in 8 allows up to 47 %."""
    from trackenv.diagnose.benchmark import rate_upper_bound, summarize

    assert rate_upper_bound(0, 59) < 0.05 < rate_upper_bound(0, 58)
    assert rate_upper_bound(0, 8) == pytest.approx(1 - 0.05 ** (1 / 8), rel=1e-9)  # 0.312
    assert rate_upper_bound(1, 8) == pytest.approx(0.4707, abs=1e-3)
    assert rate_upper_bound(3, 3) == 1.0 and rate_upper_bound(0, 0) is None
    rows = [{"label": "none", "verdict": v, "shrink": 0.0, "true_effect_shrink": None, "wall_s": 1.0}
            for v in ["none"] * 19 + ["slip_sinkage"]]
    s = summarize(rows)
    assert s["null_flagged"] == 1 and s["null_false_positive_rate"] == 0.05
    bound = s["null_false_positive_rate_upper95"]
    assert bound == pytest.approx(rate_upper_bound(1, 20)) and 0.2 < bound < 0.25


def test_a_benchmark_of_null_cases_only_writes_its_report(tmp_path):
    """A false-positive calibration (every label ``none``) has no power to plot; its report and figures are still
    written, with the bound."""
    from trackenv.diagnose.benchmark import _write

    rows = [{"case": f"c{i}", "label": "none", "verdict": "none", "confidence": 0.5, "shrink": 0.0, "own_shrink": None,
             "insample_shrink": 0.0, "true_effect_shrink": None, "visibility": None, "near_limit": False,
             "maneuvers": ["go_stop"], "terrain": "asphalt", "reason": "r", "wall_s": 1.0} for i in range(60)]
    _write(tmp_path, rows, 1, {})
    md = (tmp_path / "benchmark.md").read_text()
    assert "null cases flagged: **0 / 60** (the false-positive rate is below 0.049" in md
    assert (tmp_path / "power.png").stat().st_size > 1000 and (tmp_path / "confusion.png").exists()


def test_blind_benchmark_small(tmp_path):
    from trackenv.diagnose.benchmark import run_benchmark

    res = run_benchmark(tmp_path, len(CI_LABELS), seed=3, labels=CI_LABELS, n_tests=3, t_max=6.0, rounds=1,
                        search_points=8, polish_iters=0, near_limit_fraction=0.0, progress=False)
    s = res["summary"]
    assert sum(r["verdict"] == r["label"] for r in res["cases"]) >= 2, res["cases"]
    assert s["null_false_positive_rate"] == 0.0
    assert (tmp_path / "benchmark.md").exists() and (tmp_path / "confusion.png").exists()
    assert (tmp_path / "power.png").exists()
    # the cached evidence re-scores every case without fitting, to the same verdicts
    from trackenv.diagnose.benchmark import rescore

    again = rescore(tmp_path)
    assert [r["verdict"] for r in again["rows"]] == [r["verdict"] for r in res["cases"]]
    # with the run's confidence: the same analysis flags (not converged, single test) lower it
    assert [r["confidence"] for r in again["rows"]] == pytest.approx([r["confidence"] for r in res["cases"]], abs=1e-9)
    # the label never reaches the case folders
    for f in (tmp_path / "cases").rglob("*.json"):
        assert "lateral_friction" not in f.read_text() and "slip_sinkage" not in f.read_text()


def test_an_effects_two_fits_share_one_polish_simulation(tmp_path):
    """An effect fitted on the control and on the base model (``each_branch``) is polished as one problem: the
    fit compiles one simulation program for its search and one for both polishes (three when each branch was
    polished alone, the base branch's parameters all equal and thus a batch of another structure). Each fit
    keeps its own rows: the base branch stands on the control's anchor, the other on the control's fitted
    values, and each row is polished by itself."""
    import importlib

    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.fit import fit_candidate

    simulate_module = importlib.import_module("trackenv.simulate")
    tests, _ = load_tests(_base_case(tmp_path / "case", seed=5))
    sim = BatchSimulator(tests)
    cands = {c.name: c for c in candidate_set()}
    recal = cands["recalibrate_base"]
    fitted = {"internal_resistance_factor": 1.2, "cohesion_factor": 0.8, "friction_angle_factor": 1.02,
              "shear_modulus_factor": 1.3}
    cand = cands["pitch_load_transfer"].standing_on(recal)
    folds = make_folds(tests)
    below = [[{k: v * (1 + 0.01 * f) for k, v in fitted.items()}, dict(recal.anchor)]  # per fold, as a control fits them
             for f in range(len(folds) + 1)]
    jitted = simulate_module._simulate_jit
    before = jitted._cache_size()
    on_control, on_base = fit_candidate(sim, cand, folds, rounds=0, min_round=3, per_fold=3, polish_iters=1,
                                        below=below, each_branch=(0, 1))
    assert jitted._cache_size() - before <= 2
    for branch, fit in enumerate((on_control, on_base)):
        for f, ff in enumerate([*fit.folds, fit.full]):
            on = {k: ff.params[f"recalibrate_base.{k}"] for k in fitted}
            if ff is fit.full:  # the full fit may take any point of its branch that fits all the data better
                assert any(on == pytest.approx(below[g][branch]) for g in range(len(below))), on
            else:
                assert on == pytest.approx(below[f][branch])
            assert ff.polish["used_gradient"] and ff.polish["iterations"] == 1
            assert np.isfinite(ff.polish["start_loss"]) and ff.polish["end_loss"] <= ff.polish["start_loss"]
    # the rounding check re-simulates each fit on the values it stands on (the base's for `@base`), not on the
    # control's full fit
    from types import SimpleNamespace

    from trackenv.diagnose.candidates import ON
    from trackenv.diagnose.sensitivity import _values

    control = SimpleNamespace(candidate=recal, full=SimpleNamespace(params=below[-1][0]))
    for fit in (on_control, on_base):
        _, vals, _ = _values(fit, {"recalibrate_base": control})
        assert {k: float(vals[ON + k][0]) for k in fitted} == pytest.approx(
            {k: fit.full.params[f"recalibrate_base.{k}"] for k in fitted})
    assert {k: float(_values(on_base, {"recalibrate_base": control})[1][ON + k][0]) for k in fitted} == \
        pytest.approx({k: recal.anchor[k] for k in fitted})


SLIP = {"sinkage_rate": 0.4, "bulldozing_factor": 1.5, "max_sinkage": 0.03}  # a slip_sinkage fit, its family's names


def _report_naming(path, member="slip_sinkage@base", params=None, effect=None, internal_resistance="constant",
                   after=(), window=0.1):
    """A report.json as a diagnosis writes it, naming ``member`` at ``params`` with an encoder ``window`` [s]
    (the fields ``after=`` reads)."""
    params = dict(SLIP if params is None else params)
    rep = {"verdict": {"effect": effect or effect_of(member), "after_model": member},
           "ranking": [{"effect": member, "params": params | {"encoder_window": window}}],
           "base_model": {"internal_resistance": internal_resistance, "after": list(after)}}
    path.mkdir(parents=True, exist_ok=True)
    (path / "report.json").write_text(json.dumps(rep))
    return path / "report.json"


def test_a_named_fit_joins_the_base_model_as_its_family_predicts_it(tmp_path):
    """``after=``: the base model of the next diagnosis is the named fit, simulated exactly as the candidate
    family simulated it (the control's factors and the effect at the report's values, and its encoder window),
    and a chain of reports carries every earlier fit in order."""
    from trackenv.diagnose.batch import BatchSimulator
    from trackenv.diagnose.candidates import named_fits_from_report

    data, _ = load_tests(_base_case(tmp_path / "case"), None)
    cands = {c.name: c for c in candidate_set()}
    first = named_fits_from_report(_report_naming(tmp_path / "r1", window=0.0), "constant")
    assert [nf.member for nf in first] == ["slip_sinkage@base"]
    plain = BatchSimulator(data).run(cands["none"], {})[0]
    after = BatchSimulator(data, named=first).run(cands["none"], {})[0]
    as_candidate = BatchSimulator(data).run(cands["slip_sinkage"], {k: np.array([v]) for k, v in SLIP.items()})[0]
    turn = [t.name for t in data].index("turn")
    assert np.max(np.abs(after[turn]["yaw_rate"] - plain[turn]["yaw_rate"])) > 0.05  # the sinkage acts
    for j in range(len(data)):
        for sig in after[j]:
            np.testing.assert_array_equal(after[j][sig], as_candidate[j][sig])
    # the fit's encoder window is carried too: the speed the encoder reports is averaged over it (inside the
    # simulation, in float32 and exact for piecewise-linear samples; the encoder layer interpolates its integral)
    windowed = BatchSimulator(data, named=named_fits_from_report(_report_naming(tmp_path / "r1w"), "constant"))
    speed = windowed.run(cands["none"], {})[0]
    layer = BatchSimulator(data).run(cands["slip_sinkage"], {k: np.array([v]) for k, v in SLIP.items()},
                                     windows=(0.1,))[0]
    for j in range(len(data)):
        assert np.max(np.abs(speed[j]["speed_ideal"] - after[j]["speed_ideal"])) > 0.02
        np.testing.assert_allclose(speed[j]["speed_ideal"], layer[j]["speed_ideal"], rtol=0, atol=3e-3)
        np.testing.assert_array_equal(speed[j]["yaw_rate"], after[j]["yaw_rate"])
    # a second report, made after the first: both fits join, the first one first
    ir = {"b0_factor": 2.0, "s1": 0.0, "s2": 0.0, "s3": 0.0, "recalibrate_base.cohesion_factor": 1.2,
          "recalibrate_base.internal_resistance_factor": 1.0, "recalibrate_base.friction_angle_factor": 1.0,
          "recalibrate_base.shear_modulus_factor": 1.0}
    chain = named_fits_from_report(_report_naming(tmp_path / "r2", "internal_resistance", ir,
                                                  after=[nf.to_json() for nf in first]), "constant")
    assert [nf.member for nf in chain] == ["slip_sinkage@base", "internal_resistance"]
    assert chain[1].candidate.on is not None and chain[1].values["on.cohesion_factor"] == 1.2
    base, _ = BatchSimulator(data, named=chain).stacked_base(BatchSimulator(data).buckets[0], 1)
    assert [type(e).__name__ for e in base.effects] == ["SlipSinkage", "KnotInternalResistance", "SensorArtifacts"]
    assert float(base.effects[2].window[0]) == pytest.approx(0.1) and float(base.effects[2].gyro_bias[0]) == 0.0
    assert np.allclose(base.terrain.cohesion, 1.2 * np.asarray(te.load_params("dry_sand").terrain.cohesion))


def test_after_refuses_a_report_that_names_no_fit_or_another_base(tmp_path):
    from trackenv.diagnose.candidates import named_fits_from_report

    with pytest.raises(DiagnosisError, match="names no effect"):
        named_fits_from_report(_report_naming(tmp_path / "none", "none", {}, effect="none"), "constant")
    with pytest.raises(DiagnosisError, match="'viscous' internal resistance"):
        named_fits_from_report(_report_naming(tmp_path / "visc", internal_resistance="viscous"), "constant")
    with pytest.raises(DiagnosisError, match="lacks a finite value for max_sinkage"):
        named_fits_from_report(_report_naming(tmp_path / "part", params={"sinkage_rate": 0.4,
                                                                          "bulldozing_factor": 1.5}), "constant")
    with pytest.raises(DiagnosisError, match="no such report"):
        named_fits_from_report(tmp_path / "missing" / "report.json", "constant")
    with pytest.raises(DiagnosisError, match="base_model.after"):
        named_fits_from_report(_report_naming(tmp_path / "chain", after=[{"fit": "moon_dust"}]), "constant")


def test_after_the_named_effect_the_diagnosis_finds_the_one_that_remains(tmp_path):
    """Logs of the base model with a slip sinkage and a stronger internal resistance (2.2x b*_int, beyond the
    control's 1.4x): given the sinkage as already named (at its true values), the diagnosis does not offer it
    again, says what its base model carries, and names the internal resistance."""
    from trackenv.effects import get_effect

    rng = np.random.default_rng(3)
    params = te.load_params("dry_sand")
    params = te.load_params("dry_sand", effects=(get_effect("slip_sinkage", **SLIP),
                                                 get_effect("internal_resistance", b0=2.2 * float(params.internal.constant))))
    specs = {"go": [[0, 0, 0], [0.3, 11.8, 11.8], [3, 11.8, 11.8], [3.1, 0, 0], [5, 0, 0]],
             "turn": [[0, 0, 0], [0.3, 10, 10], [1.5, 10, 10], [1.7, 5, 15], [3.5, 5, 15], [3.7, 0, 0], [5, 0, 0]]}
    for name, rows in specs.items():
        traj = te.simulate(params, te.VoltageProfile.from_breakpoints(rows), 5.0, dt=0.02)
        noise = {"i_left": 0.08, "i_right": 0.08, "speed_ideal": 0.008, "yaw_rate": 0.015}
        cols = {"t": np.asarray(traj.t, float), "v_left": np.asarray(traj.voltage[:, 0], float),
                "v_right": np.asarray(traj.voltage[:, 1], float)}
        cols.update({k: np.asarray(traj.channels[k], float) + rng.normal(0, s, len(cols["t"])) for k, s in noise.items()})
        write_log_columns(tmp_path / "case" / name, cols, {"terrain": "dry_sand", "maneuver": name,
                                                           "current_sensor": "signed", "synthetic": True,
                                                           "notes": "SYNTHETIC test case: two effects + noise"})
    report = _report_naming(tmp_path / "first", "slip_sinkage@base", SLIP, window=0.0)  # the logs have no window
    d = diagnose(tmp_path / "case", tmp_path / "out", after=report, progress=False, rounds=1, polish_iters=2,
                 candidates=["slip_sinkage", "internal_resistance", "recalibrate_base", "sensor_artifacts"],
                 figures=False)
    skipped = {r["effect"]: r["why"] for r in d.report["not_applicable"]}
    assert "already in the base model" in skipped["slip_sinkage"], skipped
    assert not any(effect_of(r["effect"]) == "slip_sinkage" for r in d.report["ranking"])
    assert d.report["base_model"]["after"][0]["fit"] == "slip_sinkage@base"
    assert d.verdict["verdict_line"].startswith("after slip_sinkage@base: ")
    assert d.verdict["effect"] == "internal_resistance", d.verdict["verdict_line"]
    assert "slip_sinkage@base" in (tmp_path / "out" / "report.md").read_text()
