"""Batched simulation of many (test, parameter set) pairs in one jitted call per candidate.

All the pairs of a candidate run as one batch with the vehicle index on the last axis (docs/model.md §6):
vehicle ``j * S + s`` is test ``j`` with parameter set ``s``. Tests of similar length share a batch
(``buckets``: padded to the longest; a test shorter than ``BUCKET_FILL`` times the longest goes to its
own bucket, which bounds the simulation that padding wastes). Each test's voltages are resampled onto the batch's
common grid (step ≤ 10 ms and ≤ the log's smallest interval, so the log's own breakpoints are kept for
logs at ≤ 100 Hz); the simulated channels are evaluated at the log's sample times by linear
interpolation on the output grid, rectified (|i|) where ``meta.json`` says the ammeter is absolute,
and the pose is moved into the log's frame by its first pose sample: the rules of
:mod:`trackenv.compare`, which :func:`trackenv.replay.replay` follows for one test. Each bucket is one
call of :func:`trackenv.simulate.simulate_on_cores` (split over both cores); compiled programs are cached
per (candidate, bucket shape), so every round of a fit reuses them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compare import POSE, SampleWeights, at_samples, grid_weights, pose_to_log_frame, rectify, stack_trees
from ..parallel import host_movable
from ..params import load_params
from ..simulate import DEFAULT_SUBSTEP, SpeedProfile, VoltageProfile, simulate_on_cores
from .candidates import Candidate
from .data import TestData

# s: the fits integrate at the simulator's verified default substep. A coarser one is judged against the
# instruments' noise, not against a channel's span: at 1 ms (NRMSE <= 1.4 % of the span against the tight
# reference, tests/test_convergence.py) the events at the stops and steering reversals move the predictions
# by up to ~28 noise sigma on the blind benchmark's cases, so the fits chased integration error
# (docs/diagnose_benchmark.md, "The fits' substep").
FIT_SUBSTEP = DEFAULT_SUBSTEP
# A test shares a bucket only with tests at most 1 / BUCKET_FILL times its length. Padding is cheaper than it
# looks: per vehicle, a batch of a few hundred runs 1.5-2x faster than one of a hundred (docs/performance.md),
# and each extra bucket costs one compiled program per candidate. Measured on the field twin's 6-test
# diagnosis (benchmarks/bench_diagnose.py, one process, the split layout run first): the 5 s tests in
# buckets of their own, 645 s; padded to the 10 s lane changes in one bucket, 477 s.
BUCKET_FILL = 0.5


@dataclass(frozen=True)
class Bucket:
    tests: tuple  # indices into the test list
    n_steps: int
    dt: float
    substeps: int
    grid_t: np.ndarray  # drive-input grid [s]
    volts: np.ndarray  # (G, 2, n_tests_in_bucket): voltages [V], or sprocket speeds [rad/s] if kind is "speed"
    kind: str = "voltage"  # the tests' input mode (a bucket never mixes modes)

    def profile(self, repeat: int, dtype):
        """The bucket's drive profile, each test repeated ``repeat`` times on the vehicle axis."""
        values = jnp.asarray(np.repeat(self.volts, repeat, axis=-1), dtype)
        cls = SpeedProfile if self.kind == "speed" else VoltageProfile
        return cls(jnp.asarray(self.grid_t, dtype), values)


def _grid_dt(tests: list[TestData], substep: float) -> float:
    """Output step: ≤ 20 ms and ≤ the smallest log interval, a multiple of the substep (≥ 5 ms)."""
    min_int = min(float(np.min(np.diff(t.t))) for t in tests)
    target = max(min(0.02, min_int), 0.005)
    k = max(1, int(math.floor(target / substep + 1e-6)))
    return k * substep


