"""Calibrate uncertain model parameters on field logs, and measure the fit on held-out logs.

    from trackenv.calibrate import calibrate, evaluate
    cal = calibrate(["logs/asphalt_00", "logs/asphalt_04"], {"vehicle.stiction_torque": (0.0, 15.0),
                                                           "internal.constant": (0.0, 15.0)})
    cal.values                       # {"vehicle.stiction_torque": ..., "internal.constant": ...}
    evaluate(["logs/asphalt_06"], cal.values).nrmse   # held-out error per log and channel

The logs may drive the model by voltages or by measured speeds (docs/model.md §9); a calibration set
should use one vehicle. Every log is simulated with its own terrain and vehicle (or ``vehicle``), and
all logs and parameter sets of one evaluation run as one batch (:mod:`trackenv.diagnose.batch`).

**Objective.** For each log j and compared channel c, the error at the log's samples that enter fits
(:func:`trackenv.diagnose.data.fit_mask`) is divided by the channel's robust span in that log (1st-99th
percentile spread, the diagnosis's NRMSE denominator) and by sqrt(n): the cost is the sum over logs
and channels of NRMSE², so every log and channel weighs the same whatever its length or unit. In
speed mode the encoder channel ``speed_ideal`` is the input and is never compared.

**Optimiser.** ``scipy.optimize.least_squares`` (trust-region reflective) in the unit cube of the given
bounds, with a forward-difference Jacobian of step ``diff_step`` (in the unit cube) whose p columns run as
one batch. The step is a secant on purpose: the stick-slip of the contact model makes infinitesimal
derivatives erratic (the diagnosis's polish makes the same choice).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import yaml

from .compare import grid_weights, stack_trees
from .diagnose.batch import FIT_SUBSTEP, make_buckets, predictions_at_log
from .diagnose.data import DiagnosisError, TestData, load_tests
from .params import BOUNDS, ConfigError, check_range, load_params
from .simulate import simulate_batch

__all__ = ["Calibration", "Evaluation", "NaiveBaseline", "calibrate", "evaluate", "write_vehicle_config"]

DEFAULT_SIGNALS = ("i_left", "i_right", "yaw_rate")


@dataclass
class Evaluation:
    """Errors of one parameter set on a set of logs: ``nrmse[log][channel]`` and the total cost Σ NRMSE²."""

    values: dict
    nrmse: dict
    rmse: dict
    cost: float
    diverged: list = field(default_factory=list)
    predictions: dict = field(default_factory=dict)  # log -> {"t": (K,), channel: (K,) simulated, as its instruments}


@dataclass
class Calibration:
    """Result of :func:`calibrate`: fitted ``values`` (dotted parameter -> SI value), the bounds, the cost before
    and after, the per-log errors before/after, the number of evaluations and the wall time [s]."""

    values: dict
    bounds: dict
    initial: dict
    before: Evaluation
    after: Evaluation
    n_evaluations: int
    wall_time_s: float
    message: str
    at_bound: list = field(default_factory=list)


class _Problem:
    """The logs, their batches, and the map from parameter sets to scaled residuals."""

    def __init__(self, tests: list[TestData], names: Sequence[str], signals: Sequence[str], vehicle, substep: float):
        self.tests, self.names, self.substep = tests, list(names), substep
        self.signals = [[s for s in signals if s in t.measured] for t in tests]
        if not any(self.signals):
            raise DiagnosisError(f"none of the logs measures any of {', '.join(signals)}")
        self.buckets = make_buckets(tests, substep)
        self.base = [load_params(t.terrain, vehicle=vehicle or t.vehicle) for t in tests]
        for name in self.names:
            _leaf(self.base[0], name)
        self.weights = {}
        for b in self.buckets:
            for j in b.tests:
                self.weights[j] = grid_weights(tests[j].t, b.dt, b.n_steps)
        self.n_evaluations = 0

    def default_values(self) -> dict:
        """Each parameter's value in the first log's base model."""
        return {n: float(np.ravel(np.asarray(_leaf(self.base[0], n)))[0]) for n in self.names}

    def predict(self, sets: np.ndarray) -> tuple[list[dict], np.ndarray]:
        """Simulate S parameter sets (S, p) [SI] on every log: predictions {signal: (K, S)} and diverged (n, S)."""
        S = sets.shape[0]
        pred, div = [None] * len(self.tests), np.zeros((len(self.tests), S), bool)
        for b in self.buckets:
            nb = len(b.tests)
            params = stack_trees([self.base[j] for j in b.tests])
            params = jax.tree.map(lambda x: jnp.repeat(x, S, axis=-1) if eqx.is_inexact_array(x) else x, params)
            for k, name in enumerate(self.names):
                params = _set_leaf(params, name, np.tile(sets[:, k], nb))
            traj = simulate_batch(params, b.profile(S, params.dtype), b.n_steps, b.dt, b.substeps)
            ch = {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}
            d = np.asarray(traj.diverged)
            for q, j in enumerate(b.tests):
                cols = slice(q * S, (q + 1) * S)
                pred[j] = predictions_at_log(self.tests[j], {k: v[:, cols] for k, v in ch.items()}, self.weights[j])
                div[j] = d[cols]
        self.n_evaluations += S
        return pred, div

    def residuals(self, sets: np.ndarray) -> np.ndarray:
        """Scaled residuals (S, R): (sim - meas) / span / sqrt(n) over every log's compared samples."""
        pred, div = self.predict(sets)
        out = []
        for j, t in enumerate(self.tests):
            for sig in self.signals[j]:
                meas = t.measured[sig]
                ok = np.isfinite(meas) & (t.fit_mask if t.fit_mask is not None else True)
                r = (pred[j][sig][ok] - meas[ok, None]) / (t.span[sig] * np.sqrt(ok.sum()))
                r = np.where(np.isfinite(r) & ~div[j][None, :], r, 10.0 / np.sqrt(ok.sum()))
                out.append(r.T)
        return np.concatenate(out, axis=1)

    def evaluation(self, values: dict) -> Evaluation:
        sets = np.array([[values[n] for n in self.names]], np.float64)
        pred, div = self.predict(sets)
        nrmse, rmse, cost, preds = {}, {}, 0.0, {}
        for j, t in enumerate(self.tests):
            nrmse[t.name], rmse[t.name] = {}, {}
            preds[t.name] = {"t": t.t, **{sig: pred[j][sig][:, 0] for sig in self.signals[j]}}
            for sig in self.signals[j]:
                meas = t.measured[sig]
                ok = np.isfinite(meas) & (t.fit_mask if t.fit_mask is not None else True)
                e = float(np.sqrt(np.mean((pred[j][sig][ok, 0] - meas[ok]) ** 2)))
                rmse[t.name][sig] = e
                nrmse[t.name][sig] = e / t.span[sig]
                cost += (e / t.span[sig]) ** 2
        return Evaluation(dict(values), nrmse, rmse, float(cost), [t.name for j, t in enumerate(self.tests) if div[j, 0]],
                          preds)


