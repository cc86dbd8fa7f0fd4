"""Gradient polish of a candidate's fold fits: Levenberg-Marquardt through the differentiable simulator.

After the derivative-free search (:mod:`.fit`) each fold's best point is refined on the fold's
*calibration* residuals r (weighted so that ‖r‖² is exactly the fold's calibration loss):

- parameters live in the unit cube; the polish works in z = logit(u), u = sigmoid(z), so every step
  stays inside the bounds (a point on a bound stays near it: the logistic map is flat there);
- the Jacobian ∂r/∂z is by default a *secant* (central-difference) Jacobian over ±``SECANT_STEP`` in z from
  the batched simulator: 2p + 1 points per fold, all folds in one simulation. ``jacobian="forward"`` uses
  ``jax.jacfwd`` through :func:`trackenv.simulate.simulate_batch` instead (each vehicle of the batch belongs
  to one fold, so a shared perturbation δ added to every fold's z gives each fold's own Jacobian in one
  forward-mode pass with p tangents). The forward-mode Jacobian is exact for the discrete simulation, but
  stick-slip after a stop and chattering contact amplify its sensitivities. On a blind null case the
  forward-mode gradient of ``recalibrate_base``'s fold loss had a norm of 9·10⁹ and Levenberg-Marquardt
  stopped on a "small step" at once; the secant polish lowered the same fold's calibration loss from
  1.21 to 0.92. Through ``slip_sinkage`` in float32 the forward-mode Jacobian is not finite at all;
- Levenberg-Marquardt with Marquardt's diagonal scaling: step = −(JᵀJ + λ diag JᵀJ)⁻¹ Jᵀr, accepted if
  the loss drops (λ / 3), else rejected (λ × 4); a parameter the residuals do not feel is held still
  (:func:`marquardt_step`); the encoder window chosen by the search is kept.

Reported per fold: ``iterations``, ``grad_norm`` (‖∂loss/∂z‖ at the final point), ``last_rel_improvement``,
``held_still`` (the parameters the last step held still: the data do not feel them there) and ``stop``
("small step", "small gradient", "small improvement", "iteration limit", "gradient not finite"). A fold's
polished point replaces the search's only if its loss (recomputed by :mod:`.fit`) is lower. An effect's fits
on the control and on the base model are polished as one problem, one row per fold and fit (``.fit``), which
compiles one simulation for both.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..compare import POSE, wrap_angle
from ..simulate import simulate_on_cores
from .batch import predictions_at_log
from .candidates import ON, Candidate
from .metrics import signal_weight

U_EPS = 1e-3
INERT_COLUMN = 1e-3  # a parameter whose Jacobian column is below this fraction of the largest one's is held still
SECANT_STEP = 0.05  # logit units (≈ 1.2 % of a parameter's range at mid-cube): the secant Jacobian's half-width
JACOBIANS = ("secant", "forward")


def points_per_evaluation(n_params: int, jacobian: str = "secant") -> int:
    """Parameter points one polish evaluation simulates per fit: the point and its Jacobian's, 2p for the secant
    (±``SECANT_STEP`` per parameter) or p tangents for forward mode."""
    return 1 + (2 if jacobian == "secant" else 1) * n_params


def _host_divide(a, b):
    """``a / b`` in numpy, rounded as XLA's CPU compiler rounds jax's: a divisor broadcast over ``a`` (a scalar, a
    row) becomes a multiplication by its reciprocal in ``a``'s precision."""
    b = np.asarray(b, a.dtype)
    if b.shape != np.broadcast_shapes(a.shape, b.shape):
        return a * (a.dtype.type(1.0) / b)
    return a / b


