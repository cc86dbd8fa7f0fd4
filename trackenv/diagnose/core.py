"""``diagnose``: where the simulation disagrees with field logs, which unmodelled effect explains it,
and how far the gap closes once that effect is added (docs/model.md §8).

1. **Where** — every test is replayed on the base model; the gap is measured per test × signal ×
   phase (:mod:`.phases`, :mod:`.metrics`) and the cells that carry it are named.
2. **Which** — each candidate (:mod:`.candidates`: the effects, the ``recalibrate_base`` control,
   ``none``) is fitted on calibration data and scored on held-out data; every effect is fitted on top of
   the control's fit of the same fold (or on the base, if that fits the fold's calibration data better),
   so that "beats the control" compares nested models (:mod:`.fit`: a test whose
   maneuver repeats is held out whole, a unique one is forward-chained: fitted on its first half, scored
   on the rest). Fits: derivative-free search, then Levenberg-Marquardt through the simulator (:mod:`.polish`).
3. **Verdict** — :func:`decide`, from the cached per-sample evidence (:func:`evidence`); see ``RULE_TEXT``.
4. **How far** — held-out and in-sample gap shrink, each with a block-bootstrap 95 % interval that
   contains its point estimate; flags (single test, controls dropped, not converged, several terrains) in the verdict line.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..compare import json_clean as _clean
from ..params import is_integer, is_positive, is_real
from .batch import FIT_SUBSTEP, BatchSimulator
from .candidates import NONE, ON_BASE, RECALIBRATE, candidate_set, effect_of, named_fits_from_report
from .data import DiagnosisError, TestData, load_tests
from .fit import CandidateFit, fit_candidate, fit_plan, make_folds
from .metrics import (
    cell_ci,
    cell_table,
    gap_carriers,
    overall_gap,
    overall_gap_range,
    overall_nrmse,
    signal_error,
    signal_weight,
    sq_errors,
)
from .sensitivity import rounding_checks
from .stats import (
    ALPHA,
    block_draws,
    block_length,
    centred_interval,
    dm_test,
    gap_test,
    huber_loss,
    max_t_pvalue,
    noise_ar1,
    paired_covariance,
    paired_statistic,
    paired_test,
)

COMPLEXITY = 0.02
MIN_SHRINK = 0.15  # condition (5): the effect's own part of the held-out gap the better of `none` and the control leaves
SENSOR = "sensor_artifacts"
N_BOOT = 300
GAP_LEFT_BY = {NONE: "left by the base model", RECALIBRATE: "that recalibrating the base leaves"}

RULE_TEXT = (
    "Every physical effect is fitted twice: on top of the `recalibrate_base` control (fold by fold, on the base "
    "parameters the control fitted on that fold's calibration data; its family thus contains the fitted control "
    "and (3) compares nested models) and on the base model itself (`<effect>@base`, whose predictions do not "
    "inherit the control's extrapolation). Both fits are members of the max-T families below. The members are "
    "tried in the order of their held-out scores; the effect of the first for which all "
    "of these hold is named, each at alpha = 0.05 (an intersection-union rule: naming an "
    "effect when none beats the base model, or when tuning the base parameters does as well, has probability "
    "<= alpha, if the fitted control does as well as tuning can, which it does not always (condition 3b guards "
    "against that; docs/diagnose_benchmark.md measures the rate on null blind cases); the max-T corrections make "
    "trying every effect no more "
    "likely to name one under the null): "
    "(1) the base model's gap is real: the AR(1)-noise chi-square test of its residuals, "
    "Bonferroni-combined over test x signal, has p < alpha; (2) the effect "
    "beats `none` on the held-out samples: a fixed-design paired test whose variance is the instruments' "
    "AR(1) noise projected on the two predictions' difference, max-T corrected over all effect candidates "
    "(p < alpha); (3) it beats the `recalibrate_base` control the same way (max-T over the effects, p < alpha) and also by "
    "a Diebold-Mariano test on Huber losses (k = 1.345 noise units per channel sample; Newey-West variance, "
    "bandwidth >= 2 correlation times of the loss differential, p < alpha), else the verdict is `none`: a gap "
    "that tuning closes; (3b) one of the effect's fits on all the data (on the control or on the base) fits them "
    "better than the control's fit on all the data (Diebold-Mariano on the Huber loss of each sample's in-sample "
    "term, p < alpha), else `none`: a held-out win over a control that extrapolated worse while fitting as well "
    "is not evidence of an effect; (4) a physical effect that does not beat "
    "`sensor_artifacts` (max-T over the physical effects, p < alpha) gives way to it if `sensor_artifacts` "
    "itself passes (2)-(3b) and predicts the held-out data at least as well (held-out score); if it predicts them "
    "worse, the data do not separate the two and neither is named; (4b) it beats, by the same paired test (max-T over "
    "the physical effects, p < alpha), the best fit of every other physical effect that predicts the held-out data at "
    "least as well (mean Huber loss of the Diebold-Mariano test; no complexity term), else it is not named: the data "
    "do not separate the two, and the next member is tried; (5) it closes at least 15% of the held-out "
    "gap that the better of `none` and "
    "`recalibrate_base` leaves (its own part: the shrink reported beside it counts from the base model and includes "
    "what the control closes). If no physical effect passes, `sensor_artifacts` is named if it passes "
    "(2), (3), (3b) and (5) and no physical effect was left unseparated from it by (4). Otherwise `none`, with the "
    "reason of the "
    "best-scoring effect. "
    "Confidence: 1 - (largest corrected p-value the named effect had to pass); for `none`, the smallest such "
    "value of any effect; times 0.7 for a single test, 0.5 when a control was not fitted, 0.8 when the fit did "
    "not converge, 0.8 when the tests span several terrains.")


@dataclass
class Diagnosis:
    """The result of :func:`diagnose` (``report`` is what ``report.json`` holds)."""

    tests: list
    excluded: list
    fits: dict  # name -> CandidateFit
    report: dict
    out_dir: Path | None = None
    files: dict = field(default_factory=dict)
    evidence: dict | None = None

    @property
    def verdict(self) -> dict:
        return self.report["verdict"]


def _mean_over_signals(terms: list[np.ndarray]) -> np.ndarray:
    """(K,) per sample, the mean of the signals' terms that are finite there (NaN where none is)."""
    st = np.stack(terms)
    n_ok = np.sum(np.isfinite(st), axis=0)
    return np.where(n_ok > 0, np.nansum(st, axis=0) / np.maximum(n_ok, 1), np.nan)


