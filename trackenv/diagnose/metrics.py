"""Gap metrics: per test × signal × phase cells, the systematic part of a gap, lags, bootstrap CIs.

For a cell (the samples of one test's phase, one signal) with errors e = sim − meas:

- ``nrmse`` = RMSE / span (span: the signal's robust range over the whole test, so that cells of one
  test share a scale), ``bias`` = mean(e), ``lag`` [s]: the shift τ ∈ [−0.5, 0.5] s minimising the
  RMSE between sim(t − τ) and meas(t) (τ > 0: the measurement lags the simulation);
- ``gap`` = sqrt(max(MSE − σ², 0)) / span: the *systematic* NRMSE, what is left once the log's own
  noise σ is taken out (a perfect model has gap ≈ 0 however noisy the log); ``noise_ratio`` = MSE/σ².

The overall gap of a model on a set of tests is in noise units, consistent with the fit's loss
(:mod:`.fit`): per test, the mean over signals of (MSE − σ²)₊ / (σ² + (0.01 span)²); overall, the
square root of its mean over tests (1 = a systematic error as large as the noise, or as 1 % of the
range where that is larger). The shrink of a model over the base is 1 − gap_after / gap_before.
``overall_gap_range`` gives the same in % of range (sqrt of the mean of (MSE − σ²)₊/span²), for people. Confidence intervals: a paired
moving-block bootstrap (blocks of 0.5 s, resampled within each test, and the tests themselves
resampled when there are three or more), 300 resamples, percentile interval.
"""

from __future__ import annotations

import numpy as np

from ..compare import channel_error
from .data import TestData

BLOCK_S = 0.5
N_BOOT = 300
MODEL_FLOOR = 0.01  # fraction of a signal's range a model is expected to match (the fit's loss, :mod:`.fit`)


def signal_weight(test: TestData, sig: str) -> float:
    """1 / (σ² + (MODEL_FLOOR · span)²): the weight of a squared error of ``sig`` in the loss and the gap."""
    return 1.0 / (test.noise[sig] ** 2 + (MODEL_FLOOR * test.span[sig]) ** 2)


def signal_error(test: TestData, sig: str, pred: np.ndarray) -> np.ndarray:
    """sim − meas of ``sig`` for predictions (K,) or (K, S); heading errors wrapped to (−π, π]
    (:func:`trackenv.compare.channel_error`)."""
    return channel_error(sig, pred, test.measured[sig])


def lag_of(t: np.ndarray, sim: np.ndarray, meas: np.ndarray, mask: np.ndarray, max_lag: float = 0.5) -> float | None:
    ok = mask & np.isfinite(meas)
    if ok.sum() < 5 or np.nanstd(meas[ok]) == 0:
        return None
    dt = float(np.median(np.diff(t)))
    n = int(max_lag / dt)
    best, arg = np.inf, 0
    for k in range(-n, n + 1):
        src = np.arange(len(t)) - k
        valid = ok & (src >= 0) & (src < len(t))
        if valid.sum() < 5:
            continue
        m = np.mean((sim[src[valid]] - meas[valid]) ** 2)
        if m < best - 1e-15:
            best, arg = m, k
    return float(arg * dt)


def cell_table(tests: list[TestData], before: list[dict], after: list[dict] | None) -> list[dict]:
    """One row per test × signal × phase with before/after metrics."""
    rows = []
    for j, test in enumerate(tests):
        for sig in test.measured:
            eb = signal_error(test, sig, before[j][sig])
            ea = signal_error(test, sig, after[j][sig]) if after is not None else None
            ok = np.isfinite(eb)
            sigma2 = test.noise[sig] ** 2
            span = test.span[sig]
            for ph in dict.fromkeys(test.phase):
                m = ok & (test.phase == ph)
                if m.sum() < 3:
                    continue
                mse_b = float(np.mean(eb[m] ** 2))
                row = {"test": test.name, "signal": sig, "phase": ph, "n": int(m.sum()),
                       "t_start": float(test.t[m][0]), "t_end": float(test.t[m][-1]),
                       "nrmse_before": float(np.sqrt(mse_b) / span),
                       "gap_before": float(np.sqrt(max(mse_b - sigma2, 0.0)) / span),
                       "bias_before": float(np.mean(eb[m])),
                       "lag_before_s": lag_of(test.t, before[j][sig], test.measured[sig], m),
                       "noise_ratio_before": float(mse_b / sigma2)}
                if ea is not None:
                    mse_a = float(np.mean(ea[m] ** 2))
                    row.update({"nrmse_after": float(np.sqrt(mse_a) / span),
                                "gap_after": float(np.sqrt(max(mse_a - sigma2, 0.0)) / span),
                                "bias_after": float(np.mean(ea[m])), "noise_ratio_after": float(mse_a / sigma2)})
                row["weight"] = float(m.sum() / len(test.t))
                rows.append(row)
    total = sum(r["weight"] * r["gap_before"] ** 2 for r in rows) or 1.0
    for r in rows:
        r["share_of_gap"] = r["weight"] * r["gap_before"] ** 2 / total
    return rows