def make_buckets(tests: list[TestData], substep: float = FIT_SUBSTEP, pad_s: float | None = None) -> list[Bucket]:
    """Buckets of tests; with ``pad_s`` [s] every test goes into one bucket padded to ``pad_s`` (at least the
    longest test), at a 20 ms output step and 10 ms voltage grid: fixed shapes, so that a series of
    diagnoses of equally many tests (a benchmark) reuses the compiled programs."""
    dt = _grid_dt(tests, substep) if pad_s is None else max(1, int(round(0.02 / substep))) * substep
    substeps = max(1, int(round(dt / substep)))
    order = sorted(range(len(tests)), key=lambda j: (tests[j].drive_kind, -tests[j].duration))
    groups: list[list[int]] = []
    for j in order:
        same_kind = bool(groups) and tests[groups[-1][0]].drive_kind == tests[j].drive_kind
        if pad_s is not None and same_kind:
            groups[-1].append(j)
        elif same_kind and tests[j].duration >= BUCKET_FILL * tests[groups[-1][0]].duration:
            groups[-1].append(j)
        else:
            groups.append([j])
    buckets = []
    for g in groups:
        g = sorted(g)
        t_end = max(tests[j].duration for j in g)
        if pad_s is not None:
            t_end = max(t_end, pad_s)
        n_steps = int(math.ceil(t_end / dt - 1e-9)) + 1
        hv = min(0.01, min(float(np.min(np.diff(tests[j].t))) for j in g)) if pad_s is None else 0.01
        grid = np.arange(int(math.ceil(n_steps * dt / hv)) + 2) * hv
        volts = np.stack([np.stack([np.interp(grid, tests[j].t, tests[j].drive_values[:, c]) for c in range(2)], 0)
                          for j in g], -1)  # (2, G, nb) -> transpose
        volts = np.transpose(volts, (1, 0, 2))
        buckets.append(Bucket(tuple(g), n_steps, dt, substeps, grid, volts, tests[g[0]].drive_kind))
    return buckets


def encoder_average(t: np.ndarray, x: np.ndarray, window: float) -> np.ndarray:
    """Causal moving average of ``x`` (T, S) over ``window`` [s] on the uniform grid ``t`` (held before t0).

    The encoder-averaging part of ``sensor_artifacts`` (its ``moving_average``), in numpy for the
    diagnosis's per-candidate encoder layer.
    """
    if window <= 0:
        return x
    dt = t[1] - t[0]
    F = np.concatenate([np.zeros_like(x[:1]), np.cumsum(0.5 * (x[1:] + x[:-1]) * dt, axis=0)])
    tau = t - window
    k = np.clip(np.floor(tau / dt).astype(int), 0, len(t) - 2)
    f = np.clip((tau - t[k]) / dt, 0.0, 1.0)[:, None]
    Fi = F[k] * (1 - f) + F[k + 1] * f
    Fi = np.where((tau < 0)[:, None], x[:1] * tau[:, None], Fi)
    return (F - Fi) / window


@jax.jit
def _instruments_jit(effect, channels, t, params):
    return effect.instruments(channels, t, params)