def _weighted_sq(tests: list[TestData], sq: list[dict]) -> list[np.ndarray]:
    """Per test: (K,) the loss's per-sample term (mean over signals of weighted squared error, :func:`sq_errors`)."""
    return [_mean_over_signals([e2 * signal_weight(t, sig) for sig, e2 in sq[j].items()]) for j, t in enumerate(tests)]


def _scores(fits: dict) -> dict:
    return {n: float(np.sum(f.heldout_loss)) * (1.0 + COMPLEXITY * f.candidate.n_params) for n, f in fits.items()}


def _masked(sq: list[dict], masks: list) -> list[dict]:
    return [{s: np.where(m, e2, np.nan) for s, e2 in d.items()} for d, m in zip(sq, masks)]


def data_label(data: list[TestData]) -> str:
    """What the logs are, from their meta.json: SYNTHETIC, MEASURED, or field logs that say neither."""
    synthetic = [t.name for t in data if t.log.synthetic]
    measured = [t.name for t in data if t.log.meta.get("measured") is True]
    if synthetic:
        return "SYNTHETIC: " + ", ".join(synthetic) + " say synthetic: true in meta.json (not measured)"
    if measured and len(measured) == len(data):
        return "MEASURED: every log says measured: true in meta.json"
    if measured:
        return "MEASURED: " + ", ".join(measured) + "; the others' meta.json says neither measured nor synthetic"
    return "field logs (meta.json does not say synthetic)"


def gap_cells(data: list[TestData], base_pred: list[dict]) -> list[dict]:
    """Is the base model's gap real: the AR(1)-noise χ² test (:func:`.stats.gap_test`) per test × signal.

    The noise's level and lag-1 coefficient come from the consecutive differences of the base model's
    *residual* (sim − meas over the compared samples): the model has removed the signal, so the
    differences see the noise (plus the small per-sample change of a smooth systematic gap).
    """
    cells = []
    for j, t in enumerate(data):
        for sig in t.measured:
            e = signal_error(t, sig, base_pred[j][sig])
            e = np.where(t.fit_mask, e, np.nan)
            sigma, rho = noise_ar1(e)
            z, p = gap_test(e[np.isfinite(e)], sigma, rho)
            cells.append({"test": t.name, "signal": sig, "z": z, "p": p, "rho": rho, "sigma": sigma})
    return cells


def noise_models(data: list[TestData], cells: list[dict]) -> list[dict]:
    """Per test, per signal: (σ, ρ) of the AR(1) noise model (from the gap test's cells; where the residual's
    σ is not positive, the log's own white-noise level with ρ = 0)."""
    by = {(c["test"], c["signal"]): (c["sigma"], c["rho"]) for c in cells}
    out = []
    for t in data:
        d = {}
        for sig in t.measured:
            sigma, rho = by.get((t.name, sig), (float("nan"), 0.0))
            d[sig] = (float(sigma), float(rho)) if np.isfinite(sigma) and sigma > 0 else (float(t.noise[sig]), 0.0)
        out.append(d)
    return out


def evidence(data: list[TestData], fits: dict) -> dict:
    """What the verdict rule needs, per candidate and per sample (JSON/npz-cacheable: see :func:`save_evidence`)."""
    masks = fits[NONE].heldout_masks  # every candidate has the same folds, hence the same masks
    for f in fits.values():
        masks = [m & mm for m, mm in zip(masks, f.heldout_masks)]
    sq_base = sq_errors(data, fits[NONE].full_pred)
    sq_base_held = _masked(sq_base, masks)
    gap_before = overall_gap(data, sq_base)
    gap_before_held = overall_gap(data, sq_base_held)
    cells = gap_cells(data, fits[NONE].full_pred)
    # signed held-out errors on samples every candidate predicts (finite), for the paired tests
    err = {n: [{sig: signal_error(t, sig, f.heldout_pred[j][sig]) for sig in t.measured} for j, t in enumerate(data)]
           for n, f in fits.items()}
    for j, t in enumerate(data):
        for sig in t.measured:
            ok = masks[j] & t.fit_mask & np.all([np.isfinite(err[n][j][sig]) for n in fits], axis=0)
            for n in fits:
                err[n][j][sig] = np.where(ok, err[n][j][sig], np.nan)
    ev = {"tests": [t.name for t in data], "terrains": [t.terrain for t in data], "n_tests": len(data),
          "gap_cells_tested": len(cells),
          "gap_p": min(1.0, min(c["p"] for c in cells) * len(cells)) if cells else 1.0,
          "gap_z_max": max((c["z"] for c in cells), default=0.0), "gap_cells": cells,
          "gap_before": gap_before, "gap_before_heldout": gap_before_held, "candidates": {},
          "noise": noise_models(data, cells), "weights": [{sig: signal_weight(t, sig) for sig in t.measured} for t in data],
          "err_held": err, "ws_held": {}, "ws_full": {}, "_sq_base": sq_base, "_sq_base_held": sq_base_held,
          "_sq_held": {}, "_sq_full": {}}
    for n, f in fits.items():
        sq_h = _masked(sq_errors(data, f.heldout_pred), masks)
        sq_f = sq_errors(data, f.full_pred)
        ev["_sq_held"][n], ev["_sq_full"][n] = sq_h, sq_f
        ev["ws_held"][n] = _weighted_sq(data, sq_h)
        ev["ws_full"][n] = _weighted_sq(data, sq_f)
        gh, gf = overall_gap(data, sq_h), overall_gap(data, sq_f)
        ev["candidates"][n] = {
            "n_params": f.candidate.n_params, "is_effect": f.candidate.is_effect, "converged": f.converged,
            "heldout_gap": gh, "insample_gap": gf,
            "heldout_shrink": (1.0 - gh / gap_before_held) if gap_before_held > 0 else 0.0,
            "insample_shrink": (1.0 - gf / gap_before) if gap_before > 0 else 0.0,
            "heldout_loss": float(sum(np.nanmean(x) for x in ev["ws_held"][n])),
        }
    for n in fits:
        d = compare(ev, n, NONE) if n != NONE else {"z": 0.0, "p": 1.0}
        ev["candidates"][n]["p_beats_none"], ev["candidates"][n]["z_beats_none"] = d["p"], d["z"]
    return ev


