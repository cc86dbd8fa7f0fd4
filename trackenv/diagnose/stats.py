"""Statistical tests of the diagnosis: is the base model's gap real, does a candidate beat another one.

Both tests work on samples, and both account for the autocorrelation of what they sum.

**Is the gap real** (:func:`gap_test`). Under the null hypothesis the base model is right and a log's
residual e = sim − meas is the instruments' noise. The noise is modelled per log and channel as an
AR(1) process whose level σ and lag-1 coefficient ρ are estimated from the consecutive differences of
the residual itself (:func:`noise_ar1`; the model has taken the signal out, and a smooth systematic
gap hardly changes from one sample to the next; what it does contribute makes ρ and σ larger and the
test more conservative). The statistic is
T = Σ_k e_k² / σ² over the compared samples (K of them). Under the null E[T] = K and, for a Gaussian
AR(1), Var[T] = 2K(1 + ρ²)/(1 − ρ²); the uncertainty of σ̂ itself (a MAD estimate from K differences)
adds (K · δ)² with δ² = 4 · 1.36 / K. z = (T − K)/√Var, one-sided p = 1 − Φ(z). The per
test × signal p-values are combined by Bonferroni (min p × number of cells): the gap is real if
that is below α.

**Does candidate A beat candidate B** (:func:`paired_test`): a fixed-design test of equal
predictive accuracy on the held-out samples, the likelihood-ratio idea for the AR(1) noise model of
the gap test. With e = p − y − n (prediction p, noise-free truth y, noise n), the loss differential
of one channel is e_B² − e_A² = δ · (p_A + p_B − 2y) − 2 δ n with δ = p_B − p_A. Conditional on the
held-out inputs the first term is fixed and the second is *linear* in the noise, so the statistic
D = Σ_tests Σ_signals c · Σ_k (e_B,k² − e_A,k²) (c: the loss's weight of a sample, :mod:`.fit`) has
variance V = 4 Σ c² σ² δᵀRδ exactly, R the AR(1) correlation ρ^|k−l| of the channel's noise (σ, ρ
from :func:`noise_ar1` of the base model's residual). z = D / √V, one-sided p = 1 − Φ(z). The only
randomness counted is the instruments' noise, which is what "the gap shrinks beyond the noise on
these held-out samples" means; the Gaussian approximation needs only many samples (D is linear in n).

**Best of several candidates** (:func:`max_t_pvalue`): candidates are compared with the same
reference on the same noise, so their z are jointly normal with correlations from the same
quadratic form (δ_aᵀRδ_b). The p-value of the selected candidate's z is P(max_k Z_k ≥ z) under
the least favourable null (all means zero), by Monte Carlo: a max-T correction that is exact for
the family, not the Bonferroni bound.

**Diebold-Mariano** (:func:`dm_test`, the random-design check against the control): per sample k the
loss differential d_k = ℓ_B,k − ℓ_A,k; per test its mean and the Newey-West variance with a bandwidth of
at least twice the integrated correlation time of d, so that the slow systematic variation of d is counted
as uncertainty, not only the noise; tests independent, z = Σ d̄_j / √Σ v_j. The verdict feeds it Huber
losses (:func:`huber_loss`): quadratic up to ``HUBER_K`` weighted noise units, linear beyond. A prediction
that follows a bifurcation (the rocking after a stop, where float rounding can switch a residual of 200 σ
on or off) then weighs like 2·1.345·200 rather than 200², so the test asks where one prediction is
consistently better, not which one caught a chaotic event. The test stays a Diebold-Mariano test: its
null hypothesis is "equal expected loss" for whatever loss it is given.

**Intervals** (:func:`block_bootstrap`): a moving-block bootstrap whose block length per test is the
correlation time of the squared residuals (at least 0.2 s), tests resampled when there are three or
more; the 95 % interval is the percentile interval of the resampled statistic recentred on the point
estimate (θ̂ + quantiles of θ* − median θ*), so that it always contains the point estimate.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter
from scipy.stats import norm

ALPHA = 0.05
HUBER_K = 1.345  # noise units: Huber's constant (95 % efficiency at Gaussian noise), the Diebold-Mariano loss's bend
MAD_EFFICIENCY = 1.36  # Var(σ̂_MAD)/σ² · (2K): the MAD's variance inflation over the sample SD (Gaussian)


def _finite(x):
    x = np.asarray(x, np.float64)
    return x[np.isfinite(x)]


def noise_ar1(x: np.ndarray) -> tuple[float, float]:
    """(σ, ρ) of a log channel's noise as an AR(1) process, from its consecutive differences.

    For AR(1) noise of variance σ² the differences have variance 2σ²(1 − ρ) and lag-1 correlation
    −(1 − ρ)/2, so ρ = 1 + 2 r₁(Δx) (clipped to [0, 0.95]); σ² = σ̂_Δ² / (2(1 − ρ)) with σ̂_Δ the
    MAD-based level of the differences.
    """
    d = np.diff(np.asarray(x, np.float64))
    d = d[np.isfinite(d)]
    if d.size < 10:
        return float("nan"), 0.0
    s = 1.4826 * np.median(np.abs(d - np.median(d)))
    if not s > 0:
        return 0.0, 0.0
    c = np.clip(d - np.median(d), -4 * s, 4 * s)  # winsorised: steps of the signal do not decide ρ
    r1 = float(np.sum(c[1:] * c[:-1]) / np.sum(c * c))
    rho = float(np.clip(1.0 + 2.0 * r1, 0.0, 0.95))
    return float(s / math.sqrt(2.0 * (1.0 - rho))), rho


def gap_test(e: np.ndarray, sigma: float, rho: float) -> tuple[float, float]:
    """(z, one-sided p) of "the residuals ``e`` are more than AR(1) noise of level σ, coefficient ρ"."""
    e = _finite(e)
    K = e.size
    if K < 5 or not sigma > 0:
        return 0.0, 1.0
    T = float(np.sum((e / sigma) ** 2))
    var = 2.0 * K * (1.0 + rho**2) / (1.0 - rho**2) + K * 4.0 * MAD_EFFICIENCY / max(1.0 - rho, 0.05)
    z = (T - K) / math.sqrt(var)
    return float(z), float(norm.sf(z))


def correlation_time(x: np.ndarray, max_lag: int | None = None) -> float:
    """Integrated autocorrelation time of ``x`` in samples (1 for white noise): 1 + 2 Σ r_l up to the first r_l ≤ 0."""
    x = _finite(x)
    n = x.size
    if n < 4:
        return 1.0
    x = x - x.mean()
    v = float(np.dot(x, x))
    if v <= 0:
        return 1.0
    max_lag = min(n // 3, max_lag or n // 3)
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[: max_lag + 1] / v
    tau = 1.0
    for r in ac[1:]:
        if r <= 0:
            break
        tau += 2.0 * r
    return float(tau)


def ar1_form(x: np.ndarray, y: np.ndarray, rho: float) -> float:
    """xᵀ R y with R_kl = ρ^|k−l| (the AR(1) correlation matrix), in O(K) by two first-order filters."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if rho <= 0.0:
        return float(x @ y)
    fwd = lfilter([1.0], [1.0, -rho], y)
    bwd = lfilter([1.0], [1.0, -rho], y[::-1])[::-1]
    return float(x @ (fwd + bwd - y))


