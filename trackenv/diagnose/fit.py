"""Fit a candidate's parameters on calibration tests and predict the held-out ones.

**Loss** of a prediction on one test: the mean over its measured signals of

    mean_k (sim_k − meas_k)² / (σ² + (0.01·span)²)

with σ the signal's noise level and span its robust range (:mod:`.data`): a χ² per sample that
gives each signal equal say, with a 1 %-of-range floor for what a model can be expected to match
(so that the quietest channel does not dominate). The loss of a set of tests is the sum over tests
(each test counts once, whatever its length).

**Folds**: grouped by test, never by sample — leave-one-test-out for up to ``MAX_FOLDS`` tests,
else that many groups of whole tests — plus the *full* fit on every test (the parameters reported).

**Search** (a robust, derivative-free optimizer; the batched simulator makes a population cheap):
one global round of Latin-hypercube points in the candidate's unit cube, the anchor (≈ the base
model) among them, evaluated on every test; then ``rounds`` rounds of the cross-entropy method *per
fold*: new points drawn around the fold's best point (spread = the spread of its 4 best, shrinking
0.6× per round) from the fold's *calibration* losses only, evaluated in one batch for all folds.
Every physical effect (not ``none``, ``recalibrate_base``, or ``sensor_artifacts``, which has its own
window) also carries an *encoder layer*: each simulated point is scored with the speed averaged over each of
``ENCODER_WINDOWS`` (free: no new simulation), and the window is selected with the point. Encoder
averaging is common in field logs and would otherwise be the first thing any effect is fitted to
explain; with the layer, an effect wins on what the encoder cannot explain, and the verdict
(:mod:`.core`) names ``sensor_artifacts`` when an effect is no clearly better than the instruments alone.
A fold's parameters are the best point of its pool (the global points and its own) on its
calibration tests; its held-out predictions are that point's predictions on the held-out tests.
Simulations that diverge get an infinite loss; a fold whose best loss is not finite, or that still
improved by more than 2 % in its last round, is reported as not converged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import qmc

from .batch import BatchSimulator
from .candidates import Candidate
from .data import TestData
from .metrics import MODEL_FLOOR, signal_error, signal_weight  # noqa: F401  (MODEL_FLOOR: the loss's floor)

MAX_FOLDS = 6
ENCODER_WINDOWS = (0.0, 0.05, 0.1, 0.2, 0.35)  # s, the encoder layer every candidate but none carries


def test_loss(test: TestData, pred: dict) -> np.ndarray:
    """Loss of predictions ``pred[sig]`` (K, S) on one test -> (S,)."""
    terms = []
    for sig, meas in test.measured.items():
        ok = np.isfinite(meas) & test.fit_mask
        err = signal_error(test, sig, pred[sig])[ok]
        terms.append(np.mean(err**2, axis=0) * signal_weight(test, sig))
    out = np.mean(terms, axis=0)
    return np.where(np.isfinite(out), out, np.inf)


def make_folds(n_tests: int, max_folds: int = MAX_FOLDS) -> list[tuple[tuple, tuple]]:
    """[(calibration tests, held-out tests)]: leave-one-test-out, or contiguous groups of tests."""
    if n_tests < 2:
        return []
    k = min(n_tests, max_folds)
    groups = np.array_split(np.arange(n_tests), k)
    return [(tuple(int(i) for i in range(n_tests) if i not in g), tuple(int(i) for i in g)) for g in groups]


@dataclass
class FoldFit:
    calibration: tuple
    heldout: tuple
    unit: np.ndarray  # (p,) best point
    params: dict  # physical
    calibration_loss: float
    converged: bool


@dataclass
class CandidateFit:
    candidate: Candidate
    full: FoldFit
    folds: list
    heldout_pred: list  # per test: {sig: (K,)} predicted by the fold that held it out (full fit if no folds)
    full_pred: list  # per test: {sig: (K,)} of the full fit
    heldout_loss: np.ndarray  # (n_tests,)
    full_loss: np.ndarray  # (n_tests,)
    n_simulations: int
    diverged_fraction: float
    notes: list = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return self.full.converged and all(f.converged for f in self.folds)


class _Pool:
    """Evaluated points: unit coords, per-test losses, per-test predictions."""

    def __init__(self, windows=()):
        self.unit, self.loss, self.pred, self.owner, self.window = [], [], [], [], []
        self.windows = tuple(windows) or (None,)

    def add(self, unit, loss, pred, owner):
        nw = len(self.windows)
        for c in range(loss.shape[1]):
            s = c // nw
            self.unit.append(unit[s])
            self.loss.append(loss[:, c])
            self.pred.append([{k: v[:, c] for k, v in p.items()} for p in pred])
            self.owner.append(owner[s])
            self.window.append(self.windows[c % nw])

    def select(self, fold: int, calib: tuple):
        idx = [i for i, o in enumerate(self.owner) if o in (-1, fold)]
        score = np.array([np.sum(self.loss[i][list(calib)]) for i in idx])
        order = np.argsort(score)
        return [idx[o] for o in order], score[order]


def fit_candidate(sim: BatchSimulator, cand: Candidate, folds: list, *, seed: int = 0, per_fold: int = 3,
                  min_round: int = 16, rounds: int = 3, progress=None) -> CandidateFit:
    tests = sim.tests
    n = len(tests)
    all_tests = tuple(range(n))
    fold_defs = list(folds) + [(all_tests, ())]  # last = full fit
    F = len(fold_defs)
    windows = ENCODER_WINDOWS if cand.encoder_layer else ()
    pool = _Pool(windows)
    n_sims = 0
    n_div = 0
    p = cand.n_params
    if p == 0:
        pred, div = sim.run(cand, {}, progress)
        loss = np.stack([test_loss(tests[j], pred[j]) for j in range(n)])
        pool.add(np.zeros((1, 0)), loss, pred, [-1])
        n_sims += n
        n_div += int(div.sum())
        rounds = 0
    else:
        m = max(per_fold, math.ceil(min_round / F))
        S = F * m
        sob = qmc.LatinHypercube(d=p, seed=seed).random(S)
        sob[0] = cand.anchor_unit()
        pred, div = sim.run(cand, cand.physical(sob), progress, windows)
        loss = np.stack([test_loss(tests[j], pred[j]) for j in range(n)])
        loss[div] = np.inf
        pool.add(sob, loss, pred, [-1] * S)
        n_sims += n * S
        n_div += int(div.sum())
        rng = np.random.default_rng(seed + 1)
        last_gain = np.zeros(F)
        for r in range(rounds):
            pts, owner, before = [], [], []
            for f, (calib, _) in enumerate(fold_defs):
                order, score = pool.select(f, calib)
                before.append(score[0])
                elite = np.stack([pool.unit[i] for i in order[:4]])
                centre = elite[0]
                spread = np.maximum(elite.std(axis=0), 0.04) * (0.6**r)
                new = np.clip(centre + spread * rng.standard_normal((m, p)), 0.0, 1.0)
                pts.append(new)
                owner += [f] * m
            pts = np.concatenate(pts)
            pred, div = sim.run(cand, cand.physical(pts), progress, windows)
            loss = np.stack([test_loss(tests[j], pred[j]) for j in range(n)])
            loss[div] = np.inf
            pool.add(pts, loss, pred, owner)
            n_sims += n * pts.shape[0]
            n_div += int(div.sum())
            for f, (calib, _) in enumerate(fold_defs):
                _, score = pool.select(f, calib)
                last_gain[f] = (before[f] - score[0]) / max(before[f], 1e-12) if np.isfinite(before[f]) else 1.0
    fits, heldout_pred, heldout_loss = [], [None] * n, np.full(n, np.inf)
    full_fit = None
    for f, (calib, held) in enumerate(fold_defs):
        order, score = pool.select(f, calib)
        best = order[0]
        conv = bool(np.isfinite(score[0]) and (rounds == 0 or last_gain[f] <= 0.02))
        unit = pool.unit[best]
        params = {k: float(v[0]) for k, v in cand.physical(unit[None]).items()} if p else {}
        if pool.window[best] is not None:
            params["encoder_window"] = float(pool.window[best])
        ff = FoldFit(calib, held, unit, params, float(score[0]), conv)
        if f == F - 1:
            full_fit = ff
            full_pred = pool.pred[best]
            full_loss = pool.loss[best]
        else:
            fits.append(ff)
            for j in held:
                heldout_pred[j] = pool.pred[best][j]
                heldout_loss[j] = pool.loss[best][j]
    if not folds:  # a single test: nothing to hold out; scored in-sample (stated in the report)
        heldout_pred, heldout_loss = list(full_pred), np.array(full_loss)
    notes = []
    if n_div:
        notes.append(f"{n_div} of {n_sims} simulations diverged (excluded from the fit)")
    return CandidateFit(cand, full_fit, fits, heldout_pred, list(full_pred), heldout_loss, np.array(full_loss),
                        n_sims, n_div / max(n_sims, 1), notes)
