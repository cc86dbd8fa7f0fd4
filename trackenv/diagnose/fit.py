"""Fit a candidate's parameters on calibration data and predict the held-out data.

**Loss** of a prediction on one test: the mean over its measured signals of

    mean_k (sim_k − meas_k)² / (σ² + (0.01·span)²)

with σ the signal's noise level and span its robust range (:mod:`.data`): a χ² per sample that
gives each signal equal say, with a 1 %-of-range floor for what a model can be expected to match
(so that the quietest channel does not dominate). The loss of a set of tests is the sum over tests
(each test counts once, whatever its length). Each test is cut at the middle of its compared samples
into a *head* and a *tail*; a loss is kept per part (the whole test's loss is their sample-weighted
sum).

**Folds** (:func:`make_folds`, one per test, never a random split of samples):

- a test whose maneuver the folder *repeats* (another test with the same ``maneuver`` in
  ``meta.json`` at a similar operating point: peak mean |V| and peak |ΔV| within 25 %, :func:`repeats`)
  is held out whole: the fold is fitted on every other test and predicts this one;
- a test whose maneuver is unique (another test cannot stand in for it) is *forward-chained*: the fold
  is fitted on every other test plus this test's head, and predicts its tail (the part of the test
  after the data it was fitted on). An effect that only this test excites is then still measured
  out of sample, on the later half of the same test.

Plus the *full* fit on all the data (the parameters reported, and the in-sample numbers). Every point a
candidate simulates is simulated on every test, so the full fit chooses among all of them (each fold's
own points included, in its branch), and after the polish it takes any fold's final point that fits all
the data better than its own (:func:`_best_point_for_all_data`). None of this touches a fold's held-out
prediction, which uses only points chosen on that fold's calibration data.

**Search** — stage 1, derivative-free (multimodal fits): one global round of Latin-hypercube points in
the candidate's unit cube, the anchor (≈ the base model) among them, evaluated on every test; then
``rounds`` rounds of the cross-entropy method *per fold*: new points drawn around the fold's best point
(spread = the spread of its 4 best, shrinking 0.6× per round) scored on the fold's *calibration* data
only, evaluated in one batch for all folds. Every physical effect (not ``none``, ``recalibrate_base``,
or ``sensor_artifacts``, which has its own window) also carries an *encoder layer*: each simulated point
is scored with the speed averaged over each of ``ENCODER_WINDOWS`` (free: no new simulation), and the
window is selected with the point.

An effect that stands on the control (:attr:`.candidates.Candidate.on`) has a different base model per
fold: the control's factors fitted on that fold, or the base itself (*branches*). The global design
above is scored on the base itself; each fold × control branch gets its own Latin-hypercube points, the
first of them the branch's anchor. A fold's cross-entropy round stays in the branch of its best point,
and the polish refines that branch.

Stage 2, gradient polish (:mod:`.polish`): each fold's best point is refined by Levenberg-Marquardt
on the fold's weighted residuals, with the Jacobian from ``jax.jacfwd`` through the batched simulator
(all folds in one call per iteration) and the bounds kept by a logistic map of the unit cube. Each fold
reports its gradient norm and last relative improvement; a fold is *converged* if the polish stopped on
a small step, gradient or improvement (not on the iteration limit), or — where no gradient could be
used — if the search's last round improved it by at most 2 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.stats import qmc

from .batch import BatchSimulator
from .candidates import ON, Candidate
from .data import TestData
from .metrics import MODEL_FLOOR, signal_error, signal_weight  # noqa: F401  (MODEL_FLOOR: the loss's floor)
from .polish import points_per_evaluation

MAX_FOLDS = 12
ENCODER_WINDOWS = (0.0, 0.05, 0.1, 0.2, 0.35)  # s, the encoder layer every candidate but none carries
HEAD_FRACTION = 0.5  # forward chaining: the head is this fraction of a test's compared samples


def split_parts(test: TestData) -> np.ndarray:
    """(K,) 0 for the head, 1 for the tail of ``test`` (cut at ``HEAD_FRACTION`` of its compared samples)."""
    idx = np.flatnonzero(test.fit_mask)
    part = np.ones(len(test.t), np.int8)
    if idx.size:
        part[: idx[int(HEAD_FRACTION * (idx.size - 1))] + 1] = 0
    return part


def test_loss_parts(test: TestData, pred: dict, part: np.ndarray | None = None) -> np.ndarray:
    """Loss of predictions ``pred[sig]`` (K, S) on one test, per part -> (2, S) (head, tail)."""
    part = split_parts(test) if part is None else part
    out = []
    for q in (0, 1):
        terms = []
        for sig, meas in test.measured.items():
            ok = np.isfinite(meas) & test.fit_mask & (part == q)
            if ok.sum() == 0:
                continue
            err = signal_error(test, sig, pred[sig])[ok]
            terms.append(np.mean(err**2, axis=0) * signal_weight(test, sig))
        out.append(np.mean(terms, axis=0) if terms else np.zeros(np.shape(next(iter(pred.values())))[1:]))
    out = np.stack(out)
    return np.where(np.isfinite(out), out, np.inf)


def part_fractions(test: TestData, part: np.ndarray | None = None) -> np.ndarray:
    part = split_parts(test) if part is None else part
    n = np.array([np.sum(test.fit_mask & (part == q)) for q in (0, 1)], np.float64)
    return n / max(n.sum(), 1.0)


def test_loss(test: TestData, pred: dict) -> np.ndarray:
    """Loss of predictions ``pred[sig]`` (K, S) on the whole test -> (S,)."""
    lp = test_loss_parts(test, pred)
    fr = part_fractions(test)
    return fr[0] * lp[0] + fr[1] * lp[1]


@dataclass(frozen=True)
class Fold:
    """One fold: ``held`` test index, ``kind`` ("test": held out whole, "forward": head fitted, tail predicted),
    ``weights`` (n_tests, 2) on the (head, tail) part losses that make the calibration loss."""

    held: int
    kind: str
    weights: np.ndarray

    @property
    def calibration(self) -> tuple:
        return tuple(int(j) for j in np.flatnonzero(self.weights.sum(axis=1) > 0))


def _operating_point(test: TestData) -> tuple[float, float]:
    """(peak mean |V|, peak |V_r − V_l|) of a test's commands [V]."""
    v = test.volts
    return float(np.max(np.abs(v.mean(axis=1)))), float(np.max(np.abs(v[:, 1] - v[:, 0])))