class BatchSimulator:
    """Simulates candidates' parameter sets on every test; returns predictions at the logs' sample times."""

    def __init__(self, tests: list[TestData], internal_resistance: str = "constant", substep: float = FIT_SUBSTEP,
                 pad_s: float | None = None, vehicle=None, named: tuple = ()):
        self.tests = tests
        self.named = tuple(named)  # fits an earlier diagnosis named (.candidates.NamedFit), part of the base model
        self.vehicle = vehicle  # a vehicle id or YAML path replacing each log's meta.json vehicle (None: the log's)
        self.substep = substep
        self.internal_resistance = internal_resistance
        self.buckets = make_buckets(tests, substep, pad_s)
        self.base = [load_params(t.terrain, vehicle=vehicle or t.vehicle, internal_resistance=internal_resistance)
                     for t in tests]
        # The reference constant torque [N m] that the internal_resistance candidate scales: the terrain's b*_int
        # (Table 5.4), or the drive's stiction torque for a vehicle that sets no internal resistance of its own.
        ref = [load_params(t.terrain, vehicle=vehicle or t.vehicle, internal_resistance="constant") for t in tests]
        self.b_int_constant = np.array([float(p.internal.constant) if float(p.internal.constant) > 0
                                        else float(p.vehicle.stiction_torque) for p in ref])
        self.n_vehicle_seconds = 0.0
        self._on_channels = {}  # (bucket, candidate, names, values) -> channels of a fitted base (channels_on)
        self._base_channels = {}  # bucket index -> raw base-model channels on the output grid (T, nb)
        # interpolation of the output grid at each log's times
        self._interp: dict[int, SampleWeights] = {}
        for b in self.buckets:
            for j in b.tests:
                self._interp[j] = grid_weights(self.tests[j].t, b.dt, b.n_steps)

    def run(self, cand: Candidate, values: dict, progress=None, windows: tuple = ()) -> tuple[list[dict], np.ndarray]:
        """Simulate ``values`` ({name: (S,)} physical parameter sets) on every test.

        Returns ``(pred, diverged)``: ``pred[j][signal]`` is (K_j, S) at test j's sample times;
        ``diverged`` (n_tests, S) bool. With ``windows`` (encoder averaging windows [s], see
        :func:`encoder_average`), each parameter set comes in ``len(windows)`` variants: column
        ``s * len(windows) + w`` is set ``s`` with ``speed_ideal`` averaged over ``windows[w]``.
        """
        pred, div = self._run(cand, values, progress)
        if not windows:
            return pred, div
        nw = len(windows)
        out = []
        for j, p in enumerate(pred):
            q = {k: np.repeat(v, nw, axis=1) for k, v in p.items()}
            if "speed_ideal" in p:
                sp = self._speed_grid[j]  # (T, S) on the output grid
                g = self._grid_of[j]
                for k, win in enumerate(windows):
                    q["speed_ideal"][:, k::nw] = at_samples(encoder_average(g, sp, win), self._interp[j])
            out.append(q)
        return out, np.repeat(div, nw, axis=1)

    def _run(self, cand: Candidate, values: dict, progress=None) -> tuple[list[dict], np.ndarray]:
        shapes = {k: np.shape(v) for k, v in values.items()}
        if len(set(shapes.values())) > 1 or any(len(s) != 1 for s in shapes.values()):
            raise ValueError(f"{cand.name}: parameter values must be (S,) arrays of one length S, got shapes {shapes}")
        S = len(next(iter(values.values()))) if values else 1
        self._speed_grid, self._grid_of = {}, {}
        pred: list[dict] = [None] * len(self.tests)
        diverged = np.zeros((len(self.tests), S), bool)
        for bi, b in enumerate(self.buckets):
            nb = len(b.tests)
            if cand.instrument_only:
                ch = self._instrument_only(bi, b, cand, values, S)
                for q, j in enumerate(b.tests):
                    pred[j] = self._at_log(j, {k: v[:, q * S:(q + 1) * S] for k, v in ch.items()})
                if progress:
                    progress(nb * S)
                continue
            params = self._params(b, cand, values, S)
            ch, div = self._simulate(b, params, nb * S, cand)
            if cand.name == "none" and S == 1:
                self._base_channels[bi] = (ch, div)
            for q, j in enumerate(b.tests):
                cols = slice(q * S, (q + 1) * S)
                pred[j] = self._at_log(j, {k: v[:, cols] for k, v in ch.items()})
                self._speed_grid[j] = ch["speed_ideal"][:, cols]
                self._grid_of[j] = np.arange(b.n_steps + 1) * b.dt
                diverged[j] = div[cols]
            if progress:
                progress(nb * S)
        return pred, diverged

    def stacked_base(self, b: Bucket, S: int):
        """The base model of bucket ``b``'s tests, each repeated ``S`` times (leaves (nb * S,), column ``q * S + s``),
        with the fits an earlier diagnosis named (``named``) added, and the per-vehicle references of
        :meth:`.candidates.Candidate.apply`."""
        base = stack_trees([self.base[j] for j in b.tests])  # leaves (nb,)
        base = jax.tree.map(lambda x: _repeat_vehicles(x, S) if eqx.is_inexact_array(x) else x, base)
        ref = {"b_int_constant": np.repeat(self.b_int_constant[list(b.tests)], S)}
        for nf in self.named:
            base = nf.apply(base, ref)
        return base, ref

    def _params(self, b: Bucket, cand: Candidate, values: dict, S: int):
        """Params of bucket ``b`` with ``S`` parameter sets of ``cand`` per test: leaves (nb * S,)."""
        nb = len(b.tests)
        base, ref = self.stacked_base(b, S)
        vals = {k: np.tile(np.asarray(v, np.float64), nb) for k, v in values.items()}
        return cand.apply(base, vals, ref)

    def _simulate(self, b: Bucket, params, n_vehicles: int, cand: Candidate | None = None) -> tuple[dict, np.ndarray]:
        """Simulate bucket ``b``'s tests (each repeated ``n_vehicles / nb`` times): raw channels (T, B), diverged (B,).
        ``cand``'s scaled leaves stay arrays (:attr:`.candidates.Candidate.varied_leaves`)."""
        prof = b.profile(n_vehicles // len(b.tests), params.dtype)
        keep = cand.varied_leaves if cand is not None else frozenset()
        traj = simulate_on_cores(params, prof, b.n_steps, b.dt, b.substeps, keep_arrays=keep)  # (n_vehicles,), both cores
        self.n_vehicle_seconds += n_vehicles * b.n_steps * b.dt
        return {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}, np.asarray(traj.diverged)

    def base_channels(self, bi: int, b: Bucket) -> dict:
        """The base model's raw channels of bucket ``bi`` (simulated once, then reused)."""
        if bi not in self._base_channels:
            self._base_channels[bi] = self._simulate(b, self.stacked_base(b, 1)[0], len(b.tests))
        return self._base_channels[bi][0]

    def channels_on(self, bi: int, b: Bucket, below: Candidate, values: dict) -> dict:
        """Raw channels (T, nb · S) of bucket ``bi`` under ``below`` with ``values`` {name: (S,)} (column
        ``q · S + s``: test q, set s). Each distinct parameter set is simulated once and cached (a fit that
        stands on ``below`` uses one set per fold)."""
        names = sorted(values)
        rows = np.stack([np.asarray(values[k], np.float64) for k in names], axis=1)  # (S, n)
        uniq, inv = np.unique(rows, axis=0, return_inverse=True)
        inv = np.ravel(inv)
        key = (bi, below.name, tuple(names), uniq.tobytes())
        if key not in self._on_channels:
            U = uniq.shape[0]
            params = self._params(b, below, {k: uniq[:, i] for i, k in enumerate(names)}, U)
            self._on_channels[key] = (self._simulate(b, params, len(b.tests) * U, below)[0], U)
        ch, U = self._on_channels[key]
        cols = np.concatenate([q * U + inv for q in range(len(b.tests))])
        return {k: v[:, cols] for k, v in ch.items()}

    def channels_below(self, bi: int, b: Bucket, cand: Candidate, below: dict, S: int) -> dict:
        """Raw channels (T, nb · S) that the instruments-only ``cand`` transforms: those of the candidate it stands
        on at ``below`` {name: (S,)} (:meth:`channels_on`), or the base model's repeated ``S`` times."""
        if cand.on is not None:
            return self.channels_on(bi, b, cand.on, below)
        return {k: np.repeat(v, S, axis=-1) for k, v in self.base_channels(bi, b).items()}

    def _instrument_only(self, bi: int, b: Bucket, cand: Candidate, values: dict, S: int) -> dict:
        """An effect that only transforms instruments: apply it to the base trajectory (to the trajectory of
        the candidate it stands on, :meth:`channels_on`), no new simulation."""
        own, below = cand.split_values(values)
        ch = self.channels_below(bi, b, cand, below, S)
        params = self._params(b, dataclasses.replace(cand, on=None), own, S)
        t = jnp.arange(b.n_steps + 1, dtype=params.dtype) * b.dt
        for eff in params.effects[-1:]:  # its own: the base's (a named fit's window) are in ``ch`` already
            ch = _instruments_jit(eff, {k: jnp.asarray(v, params.dtype) for k, v in ch.items()}, t, params)
        return {k: np.asarray(v, np.float64) for k, v in ch.items()}

    def _at_log(self, j: int, ch: dict) -> dict:
        return predictions_at_log(self.tests[j], ch, self._interp[j])


def _repeat_vehicles(x, S: int):
    """Each vehicle of leaf ``x`` repeated ``S`` times on the last axis, in numpy where
    :func:`trackenv.parallel.host_movable` allows (a jax array either way)."""
    if not host_movable(x):
        return jnp.repeat(x, S, axis=-1)
    return jnp.asarray(np.repeat(np.asarray(x), S, axis=-1))


def predictions_at_log(test: TestData, ch: dict, weights: SampleWeights) -> dict:
    """Simulated channels ``ch`` {name: (T, S)} on a bucket's grid -> {signal: (K, S)} for ``test``'s measured
    signals, as its instruments report them (:mod:`trackenv.compare`): at its sample times, rectified for an
    absolute ammeter, the pose in its frame. Numpy or jax arrays (traceable)."""
    out = {}
    for sig in test.measured:
        if sig not in POSE:
            out[sig] = rectify(sig, at_samples(ch[sig], weights), test.sensor)
    if any(s in test.measured for s in POSE):
        pose = dict(zip(POSE, pose_to_log_frame(*(at_samples(ch[k], weights) for k in POSE), test.pose0)))
        out.update({k: v for k, v in pose.items() if k in test.measured})
    return out