def gap_carriers(rows: list[dict], cover: float = 0.6, max_cells: int = 6) -> list[dict]:
    """The cells that carry the gap: largest shares until ``cover`` of it, significant ones only."""
    out, acc = [], 0.0
    for r in sorted(rows, key=lambda r: -r["share_of_gap"]):
        if acc >= cover or len(out) >= max_cells:
            break
        if r["noise_ratio_before"] < 2.0 or r["gap_before"] < 0.02:
            continue
        out.append(r)
        acc += r["share_of_gap"]
    return out


def sq_errors(tests: list[TestData], pred: list[dict]) -> list[dict]:
    """Per test, per signal: squared errors (K,) (NaN where not measured or outside the fit mask)."""
    return [{sig: np.where(t.fit_mask, signal_error(t, sig, pred[j][sig]) ** 2, np.nan) for sig in t.measured}
            for j, t in enumerate(tests)]


def overall_gap(tests: list[TestData], sq: list[dict], idx: list[np.ndarray] | None = None) -> float:
    """Systematic gap of a model over tests, in noise units (see the module docstring)."""
    per_test = []
    for j, t in enumerate(tests):
        vals = []
        for sig, e2 in sq[j].items():
            x = e2 if idx is None else e2[idx[j]]
            x = x[np.isfinite(x)]
            if x.size:
                w = signal_weight(t, sig)
                vals.append(max(float(np.mean(x)) - t.noise[sig] ** 2, 0.0) * w)
        if vals:
            per_test.append(np.mean(vals))
    return float(np.sqrt(np.mean(per_test))) if per_test else float("nan")


def overall_gap_range(tests: list[TestData], sq: list[dict]) -> float:
    """Systematic NRMSE over tests × signals [fraction of range] (for people; the verdict uses :func:`overall_gap`)."""
    vals = []
    for j, t in enumerate(tests):
        for sig, e2 in sq[j].items():
            x = e2[np.isfinite(e2)]
            if x.size:
                vals.append(max(float(np.mean(x)) - t.noise[sig] ** 2, 0.0) / t.span[sig] ** 2)
    return float(np.sqrt(np.mean(vals))) if vals else float("nan")


def overall_nrmse(tests: list[TestData], sq: list[dict]) -> float:
    vals = [float(np.nanmean(e2)) / t.span[sig] ** 2 for j, t in enumerate(tests) for sig, e2 in sq[j].items()]
    return float(np.sqrt(np.mean(vals)))


def block_indices(tests: list[TestData], rng: np.random.Generator) -> tuple[list[int], list[np.ndarray]]:
    """One bootstrap draw: (tests drawn, per drawn test the resampled sample indices)."""
    n = len(tests)
    which = list(rng.integers(0, n, n)) if n >= 3 else list(range(n))
    idx = []
    for j in which:
        k = len(tests[j].t)
        dt = float(np.median(np.diff(tests[j].t)))
        L = max(1, min(k, int(round(BLOCK_S / dt))))
        nblk = int(np.ceil(k / L))
        starts = rng.integers(0, k - L + 1, nblk)
        idx.append((starts[:, None] + np.arange(L)[None]).ravel()[:k])
    return which, idx


def bootstrap_shrink(tests, sq_before, sq_after, seed: int = 0, n_boot: int = N_BOOT) -> tuple[float, float]:
    rng = np.random.default_rng(seed)
    vals = []
    for _ in range(n_boot):
        which, idx = block_indices(tests, rng)
        tb = [tests[j] for j in which]
        gb = overall_gap(tb, [sq_before[j] for j in which], idx)
        ga = overall_gap(tb, [sq_after[j] for j in which], idx)
        if gb > 0:
            vals.append(1.0 - ga / gb)
    if not vals:
        return (float("nan"), float("nan"))
    lo, hi = np.percentile(vals, [2.5, 97.5])
    return float(lo), float(hi)


def cell_ci(tests, rows, sq_before, sq_after, seed: int = 0, n_boot: int = 200) -> None:
    """Add 95 % block-bootstrap intervals of each cell's gap before/after (in place)."""
    rng = np.random.default_rng(seed)
    by_name = {t.name: j for j, t in enumerate(tests)}
    for r in rows:
        j = by_name[r["test"]]
        t = tests[j]
        m = np.flatnonzero((t.phase == r["phase"]) & np.isfinite(sq_before[j][r["signal"]]))
        dt = float(np.median(np.diff(t.t)))
        L = max(1, min(len(m), int(round(BLOCK_S / dt))))
        s2, span = t.noise[r["signal"]] ** 2, t.span[r["signal"]]
        out = {}
        for key, sq in (("before", sq_before), ("after", sq_after)):
            if sq is None:
                continue
            e2 = sq[j][r["signal"]][m]
            starts = rng.integers(0, len(m) - L + 1, (n_boot, int(np.ceil(len(m) / L))))
            ii = (starts[:, :, None] + np.arange(L)).reshape(n_boot, -1)[:, :len(m)]
            g = np.sqrt(np.maximum(e2[ii].mean(axis=1) - s2, 0.0)) / span
            out[key] = [float(x) for x in np.percentile(g, [2.5, 97.5])]
        r["gap_before_ci"] = out.get("before")
        if "after" in out:
            r["gap_after_ci"] = out["after"]