def _leaf(params, dotted: str):
    node = params
    for part in dotted.split("."):
        if not hasattr(node, part):
            raise ConfigError(f"unknown parameter '{dotted}' (e.g. vehicle.stiction_torque, internal.constant, "
                              "terrain.friction_angle)")
        node = getattr(node, part)
    if not eqx.is_inexact_array(node):
        raise ConfigError(f"parameter '{dotted}' is not a floating-point model parameter")
    return node


def _set_leaf(params, dotted: str, value):
    parts = dotted.split(".")

    def where(p):
        for part in parts:
            p = getattr(p, part)
        return p

    return eqx.tree_at(where, params, jnp.asarray(value, params.dtype))


def _load(logs, where: str) -> list[TestData]:
    tests = []
    for item in logs:
        found, excluded = load_tests(item)
        if excluded:
            raise DiagnosisError(f"{where}: {excluded[0]['test']}: {excluded[0]['reason']}")
        tests.extend(found)
    names = [t.name for t in tests]
    if len(set(names)) != len(names):
        tests = [dataclasses.replace(t, name=f"{t.folder.parent.name}/{t.name}") for t in tests]
    return tests


def _check_bounds(parameters: dict) -> dict:
    out = {}
    for name, rng in parameters.items():
        try:
            lo, hi = (float(x) for x in rng)
        except (TypeError, ValueError):
            raise ConfigError(f"calibration bounds of '{name}' must be a pair (low, high), got {rng!r}") from None
        if not hi > lo:
            raise ConfigError(f"calibration bounds of '{name}': high {hi:g} must exceed low {lo:g}")
        if name in BOUNDS:
            check_range(name, lo, hi, "calibration bounds")
        out[name] = (lo, hi)
    return out


def evaluate(logs: Sequence[str | Path], values: dict, *, signals: Sequence[str] = DEFAULT_SIGNALS, vehicle=None,
             substep: float = FIT_SUBSTEP) -> Evaluation:
    """Errors of the parameter set ``values`` (dotted name -> SI value; ``{}``: the configs as they are) on ``logs``
    (field-log folders, or folders of them): NRMSE and RMSE per log and channel."""
    tests = _load(logs, "evaluate")
    return _Problem(tests, list(values), signals, vehicle, substep).evaluation(values)