def robust_losses(ev: dict, name: str) -> list[np.ndarray]:
    """Per test: (K,) candidate ``name``'s per-sample held-out loss for the Diebold-Mariano test: the mean over
    signals of the Huber loss (:func:`.stats.huber_loss`) of each signal's weighted error, on the samples every
    candidate predicts (NaN elsewhere)."""
    return [_mean_over_signals([huber_loss(e**2 * ev["weights"][j][sig]) for sig, e in errs.items()])
            for j, errs in enumerate(ev["err_held"][name])]


def compare(ev: dict, a: str, b: str) -> dict:
    """The paired test of "candidate ``a`` predicts the held-out samples better than ``b``" (:func:`.stats.paired_test`)."""
    return paired_test(ev["err_held"][a], ev["err_held"][b], ev["noise"], ev["weights"])


def family_pvalue(ev: dict, chosen: str, ref: str, family: list[str]) -> float:
    """p-value of "``chosen`` beats ``ref``", max-T corrected over ``family`` (:func:`.stats.max_t_pvalue`)."""
    zs, terms = {}, {}
    for n in dict.fromkeys([*family, chosen]):
        if n == ref:
            continue
        D, V, tm = paired_statistic(ev["err_held"][n], ev["err_held"][ref], ev["noise"], ev["weights"])
        if V > 0 and np.isfinite(V):
            zs[n], terms[n] = D / np.sqrt(V), (tm, V)
    if chosen not in zs:
        return 1.0
    names = list(zs)
    corr = np.array([[paired_covariance(terms[a][0], terms[b][0]) / np.sqrt(terms[a][1] * terms[b][1])
                      for b in names] for a in names])
    return max_t_pvalue(zs[chosen], corr)