def repeats(a: TestData, b: TestData, tol: float = 0.25) -> bool:
    """True if ``b`` repeats ``a``'s maneuver: the same ``maneuver`` in meta.json at a similar operating point
    (peak mean |V| and peak |ΔV| within ``tol`` relative, or 1 V)."""
    if str(a.log.maneuver or a.name) != str(b.log.maneuver or b.name):
        return False
    pa, pb = _operating_point(a), _operating_point(b)
    return all(abs(x - y) <= max(1.0, tol * max(abs(x), abs(y))) for x, y in zip(pa, pb))


def make_folds(tests: list[TestData]) -> list[Fold]:
    """One fold per test: held out whole where another test repeats its maneuver (:func:`repeats`), else
    forward-chained."""
    n = len(tests)
    fr = np.stack([part_fractions(t) for t in tests])
    folds = []
    for j in range(n):
        w = fr.copy()
        if any(repeats(tests[j], tests[k]) for k in range(n) if k != j):
            w[j] = 0.0
            folds.append(Fold(j, "test", w))
        else:
            w[j] = (1.0, 0.0)
            folds.append(Fold(j, "forward", w))
    return folds


def full_fold(tests: list[TestData]) -> Fold:
    return Fold(-1, "full", np.stack([part_fractions(t) for t in tests]))


