"""``diagnose``: where the simulation disagrees with field logs, which unmodelled effect explains it,
and how far the gap closes once that effect is added (issue 5; MODEL.md §8).

1. **Where** — every test is replayed on the base model; the gap is measured per test × signal ×
   phase (:mod:`.phases`, :mod:`.metrics`) and the cells that carry it are named.
2. **Which** — each candidate (:mod:`.candidates`: the six effects, the ``recalibrate_base`` control,
   ``none``) is fitted on calibration tests and scored on held-out tests (:mod:`.fit`: grouped by test,
   leave-one-test-out). Score = held-out loss × (1 + 0.02 · number of fitted parameters).
3. **Verdict** — the best-scoring effect is named only if all of these hold, else ``none``:
   the base model's gap is significant against the noise (some test × signal with MSE > 2σ² and an
   overall systematic gap ≥ 1 noise unit, :func:`.metrics.overall_gap`); the effect shrinks the held-out gap by ≥ 20 %; it beats
   ``none`` in ≥ 90 % of the paired block-bootstrap resamples; and it beats ``recalibrate_base`` by
   ≥ 10 % of held-out loss (else the gap is one that mere tuning closes: verdict ``none`` with that
   reason). Physical effects carry an encoder layer (:mod:`.fit`); one that does not beat
   ``sensor_artifacts`` (window + gyro bias alone) by 10 % gives way to it (the simpler explanation). ``confidence`` = the fraction of bootstrap resamples in which the named candidate is still
   the verdict's winner (for ``none``: in which no effect passes).
4. **How far** — held-out gap before vs after, overall (with a bootstrap CI) and per cell.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .batch import FIT_SUBSTEP, BatchSimulator
from .candidates import NONE, RECALIBRATE, candidate_set
from .data import DiagnosisError, TestData, load_tests
from .fit import CandidateFit, fit_candidate, make_folds
from .metrics import (block_indices, bootstrap_shrink, cell_ci, cell_table, gap_carriers, overall_gap,
                      overall_gap_range, overall_nrmse, signal_weight, sq_errors)

COMPLEXITY = 0.02
MIN_SHRINK = 0.20
MIN_GAP = 1.0  # noise units (metrics.overall_gap)
MIN_NOISE_RATIO = 2.0
MARGIN = 0.10
SENSOR = "sensor_artifacts"
P_BEATS_NONE = 0.9


@dataclass
class Diagnosis:
    """The result of :func:`diagnose` (``report`` is what ``report.json`` holds)."""

    tests: list
    excluded: list
    fits: dict  # name -> CandidateFit
    report: dict
    out_dir: Path | None = None
    files: dict = field(default_factory=dict)

    @property
    def verdict(self) -> dict:
        return self.report["verdict"]


def _weighted_sq(tests: list[TestData], sq: list[dict]) -> list[np.ndarray]:
    """Per test: (K,) the loss's per-sample term (mean over signals of weighted squared error, :func:`sq_errors`)."""
    out = []
    for j, t in enumerate(tests):
        st = np.stack([e2 * signal_weight(t, sig) for sig, e2 in sq[j].items()])
        n_ok = np.sum(np.isfinite(st), axis=0)
        out.append(np.where(n_ok > 0, np.nansum(st, axis=0) / np.maximum(n_ok, 1), np.nan))
    return out


def _scores(fits: dict) -> dict:
    return {n: float(np.sum(f.heldout_loss)) * (1.0 + COMPLEXITY * f.candidate.n_params) for n, f in fits.items()}


def _decide(tests, fits: dict, ws: dict, idx=None, which=None) -> tuple[str, str, str]:
    """(verdict effect, best candidate, reason) from per-sample loss terms ``ws`` (optionally resampled)."""
    def total(name):
        if idx is None:
            return float(sum(np.nanmean(x) for x in ws[name]))
        return float(sum(np.nanmean(ws[name][j][ii]) for j, ii in zip(which, idx)))

    sc = {n: total(n) * (1.0 + COMPLEXITY * f.candidate.n_params) for n, f in fits.items()}
    best = min(sc, key=sc.get)
    physical = [n for n in sc if fits[n].candidate.is_effect and n != SENSOR]
    pool = physical + ([SENSOR] if SENSOR in sc else [])
    if not pool:
        return NONE, best, "no applicable effect"
    e = min(physical, key=sc.get) if physical else SENSOR
    if SENSOR in sc and e != SENSOR and sc[SENSOR] < sc[NONE] and sc[e] > (1.0 - MARGIN) * sc[SENSOR]:
        e = SENSOR  # the instruments alone do (nearly) as well: the simpler explanation
    if sc[e] >= sc[NONE]:
        return NONE, best, f"no effect improves the held-out fit (best effect {e})"
    if RECALIBRATE in sc and sc[e] > (1.0 - MARGIN) * sc[RECALIBRATE]:
        return NONE, RECALIBRATE if sc[RECALIBRATE] <= sc[e] else e, (
            f"recalibrating the base parameters does as well as the best effect ({e}): a gap that tuning closes")
    return e, e, "best held-out score"