def decide(ev: dict, alpha: float = ALPHA, min_shrink: float = MIN_SHRINK) -> dict:
    """The verdict rule (``RULE_TEXT``) on evidence from :func:`evidence` (or :func:`load_evidence`)."""
    cand = ev["candidates"]
    score = {n: c["heldout_loss"] * (1.0 + COMPLEXITY * c["n_params"]) for n, c in cand.items()}
    best = min(score, key=score.get)
    effects = [n for n, c in cand.items() if c["is_effect"]]
    # the instruments-only candidate's fits (on the control, on the base): the better-scoring one competes
    sensors = [n for n in effects if effect_of(n) == SENSOR]
    sensor = min(sensors, key=score.get) if sensors else None
    physical = [n for n in effects if effect_of(n) != SENSOR]
    tests = {}
    robust = {}

    def robust_of(x):
        if x not in robust:
            robust[x] = robust_losses(ev, x)
        return robust[x]

    def p_of(x, ref, family):
        key = f"{x} vs {ref}"
        if key not in tests:
            tests[key] = family_pvalue(ev, x, ref, family) if ref in cand else None
        return tests[key]

    out = {"best": best, "m": len(effects), "gap_p": ev["gap_p"], "gap_significant": ev["gap_p"] < alpha,
           "tests": tests}

    def insample_pvalue(e):
        """(3b): does ``e``'s fit on all the data beat the control's there? Diebold-Mariano on the Huber loss
        of each sample's in-sample term (the mean over signals of the weighted squared errors, ``ws_full``).
        None where the control or the in-sample losses are missing."""
        full = ev.get("ws_full", {})
        if RECALIBRATE not in cand or e not in full or RECALIBRATE not in full:
            return None
        ref = [huber_loss(x) for x in full[RECALIBRATE]]
        ps = []
        for m in [x for x in cand if effect_of(x) == effect_of(e) and x in full]:
            key = f"{m} vs {RECALIBRATE} (in-sample)"
            if key not in tests:
                tests[key] = dm_test([huber_loss(x) for x in full[m]], ref)["p"]
            ps.append(tests[key])
        return min(ps)

    def passes(e):
        """(passes (2)-(3b), the largest p it had to pass, why not)."""
        pn = p_of(e, NONE, effects)
        if pn >= alpha:
            return False, pn, f"{e} does not beat the base model on held-out data (paired test, max-T p = {pn:.2g} ≥ {alpha:.2g})"
        pr = p_of(e, RECALIBRATE, effects)
        if pr is not None:  # and by the random-design test: a control the fit did not tune well is not beaten
            key = f"{e} vs {RECALIBRATE} (Diebold-Mariano)"
            tests[key] = dm_test(robust_of(e), robust_of(RECALIBRATE))["p"]
            pr = max(pr, tests[key])
        if pr is not None and pr >= alpha:
            return False, max(pn, pr), (f"{e} does not beat recalibrating the base parameters (p = {pr:.2g} ≥ "
                                        f"{alpha:.2g}): a gap that tuning closes")
        p_in = insample_pvalue(e)  # None exactly where pr is (no control), or where no in-sample losses were kept
        if p_in is not None and p_in >= alpha:
            return False, max(pn, pr, p_in), (
                f"{e} predicts the held-out data better than recalibrating the base parameters but does not fit "
                f"all the data better (in-sample p = {p_in:.2g} ≥ {alpha:.2g}): the control extrapolated worse, "
                "the data do not show a gap that tuning cannot close")
        return True, max(pn, pr or 0.0, p_in or 0.0), ""

    if not effects:
        return {**out, "effect": NONE, "reason": "no applicable effect", "confidence": 1.0, "p_used": None}
    if not out["gap_significant"]:
        return {**out, "effect": NONE, "confidence": min(1.0, ev["gap_p"]),
                "reason": f"the base model's gap is within the noise (AR(1) chi-square test, p = {ev['gap_p']:.2g})",
                "p_used": ev["gap_p"]}
    # (5) is about the effect's own part: where the control was fitted, an effect stands on it (and so shares
    # what tuning closes), and its shrink counts from the gap the better of `none` and the control leaves
    ref = RECALIBRATE if RECALIBRATE in cand and cand[RECALIBRATE]["heldout_gap"] < cand[NONE]["heldout_gap"] else NONE
    gap_ref = cand[ref]["heldout_gap"]
    left_by = GAP_LEFT_BY[ref]

    def own_shrink(e):
        return (1.0 - cand[e]["heldout_gap"] / gap_ref) if gap_ref > 0 else 0.0

    out["gap_reference"] = ref

    tied = []  # physical fits that pass (2)-(3) and score better than the instruments alone, not separated from them

    def judge(e):
        """(named effect, ok, p_used, why) for physical effect ``e`` (or the instruments alone)."""
        ok, p_used, why = passes(e)
        if sensor is not None and effect_of(e) != SENSOR:
            ps = p_of(e, sensor, physical)
            if ps >= alpha:
                ok_s, p_s, _ = passes(sensor)
                sensor_worse = ok_s and score[sensor] > score[e]
                if ok_s and not sensor_worse and not tied:
                    e, ok, p_used, why = sensor, True, p_s, ""
                elif ok:
                    if sensor_worse:
                        tied.append(e)
                    ok, p_used, why = False, ps, (f"{e} does not beat the instruments alone (sensor_artifacts; "
                                                  f"p = {ps:.2g} ≥ {alpha:.2g})" + (
                                                      ", which predict the held-out data worse: the data do not "
                                                      "separate the two" if sensor_worse else ""))
            else:
                p_used = max(p_used, ps)
        if ok and own_shrink(e) < min_shrink:
            ok, why = False, (f"{e} closes only {100 * own_shrink(e):.0f}% of the held-out gap {left_by} "
                              f"(< {100 * min_shrink:.0f}%)")
        if ok and effect_of(e) != SENSOR:  # (4b)
            for rival in rivals(e):
                pr = p_of(e, rival, physical)
                if pr >= alpha:
                    ok, p_used, why = False, pr, (
                        f"{e} does not beat {rival}, another effect's fit that predicts the held-out data at least "
                        f"as well (p = {pr:.2g} ≥ {alpha:.2g}): the data do not separate the two")
                    break
                p_used = max(p_used, pr)
        return e, ok, p_used, why

    def robust_loss(x):
        """Held-out loss on the Huber losses of the Diebold-Mariano test (a sum over tests of per-sample means,
        as ``heldout_loss``): a short burst that one prediction catches does not decide who predicts better."""
        return float(sum(np.nanmean(v) for v in robust_of(x)))

    def rivals(e):
        """(4b) The best-predicting fit (:func:`robust_loss`) of each other physical effect, where it predicts the
        held-out data at least as well as ``e``."""
        best = {}
        for m in physical:
            f = effect_of(m)
            if f != effect_of(e) and (f not in best or robust_loss(m) < robust_loss(best[f])):
                best[f] = m
        return [m for m in best.values() if robust_loss(m) <= robust_loss(e)]

    # the physical effects' fits (on the control and on the base) in the order of their held-out scores: the
    # effect of the first that passes is named (the tests are max-T corrected over the family, so trying
    # each does not inflate the false-positive rate)
    why = ""
    for e in sorted(physical, key=score.get) or ([sensor] if sensor else []):
        e, ok, p_used, why_e = judge(e)
        why = why or why_e
        if ok:
            return {**out, "effect": effect_of(e), "member": e, "reason": "passes the tests of the rule",
                    "confidence": max(0.0, 1.0 - p_used), "p_used": p_used, "own_shrink": own_shrink(e)}
    if sensor is not None and physical:
        ok_s, p_s, _ = passes(sensor)
        if ok_s and not tied and score[sensor] < score[NONE] and own_shrink(sensor) >= min_shrink:
            return {**out, "effect": SENSOR, "member": sensor, "reason": "passes the tests of the rule",
                    "confidence": max(0.0, 1.0 - p_s), "p_used": p_s, "own_shrink": own_shrink(sensor)}
    # none: confidence = how far the strongest effect was from passing
    p_min = min((max(p_of(x, NONE, effects), p_of(x, RECALIBRATE, effects) or 0.0) for x in effects), default=1.0)
    return {**out, "effect": NONE, "reason": why, "confidence": min(1.0, p_min), "p_used": p_min}