def heldout_mask(test: TestData, fold: Fold) -> np.ndarray:
    """(K,) the samples of ``test`` that ``fold`` predicts out of sample."""
    if fold.kind == "forward":
        return test.fit_mask & (split_parts(test) == 1)
    return test.fit_mask.copy()


@dataclass
class FoldFit:
    calibration: tuple
    heldout: tuple
    unit: np.ndarray  # (p,) best point
    params: dict  # physical
    calibration_loss: float
    converged: bool
    kind: str = "test"
    search_loss: float = float("nan")  # the calibration loss of the search's best point (before the polish)
    polish: dict = field(default_factory=dict)  # iterations, grad_norm, last_rel_improvement, stop reason


@dataclass
class CandidateFit:
    candidate: Candidate
    full: FoldFit
    folds: list  # FoldFit per fold
    heldout_pred: list  # per test: {sig: (K,)} predicted by the fold that holds it out (full fit if no folds)
    full_pred: list  # per test: {sig: (K,)} of the full fit
    heldout_loss: np.ndarray  # (n_tests,) loss on each test's held-out samples
    full_loss: np.ndarray  # (n_tests,)
    n_simulations: int
    diverged_fraction: float
    heldout_masks: list = field(default_factory=list)  # per test: (K,) samples predicted out of sample
    notes: list = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return self.full.converged and all(f.converged for f in self.folds)


class _Pool:
    """Evaluated points: unit coords, per-test part losses (n, 2), per-test predictions."""

    def __init__(self, windows=()):
        self.unit, self.loss, self.pred, self.owner, self.window = [], [], [], [], []
        self.windows = tuple(windows) or (None,)

    def add(self, unit, loss, pred, owner):
        """``loss``: (n, 2, C) with C = S · len(windows) columns."""
        nw = len(self.windows)
        for c in range(loss.shape[2]):
            s = c // nw
            self.unit.append(unit[s])
            self.loss.append(loss[:, :, c])
            self.pred.append([{k: v[:, c] for k, v in p.items()} for p in pred])
            self.owner.append(owner[s])
            self.window.append(self.windows[c % nw])

    def select(self, fold: int, weights: np.ndarray, n_folds: int, keep=None):
        """The points fold ``fold`` may use (global ones, and its own in every branch; only owners for which
        ``keep(owner)`` is true, if given), best first. The full fit (the last fold) may use every point: all of
        them were simulated on every test, and none is held out from it."""
        full = fold == n_folds - 1
        idx = [i for i, o in enumerate(self.owner)
               if (full or o == -1 or o % n_folds == fold) and (keep is None or keep(o))]
        with np.errstate(invalid="ignore"):
            score = np.array([np.sum(np.where(weights > 0, self.loss[i] * weights, 0.0)) for i in idx])
        score = np.where(np.isfinite(score), score, np.inf)
        order = np.argsort(score)
        return [idx[o] for o in order], score[order]


def _losses(tests, pred):
    return np.stack([test_loss_parts(tests[j], pred[j]) for j in range(len(tests))])  # (n, 2, C)


def point_loss_parts(tests, pred) -> np.ndarray:
    """(n_tests, 2) loss parts (:func:`test_loss_parts`) of one parameter point; ``pred``: per test {signal: (K,)}."""
    return _losses(tests, [{s: x[:, None] for s, x in q.items()} for q in pred])[:, :, 0]


def search_size(n_fits: int, per_fold: int = 3, min_round: int = 16) -> int:
    """Points per fit and branch in each round of the search: at least ``per_fold``, and ``min_round`` over all
    ``n_fits`` fits (the folds and the full fit)."""
    return max(per_fold, math.ceil(min_round / n_fits))