def paired_terms(err_a: list, err_b: list, noise: list, weights: list) -> tuple[float, list]:
    """D and the per-channel noise directions of "A beats B" (see the module docstring).

    ``err_a[j][sig]``, ``err_b[j][sig]``: (K,) signed errors sim − meas of test j (NaN: not compared);
    ``noise[j][sig]`` = (σ, ρ); ``weights[j][sig]``: the loss's weight of a squared error of that channel.
    Returns (D, terms) with terms a list of (σ, ρ, c·δ) per channel, δ = p_B − p_A on its compared samples.
    """
    D, terms = 0.0, []
    for ea_j, eb_j, nz_j, w_j in zip(err_a, err_b, noise, weights):
        chans = []
        for sig, ea in ea_j.items():
            ea, eb = np.asarray(ea, np.float64), np.asarray(eb_j[sig], np.float64)
            ok = np.isfinite(ea) & np.isfinite(eb)
            if ok.sum() >= 3:
                chans.append((sig, ok))
        for sig, ok in chans:
            ea, eb = np.asarray(ea_j[sig], np.float64)[ok], np.asarray(eb_j[sig], np.float64)[ok]
            c = w_j[sig] / (len(chans) * ok.sum())
            D += c * float(np.sum(eb * eb - ea * ea))
            sigma, rho = nz_j[sig]
            terms.append((sig, sigma, rho, c * (eb - ea)))
    return D, terms


def paired_statistic(err_a: list, err_b: list, noise: list, weights: list) -> tuple[float, float, list]:
    """(D, V, terms) of "A beats B": D and its noise variance V (:func:`paired_covariance`) on the terms of
    :func:`paired_terms`. V = 0 (undecidable) where a channel's noise level is not positive."""
    D, terms = paired_terms(err_a, err_b, noise, weights)
    if any(not (np.isfinite(sigma) and sigma > 0) for _, sigma, _, _ in terms):
        return D, 0.0, terms
    return D, paired_covariance(terms, terms), terms


def paired_test(err_a: list, err_b: list, noise: list, weights: list) -> dict:
    """Does A predict the held-out samples better than B beyond the noise? {"z", "p" (one-sided), "diff"}.

    Arguments as :func:`paired_terms`. A channel whose noise level is not positive cannot be tested and
    makes the comparison undecidable (p = 1).
    """
    D, V, _ = paired_statistic(err_a, err_b, noise, weights)
    if not (V > 0 and np.isfinite(V)):
        return {"z": 0.0, "p": 1.0, "diff": D}
    z = D / math.sqrt(V)
    return {"z": float(z), "p": float(norm.sf(z)), "diff": float(D)}