def rested_on(rule: dict) -> str:
    """The candidate fit a verdict from :func:`decide` rests on: the named effect's member, or for ``none`` the
    best-scoring candidate."""
    return rule.get("member", rule["effect"]) if rule["effect"] != NONE else rule["best"]


def analysis_flags(ev: dict, chosen: str, restricted: bool) -> list[str]:
    """What limits the analysis (stated in the verdict line and report.json), from the evidence
    (:func:`evidence` or :func:`load_evidence`) and the fit ``chosen`` that the verdict rests on."""
    flags = []
    if ev["n_tests"] == 1:
        flags.append("single test: held out = the later half of the same test")
    missing = [c for c in (RECALIBRATE, SENSOR) if c not in ev["candidates"]]
    if missing:
        flags.append("controls not fitted: " + ", ".join(missing) + (" (dropped by the candidate list)" if restricted
                                                                     else " (not applicable)"))
    if not ev["candidates"][chosen]["converged"]:
        flags.append(f"fit of {chosen} not converged")
    terrains = sorted(set(ev.get("terrains", [])))  # evidence cached before terrains were recorded: unknown
    if len(terrains) > 1:
        flags.append(f"tests on {len(terrains)} terrains ({', '.join(terrains)}): one effect is fitted to all of them, "
                     "so an effect of one terrain is not separated from another's (diagnose each terrain on its own: "
                     "--terrains each)")
    return flags


def flag_penalty(flags: list[str]) -> float:
    """The confidence factor of the analysis flags: 0.7 for a single test, 0.5 for a missing control, 0.8 for a
    fit that did not converge and 0.8 for tests on several terrains."""
    k = 1.0
    for f in flags:
        k *= 0.7 if f.startswith("single") else 0.5 if f.startswith("controls") else 0.8
    return k


def shrink_interval(data, sq_before, sq_after, point, seed=0, n_boot=N_BOOT) -> tuple[float, float]:
    """95 % interval of a gap shrink: block bootstrap (blocks = correlation time), recentred on ``point``."""
    rng = np.random.default_rng(seed)
    blocks, lengths = [], []
    for j, t in enumerate(data):
        dt = float(np.median(np.diff(t.t)))
        st = np.stack(list(sq_before[j].values()))
        x = np.nansum(st, axis=0) / np.maximum(np.sum(np.isfinite(st), axis=0), 1)
        blocks.append(block_length(x[np.any(np.isfinite(st), axis=0)], dt))
        lengths.append(len(t.t))
    vals = []
    for which, idx in block_draws(lengths, blocks, rng, n_boot):
        tb = [data[j] for j in which]
        gb = overall_gap(tb, [sq_before[j] for j in which], idx)
        ga = overall_gap(tb, [sq_after[j] for j in which], idx)
        if gb > 0:
            vals.append(1.0 - ga / gb)
    return centred_interval(point, np.array(vals))


def verdict_line(effect, confidence, shrink, ci, ins, ins_ci, reason, flags, own=None, reference=NONE) -> str:
    fl = f" [{'; '.join(flags)}]" if flags else ""
    if effect == NONE:
        return f"none (confidence {confidence:.2f}): {reason}{fl}"
    own_txt = (f"; by itself {100 * own:.0f}% of the held-out gap {GAP_LEFT_BY[reference]}"
               if own is not None and reference == RECALIBRATE else "")
    return (f"{effect} (confidence {confidence:.2f}): held-out gap shrink {100 * shrink:.0f}% (95% CI {100 * ci[0]:.0f}"
            f"-{100 * ci[1]:.0f}%), in-sample {100 * ins:.0f}% (95% CI {100 * ins_ci[0]:.0f}-{100 * ins_ci[1]:.0f}%)"
            f"{own_txt}{fl}")