def diagnose(folder: str | Path, out_dir: str | Path | None = None, *, tests: list[str] | None = None,
             internal_resistance: str = "constant", candidates: list[str] | None = None, substep: float = FIT_SUBSTEP,
             seed: int = 0, rounds: int = 3, figures: bool = True, progress: bool = True) -> Diagnosis:
    """Diagnose the gap between the simulator and the field tests in ``folder`` (one sub-folder per test).

    Args:
        folder: a folder of MODEL.md §9 field-log folders (or one field-log folder).
        out_dir: where ``report.md``, ``report.json`` and the figures go (``None``: nothing written).
        tests: only these sub-folders. internal_resistance: the base model's (``constant``/``viscous``).
        candidates: restrict the candidate set (names from :func:`.candidates.candidate_set`;
            ``none`` is always included). substep: integration substep of the fits [s].
        seed: seeds the search and the bootstrap. rounds: refinement rounds of the search.
        figures: draw the PNGs. progress: show a progress bar on stderr.

    Raises:
        DiagnosisError: nothing usable in ``folder``, or a bad option.
    """
    t_start = time.perf_counter()
    if internal_resistance not in ("constant", "viscous"):
        raise DiagnosisError(f"internal_resistance must be 'constant' or 'viscous', got {internal_resistance!r}")
    data, excluded = load_tests(folder, tests)
    all_cands = candidate_set(internal_resistance)
    names = [c.name for c in all_cands]
    if candidates:
        unknown = [c for c in candidates if c not in names]
        if unknown:
            raise DiagnosisError(f"unknown candidate(s) {', '.join(unknown)}; known: {', '.join(names)}")
        all_cands = [c for c in all_cands if c.name in candidates or c.name == NONE]
    sim = BatchSimulator(data, internal_resistance, substep)
    deformable = [float(b.terrain.deformable) > 0.5 for b in sim.base]
    skipped = {}
    cands = []
    for c in all_cands:
        why = c.applicable(deformable)
        if why:
            skipped[c.name] = why
        else:
            cands.append(c)
    folds = make_folds(len(data))
    # progress: vehicle-simulations done out of the planned total
    from tqdm.auto import tqdm

    planned = 0
    for c in cands:
        if c.n_params == 0:
            planned += len(data)
        else:
            F = len(folds) + 1
            m = max(3, int(np.ceil(16 / F)))
            planned += len(data) * F * m * (1 + rounds)
    bar = tqdm(total=planned, desc="diagnose", unit="sim", disable=not progress, leave=False)
    fits: dict[str, CandidateFit] = {}
    order = [c for c in cands if c.name == NONE] + [c for c in cands if c.name != NONE]
    t_fit = {}
    for c in order:
        bar.set_postfix_str(c.name)
        t0 = time.perf_counter()
        fits[c.name] = fit_candidate(sim, c, folds, seed=seed, rounds=rounds, progress=bar.update)
        t_fit[c.name] = time.perf_counter() - t0
    bar.close()

    base = fits[NONE]
    sq_held = {n: sq_errors(data, f.heldout_pred) for n, f in fits.items()}
    sq_full = {n: sq_errors(data, f.full_pred) for n, f in fits.items()}
    sq_base = sq_full[NONE]
    ws = {n: _weighted_sq(data, sq) for n, sq in sq_held.items()}
    sc = _scores(fits)
    gap_before = overall_gap(data, sq_base)
    noise_ratio_max = max(float(np.nanmean(sq_base[j][s]) / t.noise[s] ** 2) for j, t in enumerate(data)
                          for s in t.measured)
    significant = bool(gap_before >= MIN_GAP and noise_ratio_max >= MIN_NOISE_RATIO)
    ranking = []
    for n, f in fits.items():
        sq = sq_held[n]
        g = overall_gap(data, sq)
        ranking.append({
            "effect": n, "description": f.candidate.description, "n_params": f.candidate.n_params,
            "heldout_nrmse": overall_nrmse(data, sq), "heldout_gap": g,
            "heldout_gap_range": overall_gap_range(data, sq),
            "insample_gap": overall_gap(data, sq_full[n]),
            "heldout_gap_shrink": (1.0 - g / gap_before) if gap_before > 0 else 0.0,
            "heldout_loss": float(np.sum(f.heldout_loss)), "score": sc[n],
            "params": f.full.params, "fold_params": [fd.params for fd in f.folds],
            "heldout_loss_per_test": {data[j].name: float(x) for j, x in enumerate(f.heldout_loss)},
            "insample_loss_per_test": {data[j].name: float(x) for j, x in enumerate(f.full_loss)},
            "converged": f.converged, "simulations": f.n_simulations, "fit_time_s": t_fit[n], "notes": f.notes,
        })
    ranking.sort(key=lambda r: r["score"])
    shrink_of = {r["effect"]: r["heldout_gap_shrink"] for r in ranking}

    def verdict_of(idx=None, which=None):
        eff, best, reason = _decide(data, fits, ws, idx, which)
        if eff != NONE and not significant:
            return NONE, best, "the base model's gap is within the noise"
        if eff != NONE and shrink_of[eff] < MIN_SHRINK:
            return NONE, best, f"the best effect ({eff}) closes only {100 * shrink_of[eff]:.0f}% of the held-out gap"
        return eff, best, reason

    effect, best, reason = verdict_of()
    if not significant:
        reason = (f"the base model's gap is within the noise (systematic gap {gap_before:.2f} noise units, "
                  f"largest MSE/σ² {noise_ratio_max:.2f})")
    # bootstrap: paired over tests and blocks
    rng = np.random.default_rng(seed + 7)
    agree, beats_none = 0, 0
    n_boot = 200
    for _ in range(n_boot):
        which, idx = block_indices(data, rng)
        e_b, _, _ = verdict_of(idx, which)
        agree += e_b == effect
        if effect != NONE:
            tot = lambda n: sum(np.nanmean(ws[n][j][ii]) for j, ii in zip(which, idx))  # noqa: E731
            beats_none += tot(effect) < tot(NONE)
    p_beats = beats_none / n_boot if effect != NONE else None
    if effect != NONE and p_beats < P_BEATS_NONE:
        reason = f"{effect} beats the base model in only {100 * p_beats:.0f}% of bootstrap resamples"
        effect = NONE
    confidence = agree / n_boot
    chosen = fits[effect] if effect != NONE else fits[best]
    sq_after = sq_held[chosen.candidate.name]
    gap_after = overall_gap(data, sq_after)
    shrink = (1.0 - gap_after / gap_before) if gap_before > 0 else 0.0
    shrink_ci = bootstrap_shrink(data, sq_base, sq_after, seed=seed)
    rows = cell_table(data, base.full_pred, chosen.heldout_pred)
    cell_ci(data, rows, sq_base, sq_after, seed=seed)
    carriers = gap_carriers(rows) if significant else []
    synthetic = [t.name for t in data if t.log.synthetic]
    report = {
        "tool": "trackenv diagnose", "folder": str(folder),
        "data_label": ("SYNTHETIC: " + ", ".join(synthetic) + " say synthetic: true in meta.json (not measured)")
        if synthetic else "field logs (meta.json does not say synthetic)",
        "base_model": {"internal_resistance": internal_resistance, "substep_s": substep},
        "verdict": {
            "effect": effect, "confidence": confidence, "heldout_gap_shrink": shrink if effect != NONE else 0.0,
            "heldout_gap_shrink_ci": list(shrink_ci) if effect != NONE else None,
            "best_candidate": best, "reason": reason, "gap_significant": significant,
            "gap_before": gap_before, "gap_after": gap_after if effect != NONE else gap_before,
            "gap_before_range": overall_gap_range(data, sq_base), "gap_after_range": overall_gap_range(data, sq_after),
            "gap_unit": "noise units: sqrt(mean over tests of mean over signals of (MSE - sigma^2)+ / (sigma^2 + (0.01 span)^2))",
            "p_beats_none": p_beats, "after_model": chosen.candidate.name,
            "insample_gap_shrink": (1.0 - overall_gap(data, sq_full[chosen.candidate.name]) / gap_before)
            if gap_before > 0 else 0.0,
            "best_candidate_shrink": shrink, "best_candidate_shrink_ci": list(shrink_ci),
        },
        "ranking": ranking,
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
            "folds": [{"calibration": [data[i].name for i in c], "heldout": [data[i].name for i in h]}
                      for c, h in folds] or "single test: scored in-sample (nothing to hold out)",
            "loss": "per test: mean over signals of mean((sim-meas)^2)/(sigma^2 + (0.01 span)^2); summed over tests",
            "score": f"held-out loss x (1 + {COMPLEXITY} x fitted parameters)",
            "gap": "noise units: sqrt(mean over tests of mean over signals of max(MSE - sigma^2, 0)/(sigma^2 + (0.01 span)^2)); "
                   "gap_range: sqrt(mean over test x signal of max(MSE - sigma^2, 0)/span^2) (systematic NRMSE)",
            "thresholds": {"min_gap": MIN_GAP, "min_noise_ratio": MIN_NOISE_RATIO, "min_shrink": MIN_SHRINK,
                           "margin": MARGIN, "p_beats_none": P_BEATS_NONE},
            "search": f"Latin hypercube + {rounds} cross-entropy rounds per fold; seed {seed}",
        },
        "timing": {"wall_s": time.perf_counter() - t_start, "fit_s": t_fit,
                   "vehicle_seconds_simulated": sim.n_vehicle_seconds},
    }
    diag = Diagnosis(data, excluded, fits, report)
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


def _clean(x):
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