def calibrate(logs: Sequence[str | Path], parameters: dict, *, signals: Sequence[str] = DEFAULT_SIGNALS,
              vehicle=None, substep: float = FIT_SUBSTEP, max_nfev: int = 12, diff_step: float = 0.03,
              initial: dict | None = None, progress: bool = True) -> Calibration:
    """Fit ``parameters`` ({dotted name: (low, high)} in SI units) to ``logs`` by least squares.

    Args:
        logs: field-log folders, or folders holding field-log folders (voltage or speed mode).
        parameters: the uncertain parameters and their search bounds, e.g. ``{"vehicle.stiction_torque":
            (0, 15), "internal.constant": (0, 15), "terrain.friction_angle": (0.35, 0.8)}`` (angles in rad).
        signals: the compared channels (those a log lacks are skipped for it).
        vehicle: a vehicle id or YAML path replacing the logs' ``meta.json`` vehicle.
        substep: integration substep [s] (the diagnosis's fit substep by default).
        max_nfev: most residual evaluations of the optimiser (each Jacobian is one more batch).
        diff_step: forward-difference step in the unit cube of the bounds.
        initial: start values (default: the configs' values, clipped into the bounds).
        progress: print one line per evaluation to stderr.

    Raises:
        DiagnosisError: a log is unusable. ConfigError: an unknown parameter or bad bounds.
    """
    from scipy.optimize import least_squares  # noqa: PLC0415

    t0 = time.perf_counter()
    bounds = _check_bounds(parameters)
    tests = _load(logs, "calibrate")
    names = list(bounds)
    prob = _Problem(tests, names, signals, vehicle, substep)
    lo = np.array([bounds[n][0] for n in names])
    hi = np.array([bounds[n][1] for n in names])
    start = dict(prob.default_values(), **(initial or {}))
    x0 = np.clip((np.array([start[n] for n in names]) - lo) / (hi - lo), 0.0, 1.0)
    to_si = lambda u: lo + np.clip(u, 0.0, 1.0) * (hi - lo)  # noqa: E731
    before = prob.evaluation(dict(zip(names, to_si(x0))))

    def fun(u):
        r = prob.residuals(to_si(u)[None])[0]
        if progress:
            import sys  # noqa: PLC0415

            vals = ", ".join(f"{n}={v:.4g}" for n, v in zip(names, to_si(u)))
            print(f"calibrate: cost {float(r @ r):.5g} at {vals}", file=sys.stderr)
        return r

    def jac(u):
        steps = np.where(u + diff_step <= 1.0, diff_step, -diff_step)
        sets = np.repeat(u[None], len(u), axis=0) + np.diag(steps)
        r0 = prob.residuals(to_si(u)[None])[0]
        r = prob.residuals(to_si(sets))
        return ((r - r0[None]) / steps[:, None]).T

    res = least_squares(fun, x0, jac=jac, bounds=(0.0, 1.0), method="trf", max_nfev=max_nfev, x_scale=1.0)
    values = dict(zip(names, (float(v) for v in to_si(res.x))))
    after = prob.evaluation(values)
    at_bound = [n for n, u in zip(names, res.x) if u <= 1e-3 or u >= 1 - 1e-3]
    return Calibration(values, bounds, dict(zip(names, to_si(x0).tolist())), before, after, prob.n_evaluations,
                       time.perf_counter() - t0, str(res.message), at_bound)


def write_vehicle_config(base: str | Path, values: dict, path: str | Path, source: str) -> Path:
    """Write a vehicle YAML: the config ``base`` (an id of ``configs/vehicle`` or a path) with the ``vehicle.*``
    entries of ``values`` replaced, each sourced as ``source``. Other entries are kept as they are."""
    from .params import VEHICLE_DIR, _resolve  # noqa: PLC0415

    src = _resolve(base, VEHICLE_DIR, "vehicle")
    data = yaml.safe_load(src.read_text(encoding="utf-8"))
    for name, value in values.items():
        if not name.startswith("vehicle."):
            continue
        key = name.split(".", 1)[1]
        if key not in data or not isinstance(data[key], dict):
            raise ConfigError(f"{src}: no entry '{key}' to calibrate")
        data[key] = {"value": float(value), "unit": data[key].get("unit", ""), "source": source}
    data["id"] = Path(path).stem
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# {data['id']}: {src.name} with calibrated entries ({source}).\n"
                   + yaml.safe_dump(data, sort_keys=False, allow_unicode=True), encoding="utf-8")
    return out