def _encoder_average(t, x, window, host: bool = False):
    """:func:`.batch.encoder_average` with one window per column (``window`` (S,), 0 = none); jax, or with
    ``host`` numpy in float32 except the running sum (jax's, whose order of additions numpy's does not share),
    the same numbers (see :meth:`_Problem._predict`)."""
    xp = np if host else jnp
    div = _host_divide if host else jnp.divide
    dt = t[1] - t[0]
    steps = 0.5 * (x[1:] + x[:-1]) * dt
    cum = np.asarray(jnp.cumsum(steps, axis=0)) if host else jnp.cumsum(steps, axis=0)
    F = xp.concatenate([xp.zeros_like(x[:1]), cum])
    w = xp.maximum(window, xp.asarray(1e-6, window.dtype))[None, :]
    tau = t[:, None] - w
    k = xp.clip(xp.floor(div(tau, dt)).astype(xp.int32), 0, len(t) - 2)
    f = xp.clip(div(tau - t[k], dt), xp.asarray(0.0, x.dtype), xp.asarray(1.0, x.dtype))
    cols = xp.arange(x.shape[1])[None, :]
    Fi = F[k, cols] * (1 - f) + F[k + 1, cols] * f
    Fi = xp.where(tau < 0, x[:1] * tau, Fi)
    return xp.where(window[None, :] > 0, div(F - Fi, w), x)