def save_evidence(ev: dict, path: Path) -> None:
    """Cache the evidence (per-sample losses and signed held-out errors as npz, the rest as JSON) so that
    :func:`decide` re-runs in milliseconds."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    arrs = {}
    for kind in ("ws_held", "ws_full"):
        for n, lst in ev[kind].items():
            for j, x in enumerate(lst):
                arrs[f"{kind}|{n}|{j}"] = x
    for n, lst in ev["err_held"].items():
        for j, d in enumerate(lst):
            for sig, x in d.items():
                arrs[f"err_held|{n}|{j}|{sig}"] = x
    np.savez_compressed(path / "evidence.npz", **arrs)
    meta = {k: v for k, v in ev.items() if not k.startswith("_") and k not in ("ws_held", "ws_full", "err_held")}
    (path / "evidence.json").write_text(json.dumps(_clean(meta), indent=1) + "\n")


def without(ev: dict, names) -> dict:
    """``ev`` without the candidates ``names`` (e.g. to re-score a cache made with a larger candidate set; the
    held-out masks are unchanged where those candidates predicted every sample the others did)."""
    names = set(names)
    out = dict(ev)
    for key in ("candidates", "err_held", "ws_held", "ws_full", "_sq_held", "_sq_full"):
        if key in ev:
            out[key] = {n: v for n, v in ev[key].items() if n not in names}
    return out


def load_evidence(path: Path) -> dict:
    """Evidence written by :func:`save_evidence`.

    Raises:
        DiagnosisError: the cache lacks the signed held-out errors (written by an earlier version: re-fit it).
    """
    path = Path(path)
    ev = json.loads((path / "evidence.json").read_text())
    ev["ws_held"], ev["ws_full"], err = {}, {}, {}
    with np.load(path / "evidence.npz") as z:
        for key in z.files:
            kind, n, j, *sig = key.split("|")
            if kind == "err_held":
                err.setdefault(n, {}).setdefault(int(j), {})[sig[0]] = z[key]
            else:
                ev[kind].setdefault(n, {})[int(j)] = z[key]
    if not err or "noise" not in ev:
        raise DiagnosisError(f"{path}: the evidence cache has no signed held-out errors (an earlier format); "
                             "delete it and run the diagnosis again")
    for kind in ("ws_held", "ws_full"):
        ev[kind] = {n: [d[j] for j in sorted(d)] for n, d in ev[kind].items()}
    ev["err_held"] = {n: [d[j] for j in sorted(d)] for n, d in err.items()}
    ev["noise"] = [{sig: tuple(v) for sig, v in d.items()} for d in ev["noise"]]
    return ev


def check_options(*, seed: int = 0, rounds: int = 3, search_points: int = 16, polish_iters: int = 4,
                  alpha: float = ALPHA, substep: float = FIT_SUBSTEP, pad_s: float | None = None,
                  candidates: list[str] | None = None) -> None:
    """Raise :class:`.data.DiagnosisError` naming the option if a fit or rule option of :func:`diagnose` cannot
    work: ``seed`` (an integer >= 0), ``rounds`` and ``polish_iters`` (integers >= 0), ``search_points`` (an
    integer >= 1), ``alpha`` (strictly between 0 and 1), ``substep`` (:func:`trackenv.simulate.check_substep`),
    ``pad_s`` (None or a positive duration [s]), ``candidates`` (None for all, or at least one name: an empty list
    is not "all of them"). Checked before any log is read or any fit starts."""
    from ..simulate import MAX_SUBSTEP, check_substep

    for name, value, low, what in (("seed", seed, 0, "an integer >= 0"), ("rounds", rounds, 0, "an integer >= 0"),
                                   ("search_points", search_points, 1, "an integer >= 1"),
                                   ("polish_iters", polish_iters, 0, "an integer >= 0 (0: no polish)")):
        if not (is_integer(value) and value >= low):
            raise DiagnosisError(f"{name} must be {what}, got {value!r}")
    if not (is_real(alpha) and 0.0 < alpha < 1.0):
        raise DiagnosisError(f"alpha (the rule's significance level) must lie strictly between 0 and 1, got {alpha!r}")
    try:
        check_substep(substep, MAX_SUBSTEP)
    except ValueError as exc:
        raise DiagnosisError(f"the fits' {exc}") from None
    if pad_s is not None and not is_positive(pad_s):
        raise DiagnosisError(f"pad_s must be a positive duration [s] or None, got {pad_s!r}")
    if candidates is not None and not list(candidates):
        names = ", ".join(c.name for c in candidate_set())
        raise DiagnosisError(f"candidates is empty: name at least one of {names}, or leave the option out for all of them")


def diagnose(folder: str | Path, out_dir: str | Path | None = None, *, tests: list[str] | None = None,
             internal_resistance: str = "constant", candidates: list[str] | None = None, substep: float = FIT_SUBSTEP,
             seed: int = 0, rounds: int = 3, search_points: int = 16, polish_iters: int = 4, alpha: float = ALPHA, figures: bool = True,
             progress: bool = True, pad_s: float | None = None, cache: str | Path | None = None,
             jacobian: str = "secant", vehicle: str | Path | None = None,
             after: str | Path | None = None) -> Diagnosis:
    """Diagnose the gap between the simulator and the field tests in ``folder`` (one sub-folder per test).

    Args:
        folder: a folder of docs/model.md §9 field-log folders (or one field-log folder).
        out_dir: where ``report.md``, ``report.json`` and the figures go (``None``: nothing written).
        tests: only these sub-folders. internal_resistance: the base model's (``constant``/``viscous``).
        candidates: restrict the candidate set (names from :func:`.candidates.candidate_set`;
            ``none`` is always included). substep: integration substep of the fits [s].
        seed: seeds the search and the bootstrap. rounds: refinement rounds of the search.
        search_points: points per search round (at least 3 per fold). polish_iters: Levenberg-Marquardt
            iterations per fit (0: derivative-free search only). alpha: significance level of the rule.
        pad_s: pad every test to this duration [s] in one batch (fixed shapes across diagnoses, :mod:`.batch`).
        cache: a folder to write the verdict's evidence to (:func:`save_evidence`).
        jacobian: the polish's Jacobian, ``"secant"`` (central differences, batched) or ``"forward"``
            (``jax.jacfwd``); see :mod:`.polish`.
        figures: draw the PNGs. progress: show a progress bar on stderr.
        vehicle: a vehicle id or YAML path used for every test instead of its ``meta.json`` vehicle (e.g. a
            vehicle calibrated on other runs, :mod:`trackenv.calibrate`).
        after: the ``report.json`` (or its folder) of an earlier diagnosis: the fit it named, at its values
            fitted on all the data, joins the base model (with the fits its own base carried), and the
            candidates look for what remains. Its effect is not a candidate again (:class:`.candidates.NamedFit`).

    Raises:
        DiagnosisError: nothing usable in ``folder``, or a bad option.
    """
    t_start = time.perf_counter()
    from .polish import JACOBIANS

    check_options(seed=seed, rounds=rounds, search_points=search_points, polish_iters=polish_iters, alpha=alpha,
                  substep=substep, pad_s=pad_s, candidates=candidates)

    if jacobian not in JACOBIANS:
        raise DiagnosisError(f"jacobian must be one of {', '.join(JACOBIANS)}, got {jacobian!r}")
    if internal_resistance not in ("constant", "viscous"):
        raise DiagnosisError(f"internal_resistance must be 'constant' or 'viscous', got {internal_resistance!r}")
    named = named_fits_from_report(after, internal_resistance) if after is not None else ()
    data, excluded = load_tests(folder, tests)
    all_cands = candidate_set(internal_resistance)
    names = [c.name for c in all_cands]
    if candidates:
        unknown = [c for c in candidates if c not in names]
        if unknown:
            raise DiagnosisError(f"unknown candidate(s) {', '.join(unknown)}; known: {', '.join(names)}")
        all_cands = [c for c in all_cands if c.name in candidates or c.name == NONE]
    sim = BatchSimulator(data, internal_resistance, substep, pad_s=pad_s, vehicle=vehicle, named=named)
    deformable = [float(b.terrain.deformable) > 0.5 for b in sim.base]
    skipped = {}
    cands = []
    in_base = {nf.effect: nf for nf in named}
    for c in all_cands:
        why = (f"already in the base model ({in_base[c.name].member}, named by {in_base[c.name].source})"
               if c.name in in_base else c.applicable(deformable))
        if why:
            skipped[c.name] = why
        else:
            cands.append(c)
    folds = make_folds(data)
    # progress: simulations of a test done out of the planned total (each candidate's :func:`.fit.fit_plan`)
    from tqdm.auto import tqdm

    on_control = RECALIBRATE in {c.name for c in cands}

    def branches_of(c) -> tuple[int, ...]:
        """The fits of ``c`` refined on top of the control's (0) and on the base model (1); () if it stands on nothing.
        The instruments-only candidate competes only as fitted on the control: its base branch is sampled by the
        shared design but not refined."""
        if not (c.is_effect and on_control):
            return ()
        return (0,) if c.name == SENSOR else (0, 1)

    planned = sum(fit_plan(c, len(data), len(folds) + 1, min_round=search_points, rounds=rounds,
                           polish_iters=polish_iters, jacobian=jacobian, n_branch=2 if branches_of(c) else 1,
                           refined=len(branches_of(c)) or 1) for c in cands)
    bar = tqdm(total=planned, desc="diagnose", unit="sim", disable=not progress, leave=False)
    fits: dict[str, CandidateFit] = {}
    # none, then the control, then every effect twice from one shared search: on top of the control's fit
    # (fold by fold) and on the base model itself (`<effect>@base`)
    order = sorted(cands, key=lambda c: (c.name != NONE, c.name != RECALIBRATE))
    t_fit = {}
    for c in order:
        bar.set_postfix_str(c.name)
        t0 = time.perf_counter()
        if branches_of(c):
            rc = fits[RECALIBRATE]
            c = c.standing_on(rc.candidate)
            below = [[dict(fd.params), dict(rc.candidate.anchor)] for fd in [*rc.folds, rc.full]]
            branch_fits = fit_candidate(sim, c, folds, seed=seed, rounds=rounds, min_round=search_points,
                                        polish_iters=polish_iters, jacobian=jacobian, progress=bar.update,
                                        below=below, each_branch=branches_of(c))
            fits[c.name] = branch_fits[0]
            t_fit[c.name] = time.perf_counter() - t0  # one search for both fits
            if len(branch_fits) > 1:
                fits[c.name + ON_BASE] = branch_fits[1]
                t_fit[c.name + ON_BASE] = t_fit[c.name]
        else:
            fits[c.name] = fit_candidate(sim, c, folds, seed=seed, rounds=rounds, min_round=search_points,
                                         polish_iters=polish_iters, jacobian=jacobian, progress=bar.update)
            t_fit[c.name] = time.perf_counter() - t0
    bar.close()

    base = fits[NONE]
    ev = evidence(data, fits)
    rule = decide(ev, alpha=alpha)
    effect, best, reason = rule["effect"], rule["best"], rule["reason"]
    sq_base = ev["_sq_base"]
    gap_before = ev["gap_before"]
    ranking = []
    sc = _scores(fits)
    for n, f in fits.items():
        rk = ev["candidates"][n]
        ranking.append({
            "effect": n, "n_params": f.candidate.n_params,
            "description": f.candidate.description + (" (on the base model itself)" if n.endswith(ON_BASE) else
                                                      " (on the fitted control)" if f.candidate.on is not None else ""),
            "heldout_nrmse": overall_nrmse(data, ev["_sq_held"][n]), "heldout_gap": rk["heldout_gap"],
            "heldout_gap_range": overall_gap_range(data, ev["_sq_held"][n]),
            "insample_gap": rk["insample_gap"],
            "heldout_gap_shrink": rk["heldout_shrink"], "insample_gap_shrink": rk["insample_shrink"],
            "p_beats_none": rk["p_beats_none"], "z_beats_none": rk["z_beats_none"],
            "heldout_loss": float(np.sum(f.heldout_loss)), "score": sc[n],
            "params": f.full.params, "fold_params": [fd.params for fd in f.folds],
            "heldout_loss_per_test": {data[j].name: float(x) for j, x in enumerate(f.heldout_loss)},
            "insample_loss_per_test": {data[j].name: float(x) for j, x in enumerate(f.full_loss)},
            "converged": f.converged,
            "polish": {"full": f.full.polish, "folds": [fd.polish for fd in f.folds]},
            "simulations": f.n_simulations, "fit_time_s": t_fit[n], "notes": f.notes,
        })
    ranking.sort(key=lambda r: r["score"])
    chosen_name = rested_on(rule)
    chosen = fits[chosen_name]
    sq_after = ev["_sq_held"][chosen_name]
    held_base = ev["_sq_base_held"]
    gap_before_held = overall_gap(data, held_base)
    gap_after = overall_gap(data, sq_after)
    shrink = ev["candidates"][chosen_name]["heldout_shrink"]
    ins = ev["candidates"][chosen_name]["insample_shrink"]
    shrink_ci = shrink_interval(data, held_base, sq_after, shrink, seed=seed)
    ins_ci = shrink_interval(data, sq_base, ev["_sq_full"][chosen_name], ins, seed=seed + 1)
    flags = analysis_flags(ev, chosen_name, restricted=bool(candidates))
    confidence = rule["confidence"] * flag_penalty(flags)
    line = verdict_line(effect, confidence, shrink, shrink_ci, ins, ins_ci, reason, flags, rule.get("own_shrink"),
                        rule.get("gap_reference", NONE))
    if named:  # what the verdict is conditional on comes first in its line
        line = f"after {' + '.join(nf.member for nf in named)}: {line}"
    rounding = rounding_checks(sim, data, chosen_name, fits)
    rows = cell_table(data, base.full_pred, chosen.heldout_pred)
    cell_ci(data, rows, sq_base, sq_after, seed=seed)
    significant = rule["gap_significant"]
    carriers = gap_carriers(rows) if significant else []
    report = {
        "tool": "trackenv diagnose", "folder": str(folder),
        "data_label": data_label(data),
        "base_model": {"internal_resistance": internal_resistance, "substep_s": substep,
                       "vehicle": str(vehicle) if vehicle else "each log's meta.json vehicle",
                       "input_modes": sorted({t.drive_kind for t in data}),
                       "after": [nf.to_json() for nf in named]},
        "verdict": {
            "effect": effect, "confidence": confidence, "verdict_line": line, "flags": flags,
            "heldout_gap_shrink": shrink if effect != NONE else 0.0,
            "heldout_gap_shrink_ci": list(shrink_ci) if effect != NONE else None,
            "insample_gap_shrink": ins, "insample_gap_shrink_ci": list(ins_ci),
            "heldout_gap_shrink_own": rule.get("own_shrink"), "own_shrink_reference": rule.get("gap_reference"),
            "best_candidate": best, "reason": reason, "gap_significant": significant,
            "gap_test": {"p": rule["gap_p"], "z_max": ev["gap_z_max"], "cells": ev["gap_cells_tested"]},
            "tests_used": rule["tests"],
            "gap_before": gap_before, "gap_before_heldout": gap_before_held,
            "gap_after": gap_after if effect != NONE else gap_before_held,
            "gap_before_range": overall_gap_range(data, sq_base), "gap_after_range": overall_gap_range(data, sq_after),
            "gap_unit": "noise units: sqrt(mean over tests of mean over signals of (MSE - sigma^2)+ / (sigma^2 + (0.01 span)^2))",
            "p_beats_none": ev["candidates"][chosen_name]["p_beats_none"], "after_model": chosen_name,
            "best_candidate_shrink": shrink, "best_candidate_shrink_ci": list(shrink_ci),
            "converged": chosen.converged,
        },
        "ranking": ranking,
        "rounding_check": rounding,
        "not_applicable": [{"effect": k, "why": v} for k, v in skipped.items()],
        "gap_cells": [{k: r[k] for k in ("test", "signal", "phase", "t_start", "t_end", "nrmse_before", "gap_before",
                                         "bias_before", "lag_before_s", "share_of_gap")} for r in carriers],
        "cells": rows,
        "tests": [{"test": t.name, "terrain": t.terrain, "maneuver": t.log.maneuver, "current_sensor": t.sensor,
                   "synthetic": t.log.synthetic, "duration_s": t.duration, "n_samples": len(t.t),
                   "signals": t.signals, "noise": t.noise, "span": t.span,
                   "phases": _spans(t), "notes": t.notes} for t in data],
        "excluded": excluded,
        "method": {
            "folds": [{"kind": fd.kind, "calibration": [data[i].name for i in fd.calibration],
                       "heldout": data[fd.held].name + (" (tail)" if fd.kind == "forward" else "")} for fd in folds],
            "loss": "per test: mean over signals of mean((sim-meas)^2)/(sigma^2 + (0.01 span)^2); summed over tests",
            "score": f"held-out loss x (1 + {COMPLEXITY} x fitted parameters) (ranking only; the verdict uses the tests)",
            "gap": "noise units: sqrt(mean over tests of mean over signals of max(MSE - sigma^2, 0)/(sigma^2 + (0.01 span)^2)); "
                   "gap_range: sqrt(mean over test x signal of max(MSE - sigma^2, 0)/span^2) (systematic NRMSE)",
            "rule": RULE_TEXT,
            "thresholds": {"alpha": alpha, "bonferroni_m": rule["m"], "min_shrink": MIN_SHRINK},
            "search": f"Latin hypercube + {rounds} cross-entropy rounds per fold, then Levenberg-Marquardt "
                      f"({polish_iters} iterations at most, {jacobian} Jacobian); seed {seed}",
        },
        "timing": {"wall_s": time.perf_counter() - t_start, "fit_s": t_fit,
                   "vehicle_seconds_simulated": sim.n_vehicle_seconds},
    }
    diag = Diagnosis(data, excluded, fits, report)
    diag.evidence = ev
    if cache is not None:
        save_evidence(ev, Path(cache))
    if out_dir is not None:
        from .report import write_report

        diag.out_dir = Path(out_dir)
        diag.files = write_report(diag, Path(out_dir), figures=figures)
        report["timing"]["wall_s"] = time.perf_counter() - t_start
        import json

        (Path(out_dir) / "report.json").write_text(json.dumps(_clean(report), indent=1, allow_nan=False) + "\n")
    return diag


def _spans(t: TestData) -> list:
    from .phases import phase_spans

    return [{"phase": p, "t0": a, "t1": b} for p, a, b in phase_spans(t.t, t.phase)]