@dataclass
class NaiveBaseline:
    """A model-free reference for speed-mode logs, fitted by linear least squares on calibration logs.

    Motor current per side: |i| = a + b |V_side| + c |V_right - V_left| (a current per speed, plus a term for
    turning, where skid steering costs torque); yaw rate: r = chi (V_right - V_left) / B, the kinematic
    skid-steer yaw rate with a fitted slip factor chi (B: the vehicle's track gauge). V are the log's track
    speeds [m/s] (omega r_s' for ``omega`` columns). The simulator should beat it on held-out logs to be worth
    its physics.
    """

    current: np.ndarray  # (3,) a [A], b [A s/m], c [A s/m]
    chi: float
    gauge: float

    @staticmethod
    def _features(t: TestData, radius: float):
        v = t.drive_values * radius  # (K, 2) track speeds [m/s]
        turn = np.abs(v[:, 1] - v[:, 0])
        return v, turn

    @classmethod
    def fit(cls, logs: Sequence[str | Path], vehicle=None) -> NaiveBaseline:
        """Fit on speed-mode ``logs`` (field-log folders or folders of them)."""
        tests = _load(logs, "baseline")
        rows, ys, kin, yaw = [], [], [], []
        for t in tests:
            if t.drive_kind != "speed":
                raise DiagnosisError(f"{t.folder}: the naive baseline needs a speed-mode log")
            radius, gauge = _radius_gauge(t, vehicle)
            v, turn = cls._features(t, radius)
            mask = t.fit_mask if t.fit_mask is not None else np.ones(len(t.t), bool)
            for side, sig in enumerate(("i_left", "i_right")):
                if sig in t.measured:
                    ok = mask & np.isfinite(t.measured[sig])
                    rows.append(np.stack([np.ones(ok.sum()), np.abs(v[ok, side]), turn[ok]], 1))
                    ys.append(t.measured[sig][ok])
            if "yaw_rate" in t.measured:
                ok = mask & np.isfinite(t.measured["yaw_rate"])
                kin.append((v[ok, 1] - v[ok, 0]) / gauge)
                yaw.append(t.measured["yaw_rate"][ok])
        coef = np.linalg.lstsq(np.concatenate(rows), np.concatenate(ys), rcond=None)[0]
        k, y = np.concatenate(kin), np.concatenate(yaw)
        return cls(coef, float(k @ y / max(k @ k, 1e-12)), gauge)

    def predict(self, t: TestData, vehicle=None) -> dict:
        """The baseline's |i_left|, |i_right| [A] and yaw rate [rad/s] at a speed-mode log's samples, (K,) each."""
        radius, gauge = _radius_gauge(t, vehicle)
        v, turn = self._features(t, radius)
        one = np.ones_like(turn)
        return {"i_left": self.current @ np.stack([one, np.abs(v[:, 0]), turn]),
                "i_right": self.current @ np.stack([one, np.abs(v[:, 1]), turn]),
                "yaw_rate": self.chi * (v[:, 1] - v[:, 0]) / gauge}

    def evaluate(self, logs: Sequence[str | Path], vehicle=None) -> Evaluation:
        """NRMSE and RMSE per log and channel, as :func:`evaluate` reports them for the simulator."""
        nrmse, rmse, cost, preds = {}, {}, 0.0, {}
        for t in _load(logs, "baseline"):
            pred = self.predict(t, vehicle)
            preds[t.name] = {"t": t.t, **pred}
            mask = t.fit_mask if t.fit_mask is not None else np.ones(len(t.t), bool)
            nrmse[t.name], rmse[t.name] = {}, {}
            for sig in DEFAULT_SIGNALS:
                if sig in t.measured:
                    ok = mask & np.isfinite(t.measured[sig])
                    e = float(np.sqrt(np.mean((pred[sig][ok] - t.measured[sig][ok]) ** 2)))
                    rmse[t.name][sig], nrmse[t.name][sig] = e, e / t.span[sig]
                    cost += (e / t.span[sig]) ** 2
        return Evaluation({"current": self.current.tolist(), "chi": self.chi}, nrmse, rmse, float(cost),
                          predictions=preds)


def _radius_gauge(t: TestData, vehicle) -> tuple[float, float]:
    from .physics.geometry import belt_radius  # noqa: PLC0415

    p = load_params(t.terrain, vehicle=vehicle or t.vehicle)
    return float(np.asarray(belt_radius(p.vehicle, p.terrain))), float(p.vehicle.track_gauge)