class _Problem:
    """The residual function of every fold of one candidate, evaluated with its Jacobian in one batched simulation."""

    def __init__(self, sim, cand: Candidate, fold_defs, windows, below=None):
        self.sim, self.cand, self.F = sim, cand, len(fold_defs)
        self.below = below  # per fold: the fitted values of the candidate ``cand`` stands on (or None)
        tests = sim.tests
        self.sigs = []  # per test: signals compared
        self.meas, self.coef, self.ok = [], [], []
        from .fit import split_parts

        for j, t in enumerate(tests):
            part = split_parts(t)
            sigs = [s for s in t.measured]
            nsig = [sum(int(np.any(np.isfinite(t.measured[s]) & t.fit_mask & (part == q))) for s in sigs)
                    for q in (0, 1)]
            for s in sigs:
                ok = np.isfinite(t.measured[s]) & t.fit_mask
                c = np.zeros((self.F, len(t.t)))
                for q in (0, 1):
                    m = ok & (part == q)
                    if m.sum() == 0:
                        continue
                    for f, fd in enumerate(fold_defs):
                        c[f, m] = fd.weights[j, q] * signal_weight(t, s) / (m.sum() * nsig[q])
                self.meas.append(np.where(ok, t.measured[s], 0.0))
                self.coef.append(np.sqrt(c))
                self.sigs.append((j, s))
        self.windows = np.array([0.0 if w is None else float(w) for w in windows])

    def _predict(self, z, host: bool):
        """z (R, p), row r a point of fold r mod F -> {(j, sig): (R, K_j)} predictions at the logs' sample times.

        ``host`` False (``z`` traced, forward mode): everything is jax. On the host (the
        secant Jacobian), the indexing, tiling and transposing and the float32 +, −, ×, ÷ and |x| run in numpy:
        eagerly, each jax operation compiles a small program for every shape it meets (about 680 programs and
        20 s in a diagnosis of three tests), and numpy's float32 operations round as jax's do (where XLA
        rewrites a division, :func:`_host_divide` does the same). The exponentials, the running sums, the
        candidate's parameter arithmetic and the simulation stay in jax. Both give the same numbers to the last
        bit (tests/test_polish_programs.py; docs/performance.md, "The polish's evaluations on the host")."""
        sim, cand = self.sim, self.cand
        F = z.shape[0]  # rows simulated (a multiple of the number of folds)
        windows = self.windows[np.arange(F) % self.F]
        u = jax.nn.sigmoid(z)
        u = np.asarray(u) if host else u
        vals = {s.name: s.to_physical_jnp(u[:, k]) for k, s in enumerate(cand.specs)}
        fold_of = np.arange(F) % self.F
        fixed = {} if self.below is None else {ON + k: np.array([self.below[f][k] for f in fold_of])
                                               for k in self.below[0]}
        out = {}
        for bi, b in enumerate(sim.buckets):
            nb = len(b.tests)
            base, ref = sim.stacked_base(b, F)
            # jax arrays, so that the candidate's arithmetic on them is jax's (float32 throughout)
            v = {k: jnp.asarray(np.tile(np.asarray(x), nb)) if host else jnp.tile(x, nb) for k, x in vals.items()}
            v |= {k: np.tile(x, nb) for k, x in fixed.items()}
            params = cand.apply(base, v, ref)
            t = jnp.arange(b.n_steps + 1, dtype=params.dtype) * b.dt
            if cand.instrument_only:
                ch0 = sim.channels_below(bi, b, cand, {k[len(ON):]: x for k, x in fixed.items()}, F)
                ch = {k: jnp.asarray(x, params.dtype) for k, x in ch0.items()}
                for eff in params.effects[-1:]:  # its own: the base's are in ``ch`` already
                    ch = eff.instruments(ch, t, params)
            else:
                prof = b.profile(F, params.dtype)
                traj = simulate_on_cores(params, prof, b.n_steps, b.dt, b.substeps,
                                         keep_arrays=cand.varied_leaves)  # (nb * F,) vehicles
                ch = dict(traj.channels)
            if host:
                ch, t = {k: np.asarray(x) for k, x in ch.items()}, np.asarray(t)
            if not cand.instrument_only and np.any(windows > 0):
                win = (np.asarray if host else jnp.asarray)(np.tile(windows, nb), params.dtype)
                ch["speed_ideal"] = _encoder_average(t, ch["speed_ideal"], win, host)
            for q, j in enumerate(b.tests):
                cols = slice(q * F, (q + 1) * F)
                test = sim.tests[j]
                need = set(test.measured) | (set(POSE) if any(k in test.measured for k in POSE) else set())
                at_log = predictions_at_log(test, {k: ch[k][:, cols] for k in need}, sim._interp[j])
                out.update({(j, s): x.T for s, x in at_log.items()})  # (F, K)
        return out

    def _residual(self, z, host: bool | None = None):
        """Weighted residuals (R, N) and the predictions of :meth:`_predict` (``host`` by default unless ``z`` is
        traced)."""
        host = not isinstance(z, jax.core.Tracer) if host is None else host
        pred = self._predict(z, host)
        xp = np if host else jnp
        rs = []
        for (j, s), meas, coef in zip(self.sigs, self.meas, self.coef):
            dtype = pred[(j, s)].dtype
            e = pred[(j, s)] - xp.asarray(meas, dtype)[None]
            if s == "heading":
                e = wrap_angle(e)
            rs.append(e * xp.asarray(coef[np.arange(e.shape[0]) % self.F], dtype))
        return xp.concatenate(rs, axis=1), pred

    def _value_and_jac(self, z):
        p = z.shape[1]
        g = lambda d: self._residual(z + d[None])  # noqa: E731
        (r, pred) = g(jnp.zeros((p,), z.dtype))
        J = jax.jacfwd(lambda d: g(d)[0])(jnp.zeros((p,), z.dtype))  # (F, N, p)
        return r, J, pred

    def _value_and_secant(self, z):
        """Residuals and the central-difference Jacobian over ±``SECANT_STEP`` in z: 2p + 1 points per fold, one
        batched simulation (``z`` a float32 numpy array; the arithmetic in numpy, as :meth:`_predict`)."""
        F, p = z.shape
        shifts = np.concatenate([np.zeros((1, p)), SECANT_STEP * np.eye(p), -SECANT_STEP * np.eye(p)])
        Z = (z[None] + shifts.astype(z.dtype)[:, None]).reshape(((2 * p + 1) * F, p))
        R, pred_all = self._residual(Z)
        R = R.reshape((2 * p + 1, F) + R.shape[1:])
        J = np.moveaxis(_host_divide(R[1: p + 1] - R[p + 1:], 2.0 * SECANT_STEP), 0, -1)  # (F, N, p)
        # laid out in memory as jax lays them out, so that the float64 products and sums over them add in the same
        # order
        J = np.ascontiguousarray(J)
        pred = {k: np.ascontiguousarray(v[:F]) for k, v in pred_all.items()}
        return R[0], J, pred

    def __call__(self, z, jacobian: str = "secant"):
        # the simulation inside is one jitted call (forward mode: its JVP, which jax caches by shape)
        if jacobian == "secant":
            r, J, pred = self._value_and_secant(np.asarray(z, np.float32))
        else:
            r, J, pred = self._value_and_jac(jnp.asarray(z, jnp.float32))
            pred = {k: np.asarray(v) for k, v in pred.items()}
        # counted here, outside any trace, as :attr:`.batch.BatchSimulator.n_vehicle_seconds` counts the search's:
        # the rows simulated (a forward-mode pass counts its p tangents too, as ``n_simulations`` does)
        if not self.cand.instrument_only:
            rows = z.shape[0] * points_per_evaluation(z.shape[1], jacobian)
            self.sim.n_vehicle_seconds += rows * sum(len(b.tests) * b.n_steps * b.dt for b in self.sim.buckets)
        return np.asarray(r, np.float64), np.asarray(J, np.float64), pred