def fit_plan(cand: Candidate, n_tests: int, n_fits: int, *, per_fold: int = 3, min_round: int = 16, rounds: int = 3,
             polish_iters: int = 4, jacobian: str = "secant", n_branch: int = 1, refined: int = 1) -> int:
    """The test evaluations (one parameter set simulated, or for an instruments-only candidate transformed, on
    one test) that :func:`fit_candidate` plans for ``cand`` on ``n_tests`` tests and ``n_fits`` fits (the folds
    and the full fit), with ``n_branch`` parameter sets to stand on (``below``) of which ``refined`` are searched
    and polished (``each_branch``). Every polish iteration is counted; a polish that stops early reports the
    iterations it skipped when it ends, so that a progress bar over this plan ends full."""
    p = cand.n_params
    if p == 0:
        return n_tests
    m = search_size(n_fits, per_fold, min_round)
    search = n_fits * m * n_branch + rounds * n_fits * refined * m
    polish = (1 + polish_iters) * n_fits * refined * points_per_evaluation(p, jacobian) if polish_iters > 0 else 0
    return n_tests * (search + polish)


def fit_candidate(sim: BatchSimulator, cand: Candidate, folds: list, *, seed: int = 0, per_fold: int = 3,
                  min_round: int = 16, rounds: int = 3, polish_iters: int = 4, progress=None,
                  jacobian: str = "secant", below: list | None = None,
                  each_branch: bool | tuple[int, ...] = False) -> CandidateFit | list[CandidateFit]:
    """Fit ``cand`` on every fold and on all the data (see the module docstring).

    ``below``: where ``cand`` stands on another candidate (:attr:`.candidates.Candidate.on`), per fit (the
    ``folds``, then the full fit) a list of the parameter sets of that candidate it may stand on: e.g. its
    fitted values on that fold, then its anchor (the base model). The last set must be the same for every
    fit: its points are shared by all folds, as without ``below``. Each fold searches every *branch* (one
    per set, each holding its own anchor) and keeps the branch of its best calibration loss; a fold's
    held-out prediction therefore uses nothing fitted on its held-out data.

    ``each_branch``: instead, search and polish every branch separately (sharing the global design) and
    return one :class:`CandidateFit` per branch, in the order of the sets in ``below``; a tuple of branch
    indices refines and returns only those branches (the global design still spans all of them).

    ``progress``: called with the test evaluations of each batch as it ends, the search's and the polish's; over
    the whole fit they add up to :func:`fit_plan`'s count.
    """
    tests = sim.tests
    n = len(tests)
    fold_defs = list(folds) + [full_fold(tests)]  # last = full fit
    F = len(fold_defs)
    if (cand.on is None) != (below is None) or (below is not None and (len(below) != F or
                                                                        len({len(b) for b in below}) != 1)):
        raise ValueError(f"{cand.name}: 'below' must give, for each of the {F} fits (folds, then the full fit), "
                         f"equally many parameter sets of {cand.on and cand.on.name}")
    below_keys = [s.name for s in cand.on.specs] if cand.on is not None else []
    n_branch = len(below[0]) if below is not None else 1

    if below is not None and any(b[-1] != below[0][-1] for b in below):
        raise ValueError(f"{cand.name}: the last parameter set of 'below' must be the same for every fit")

    def branch_of(o):
        return n_branch - 1 if o < 0 else o // F

    if isinstance(each_branch, tuple):
        if below is None or not each_branch or any(not 0 <= b < n_branch for b in each_branch):
            raise ValueError(f"{cand.name}: each_branch={each_branch!r} needs 'below' and branch indices in "
                             f"0..{n_branch - 1}")
        branches = list(each_branch)
    else:
        branches = list(range(n_branch)) if (each_branch and below is not None) else [None]
    plan = fit_plan(cand, n, F, per_fold=per_fold, min_round=min_round, rounds=rounds, polish_iters=polish_iters,
                    jacobian=jacobian, n_branch=n_branch, refined=len(branches))
    done = 0

    def tick(k: int) -> None:
        nonlocal done
        done += k
        if progress:
            progress(k)

    def keep_branch(b):
        return None if b is None else (lambda o: branch_of(o) == b)

    def below_of(o):
        """The parameter set that owner ``o`` (fold ``o mod F``, branch ``o // F``; -1: shared, the last) stands on."""
        return below[0][-1] if o < 0 else below[o % F][o // F]

    def values(pts, owner):
        """Physical values of unit points ``pts`` (S, p), each with the values its owner stands on."""
        vals = cand.physical(pts) if p else {}
        for k in below_keys:
            vals[ON + k] = np.array([below_of(o)[k] for o in owner], np.float64)
        return vals

    windows = ENCODER_WINDOWS if cand.encoder_layer else ()
    pool = _Pool(windows)
    n_sims = 0
    n_div = 0
    p = cand.n_params
    last_gain = np.zeros((n_branch, F))
    if p == 0:
        if below is not None:
            raise ValueError(f"{cand.name}: a candidate without parameters cannot stand on another one")
        pred, div = sim.run(cand, {}, tick)
        pool.add(np.zeros((1, 0)), _losses(tests, pred), pred, [-1])
        n_sims += n
        n_div += int(div.sum())
        rounds = 0
    else:
        m = search_size(F, per_fold, min_round)
        S = F * m
        # one global design, every point scored for every fold (on the shared base)
        sob = qmc.LatinHypercube(d=p, seed=seed).random(S)
        owner0 = [-1] * S
        sob[0] = cand.anchor_unit(below_of(-1) if below is not None else None)
        if below is not None:  # and each fold × other branch its own: m points each, the first its anchor
            FB = F * (n_branch - 1)
            extra = qmc.LatinHypercube(d=p, seed=seed + 7).random(FB * m)
            owner0 += [i % FB for i in range(FB * m)]
            for o in range(FB):
                extra[o] = cand.anchor_unit(below_of(o))
            sob = np.concatenate([sob, extra])
        pred, div = sim.run(cand, values(sob, owner0), tick, windows)
        loss = _losses(tests, pred)
        loss[np.broadcast_to(div[:, None, :], loss.shape)] = np.inf
        pool.add(sob, loss, pred, owner0)
        n_sims += n * len(owner0)
        n_div += int(div.sum())
        rng = np.random.default_rng(seed + 1)
        for r in range(rounds):
            pts, owner, before = [], [], []
            for f, fd in enumerate(fold_defs):
                for b in branches:
                    order, score = pool.select(f, fd.weights, F, keep_branch(b))
                    before.append(score[0])
                    elite = np.stack([pool.unit[i] for i in order[:4]])
                    centre = elite[0]
                    spread = np.maximum(elite.std(axis=0), 0.04) * (0.6**r)
                    new = np.clip(centre + spread * rng.standard_normal((m, p)), 0.0, 1.0)
                    pts.append(new)
                    o = pool.owner[order[0]]  # new points in the branch of the best one
                    if below is None:
                        o = f
                    elif o < 0:  # the shared branch, owned by this fold
                        o = f + F * (n_branch - 1)
                    owner += [o] * m
            pts = np.concatenate(pts)
            pred, div = sim.run(cand, values(pts, owner), tick, windows)
            loss = _losses(tests, pred)
            loss[np.broadcast_to(div[:, None, :], loss.shape)] = np.inf
            pool.add(pts, loss, pred, owner)
            n_sims += n * pts.shape[0]
            n_div += int(div.sum())
            k = 0
            for f, fd in enumerate(fold_defs):
                for b in branches:
                    _, score = pool.select(f, fd.weights, F, keep_branch(b))
                    last_gain[b or 0, f] = ((before[k] - score[0]) / max(before[k], 1e-12)
                                            if np.isfinite(before[k]) else 1.0)
                    k += 1
    picks = [_search_best(cand, fold_defs, pool, F, keep_branch(b), below_of if below is not None else None)
             for b in branches]
    polished = _polish_branches(sim, cand, fold_defs, picks, polish_iters, jacobian, tick)
    if done < plan:  # a polish that stopped early: the iterations it skipped
        tick(plan - done)
    out = [_finish(cand, tests, fold_defs, pick, pol, below_keys, rounds, last_gain[b or 0], n_sims, n_div)
           for b, pick, pol in zip(branches, picks, polished)]
    return out if each_branch and below is not None else out[0]


class _Pick(NamedTuple):
    """The search's best point of each fold in one branch: what the polish starts from."""

    units: list  # per fold: unit point (p,)
    chosen: list | None  # per fold: the parameter set it stands on (None: stands on nothing)
    windows: list  # per fold: encoder window [s] or None
    preds: list  # per fold: predictions of every test
    search_score: list  # per fold: the search's calibration loss


def _search_best(cand, fold_defs, pool, F, keep, below_of) -> _Pick:
    """Each fold's best searched point (of one branch if ``keep``)."""
    best_i, search_score = [], []
    for f, fd in enumerate(fold_defs):
        order, score = pool.select(f, fd.weights, F, keep)
        best_i.append(order[0])
        search_score.append(float(score[0]))
    return _Pick([np.asarray(pool.unit[i], np.float64) for i in best_i],
                 [below_of(pool.owner[i]) for i in best_i] if below_of is not None else None,
                 [pool.window[i] for i in best_i], [pool.pred[i] for i in best_i], search_score)


def _polish_branches(sim, cand, fold_defs, picks: list[_Pick], polish_iters, jacobian, progress) -> list[dict | None]:
    """Levenberg-Marquardt from every branch's fold points in **one** :func:`.polish.polish_folds` problem (rows:
    branch-major), split back per branch; ``None`` per branch where nothing is polished.

    The fits of an effect on the control and on the base model differ only in the values they stand on, so one
    compiled simulation serves both. (Polished apart, where every test has the same base values (one terrain),
    the base branch's factor leaves were all equal and became scalars, a program of their own, compiled once more
    per effect; those leaves now stay arrays, :attr:`.candidates.Candidate.varied_leaves`.) Each row keeps its own damping and stopping
    (:func:`.polish.polish_folds`), so a row's iterations are those it would take alone; its batch, and so its
    float rounding, changes."""
    if not (cand.n_params and polish_iters > 0):
        return [None] * len(picks)
    from .polish import not_polished_note, polish_folds

    F, k = len(fold_defs), len(picks)
    joint = lambda field: [x for pk in picks for x in getattr(pk, field)]  # noqa: E731
    res = polish_folds(sim, cand, fold_defs * k, joint("units"), joint("windows"), joint("search_score"),
                       iters=polish_iters, progress=progress, jacobian=jacobian,
                       below=None if picks[0].chosen is None else joint("chosen"))
    rows = lambda key, b: res[key][b * F:(b + 1) * F]  # noqa: E731
    return [{"units": rows("units", b), "preds": rows("preds", b), "scores": rows("scores", b),
             "improved": rows("improved", b), "info": rows("info", b), "notes": not_polished_note(rows("info", b)),
             "n_simulations": res["n_simulations"] // k} for b in range(k)]


def _best_point_for_all_data(fold_defs, parts, units, chosen, wins, preds, scores, polish_info) -> None:
    """Make the full fit (the last fold) the best point for all the data among its own and every fold's final
    point (in place). Each fold's point was simulated on every test, so its loss on all the data is known
    without a new simulation. Where the loss is rough in the parameters (stick-slip after a stop on hard
    ground), the full fit's own search and polish can stop far above a point that a fold fit reached:
    on a blind null case on asphalt the control's full fit ended at 1.77 while one of its fold points
    fits all the data at 0.68 (the nuisance's own values: 0.74). ``polish_info[-1]["from_fold"]`` records
    a replacement. ``parts``: per fit, its (n_tests, 2) loss parts (:func:`test_loss_parts`), swapped too."""
    F = len(fold_defs)
    w = fold_defs[-1].weights
    best = F - 1
    best_loss = scores[-1] if np.isfinite(scores[-1]) else np.inf
    for f in range(F - 1):
        loss = float(np.sum(np.where(w > 0, parts[f] * w, 0.0)))
        if np.isfinite(loss) and loss < best_loss:
            best, best_loss = f, loss
    if best == F - 1:
        return
    polish_info[-1] = dict(polish_info[-1], from_fold=best, own_loss=float(scores[-1]))
    units[-1], wins[-1], preds[-1], scores[-1] = units[best], wins[best], preds[best], best_loss
    parts[-1] = parts[best]
    if chosen is not None:
        chosen[-1] = chosen[best]


def _finish(cand, tests, fold_defs, pick: _Pick, res: dict | None, below_keys, rounds, last_gain, n_sims,
            n_div) -> CandidateFit:
    """A fit from one branch's searched points and their polish (``res``; None: not polished)."""
    n = len(tests)
    p = cand.n_params
    F = len(fold_defs)
    units, wins = list(pick.units), list(pick.windows)
    chosen = None if pick.chosen is None else list(pick.chosen)
    preds, search_score, scores = list(pick.preds), pick.search_score, list(pick.search_score)
    polish_info = [dict() for _ in range(F)]
    notes = []
    if res is not None:
        n_sims += res["n_simulations"]
        for f in range(F):
            polish_info[f] = res["info"][f]
            if res["improved"][f]:
                units[f] = res["units"][f]
                preds[f] = res["preds"][f]
                scores[f] = res["scores"][f]
        notes += res["notes"]
    fits, heldout_pred, heldout_loss = [], [None] * n, np.full(n, np.inf)
    masks = [t.fit_mask.copy() for t in tests]
    parts = [point_loss_parts(tests, preds[f]) for f in range(F)]  # per fit: (n, 2)
    _best_point_for_all_data(fold_defs, parts, units, chosen, wins, preds, scores, polish_info)
    full_fit = full_pred = full_loss = None
    for f, fd in enumerate(fold_defs):
        info = polish_info[f]
        if info.get("used_gradient"):
            conv = bool(np.isfinite(scores[f]) and info.get("stop") in ("small step", "small gradient",
                                                                         "small improvement"))
        else:
            conv = bool(np.isfinite(scores[f]) and (rounds == 0 or last_gain[f] <= 0.02))
        unit = units[f]
        params = {k: float(v[0]) for k, v in cand.physical(unit[None]).items()} if p else {}
        if wins[f] is not None:
            params["encoder_window"] = float(wins[f])
        if chosen is not None:
            params.update({f"{cand.on.name}.{k}": float(chosen[f][k]) for k in below_keys})
        lp = parts[f]
        held = () if fd.kind == "full" else (fd.held,)
        ff = FoldFit(fd.calibration, held, unit, params, float(scores[f]), conv, fd.kind, search_score[f], info)
        if fd.kind == "full":
            full_fit = ff
            full_pred = preds[f]
            full_loss = np.sum(lp * fd.weights, axis=1)
        else:
            fits.append(ff)
            j = fd.held
            heldout_pred[j] = preds[f][j]
            heldout_loss[j] = lp[j, 1] if fd.kind == "forward" else float(np.sum(lp[j] * part_fractions(tests[j])))
            masks[j] = heldout_mask(tests[j], fd)
    if n_div:
        notes.append(f"{n_div} of {n_sims} simulations diverged (excluded from the fit)")
    return CandidateFit(cand, full_fit, fits, heldout_pred, list(full_pred), heldout_loss, np.array(full_loss),
                        n_sims, n_div / max(n_sims, 1), masks, notes)