def paired_covariance(terms_a: list, terms_b: list) -> float:
    """Noise covariance of two statistics D_A, D_B against the same reference (terms from :func:`paired_terms`)."""
    cov = 0.0
    for (sa, sigma, rho, ca), (sb, _, _, cb) in zip(terms_a, terms_b):
        if sa != sb or ca.shape != cb.shape:
            raise ValueError("paired_covariance: the two statistics are not on the same samples")
        cov += 4.0 * sigma**2 * ar1_form(ca, cb, rho)
    return cov


def max_t_pvalue(z: float, corr: np.ndarray, n_draws: int = 200_000, seed: int = 0) -> float:
    """P(max_k Z_k ≥ z) for Z ~ N(0, corr) (Monte Carlo with a fixed seed; 1 dimension: exact)."""
    corr = np.atleast_2d(np.asarray(corr, np.float64))
    if corr.shape[0] == 1:
        return float(norm.sf(z))
    w, v = np.linalg.eigh(corr)
    L = v * np.sqrt(np.clip(w, 0.0, None))
    draws = np.random.default_rng(seed).standard_normal((n_draws, corr.shape[0])) @ L.T
    p = float(np.mean(draws.max(axis=1) >= z))
    return max(p, float(norm.sf(z)))


def hac_mean_var(d: np.ndarray) -> tuple[float, float, int]:
    """(mean, variance of the mean, bandwidth) of ``d`` by Newey-West with a bandwidth ≥ 2 correlation times."""
    d = _finite(d)
    n = d.size
    if n < 3:
        return (float(d.mean()) if n else 0.0), float("inf"), 0
    m = float(d.mean())
    x = d - m
    L = int(min(n // 2, max(math.ceil(4 * (n / 100) ** (2 / 9)), math.ceil(2 * correlation_time(d)))))
    g0 = float(np.dot(x, x)) / n
    s = g0
    for lag in range(1, L + 1):
        s += 2.0 * (1.0 - lag / (L + 1)) * float(np.dot(x[lag:], x[:-lag])) / n
    return m, max(s, g0 / n) / n, L


def huber_loss(sq: np.ndarray, k: float = HUBER_K) -> np.ndarray:
    """Huber loss 2ρ(e) of standardized errors, from their squares ``sq`` = e² (noise units²; NaN passes):
    e² for |e| ≤ ``k``, 2k|e| − k² beyond (continuous, with a continuous slope, at |e| = k)."""
    sq = np.asarray(sq, np.float64)
    with np.errstate(invalid="ignore"):
        return np.where(sq <= k * k, sq, 2.0 * k * np.sqrt(np.maximum(sq, 0.0)) - k * k)


def dm_test(loss_a: list, loss_b: list) -> dict:
    """Diebold-Mariano: does A (per-test per-sample losses) have lower expected loss than B?

    ``loss_a[j]``, ``loss_b[j]``: (K_j,) per-sample losses of test j (NaN: not compared).
    Returns {"z", "p", "diff"} with diff = Σ_j mean(ℓ_B − ℓ_A) (> 0: A better), p one-sided.
    """
    D, V = 0.0, 0.0
    for a, b in zip(loss_a, loss_b):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
        ok = np.isfinite(a) & np.isfinite(b)
        if ok.sum() < 3:
            continue
        m, v, _ = hac_mean_var(b[ok] - a[ok])
        D += m
        V += v
    if not (V > 0) or not np.isfinite(V):
        return {"z": 0.0, "p": 1.0, "diff": D}
    z = D / math.sqrt(V)
    return {"z": float(z), "p": float(norm.sf(z)), "diff": float(D)}


def block_length(x: np.ndarray, dt: float, min_s: float = 0.2) -> int:
    """Block length [samples] of a moving-block bootstrap: the correlation time of ``x``, at least ``min_s``."""
    return int(max(round(min_s / dt), math.ceil(correlation_time(x)), 1))


def block_draws(lengths: list[int], blocks: list[int], rng, n_boot: int) -> list[tuple[list, list]]:
    """``n_boot`` draws of (tests, per drawn test the resampled indices) for tests of ``lengths`` samples."""
    n = len(lengths)
    out = []
    for _ in range(n_boot):
        which = list(rng.integers(0, n, n)) if n >= 3 else list(range(n))
        idx = []
        for j in which:
            k, L = lengths[j], min(blocks[j], lengths[j])
            starts = rng.integers(0, k - L + 1, int(np.ceil(k / L)))
            idx.append((starts[:, None] + np.arange(L)[None]).ravel()[:k])
        out.append((which, idx))
    return out


def centred_interval(point: float, boot: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Percentile interval of ``boot`` recentred on ``point`` (contains ``point`` by construction)."""
    b = _finite(boot)
    if b.size < 10 or not np.isfinite(point):
        return (float("nan"), float("nan"))
    q = np.percentile(b - np.median(b), [50 * (1 - level), 50 * (1 + level)])
    return float(point + q[0]), float(point + q[1])