def marquardt_step(J: np.ndarray, r: np.ndarray, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """The Levenberg-Marquardt step −(JᵀJ + λ diag JᵀJ)⁻¹ Jᵀr for Jacobian ``J`` (N, p) and residuals ``r`` (N,),
    and the (p,) bool mask of the parameters it moves.

    A parameter whose Jacobian column is below ``INERT_COLUMN`` of the largest column's norm is held still
    (step 0) and the step is solved for the others. Such a column is float32 rounding, not sensitivity (the
    cohesion factor on asphalt, which no force on hard ground depends on): Marquardt's scaling divides by its
    tiny norm, and the step it would get used up the step-length limit of :func:`polish_folds` and left the
    other parameters all but still. On a blind null case on asphalt that stopped ``recalibrate_base`` at a
    loss of 1.076 where the nuisance's own values give 1.059.
    """
    A = J.T @ J
    g = J.T @ r
    col2 = np.diag(A)
    free = col2 > INERT_COLUMN**2 * col2.max()
    d = np.zeros(len(g))
    if free.any():
        Af = A[np.ix_(free, free)]
        d[free] = -np.linalg.solve(Af + lam * np.diag(np.diag(Af)) + 1e-9 * np.eye(int(free.sum())), g[free])
    return d, free


def not_polished_note(info: list[dict]) -> list[str]:
    """The report's note on the fits whose search point had no finite gradient (``info``: per fit, as
    :func:`polish_folds` returns it)."""
    bad = sum(not i["used_gradient"] for i in info)
    return [f"gradient not finite at the search point of {bad} of {len(info)} fits (those not polished)"] if bad else []


def polish_folds(sim, cand: Candidate, fold_defs, units, windows, scores, *, iters: int = 4,
                 progress=None, jacobian: str = "secant", below: list | None = None) -> dict:
    """Levenberg-Marquardt from each fold's search point; see the module docstring. ``below``: per fold, the
    fitted values of the candidate that ``cand`` stands on (:attr:`.candidates.Candidate.on`). ``progress``:
    called after each batched evaluation with its number of test evaluations (one parameter point on one test),
    the ``n_simulations`` it adds."""
    from .fit import point_loss_parts

    F, p = len(fold_defs), cand.n_params
    tests = sim.tests
    prob = _Problem(sim, cand, fold_defs, windows, below)
    u0 = np.clip(np.stack(units), U_EPS, 1 - U_EPS)
    z = np.log(u0) - np.log1p(-u0)
    if jacobian not in JACOBIANS:
        raise ValueError(f"jacobian must be one of {JACOBIANS}, got {jacobian!r}")
    per_call = sum(len(b.tests) for b in sim.buckets) * F * points_per_evaluation(p, jacobian)
    r, J, pred = prob(z, jacobian)
    n_calls = 1
    if progress:
        progress(per_call)
    loss = np.sum(r**2, axis=1)
    lam = np.full(F, 1e-2)
    active = np.isfinite(J).all(axis=(1, 2)) & np.isfinite(loss)
    info = [{"used_gradient": bool(active[f]), "iterations": 0, "grad_norm": None, "last_rel_improvement": None,
             "stop": "iteration limit" if active[f] else "gradient not finite", "start_loss": float(loss[f]),
             "held_still": []}
            for f in range(F)]
    best_pred = [pred] * F
    fold_z = z.copy()
    for it in range(iters):
        if not active.any():
            break
        step = np.zeros_like(z)
        for f in np.flatnonzero(active):
            g = J[f].T @ r[f]
            info[f]["grad_norm"] = float(2 * np.linalg.norm(g))
            if 2 * np.linalg.norm(g) < 1e-6 * max(loss[f], 1e-12):
                info[f]["stop"], active[f] = "small gradient", False
                continue
            d, free = marquardt_step(J[f], r[f], lam[f])
            info[f]["held_still"] = [s.name for s, moved in zip(cand.specs, free) if not moved]
            nd = np.linalg.norm(d)
            if nd > 2.0:
                d *= 2.0 / nd
            if nd < 1e-4:
                info[f]["stop"], active[f] = "small step", False
                continue
            step[f] = d
        if not active.any():
            break
        z_new = fold_z + step
        r2, J2, pred2 = prob(z_new, jacobian)
        n_calls += 1
        if progress:
            progress(per_call)
        loss2 = np.sum(r2**2, axis=1)
        for f in np.flatnonzero(active):
            info[f]["iterations"] = it + 1
            if np.isfinite(loss2[f]) and loss2[f] < loss[f] and np.isfinite(J2[f]).all():
                rel = (loss[f] - loss2[f]) / max(loss[f], 1e-12)
                info[f]["last_rel_improvement"] = float(rel)
                fold_z[f], r[f], J[f], loss[f] = z_new[f], r2[f], J2[f], loss2[f]
                best_pred[f] = pred2
                lam[f] = max(lam[f] / 3.0, 1e-7)
                if rel < 1e-4:
                    info[f]["stop"], active[f] = "small improvement", False
            else:
                info[f]["last_rel_improvement"] = 0.0
                lam[f] *= 4.0
    for f in range(F):
        if info[f]["used_gradient"]:
            info[f]["grad_norm"] = float(2 * np.linalg.norm(J[f].T @ r[f]))
        info[f]["end_loss"] = float(loss[f])
    units_new, preds_new, scores_new, improved = [], [], [], []
    for f in range(F):
        u = 1.0 / (1.0 + np.exp(-fold_z[f]))
        pr = best_pred[f]
        per_test = []
        for j, t in enumerate(tests):
            per_test.append({s: np.asarray(pr[(j, s)][f], np.float64) for s in t.measured})
        lp = point_loss_parts(tests, per_test)
        sc = float(np.sum(np.where(fold_defs[f].weights > 0, lp * fold_defs[f].weights, 0.0)))
        units_new.append(u)
        preds_new.append(per_test)
        scores_new.append(sc)
        improved.append(bool(info[f]["used_gradient"] and np.isfinite(sc) and sc < scores[f]))
        info[f]["polished_loss"] = sc
        info[f]["search_loss"] = float(scores[f])
    return {"units": units_new, "preds": preds_new, "scores": scores_new, "improved": improved, "info": info,
            "notes": not_polished_note(info), "n_simulations": n_calls * per_call}
