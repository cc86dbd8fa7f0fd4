"""Field tests for a diagnosis: read a folder of docs/model.md §9 logs, check them, estimate their noise.

A diagnosis folder holds one sub-folder per field test (``log.csv`` + ``meta.json``); a folder that
is itself a field log is a diagnosis of that one test. Every sub-folder is read with
:func:`trackenv.fieldlog.read_field_log`; one that is invalid (missing voltages, a bad row, NaN
voltages...) or too short to say anything (under ``MIN_DURATION`` s or ``MIN_SAMPLES`` samples) is
*excluded* with its reason, which the report states; if nothing usable is left the diagnosis stops
with a :class:`DiagnosisError` listing the reasons. Inside a test, a measured channel with fewer
than half of its samples present is excluded from that test (stated too); isolated empty cells and
NaN runs are simply not compared.

Fits and verdicts use every sample except those of a coast phase beyond its first second
(:func:`fit_mask`); cells and figures show all samples.

Noise: each channel's white-noise level is estimated from the log itself, σ = 1.4826 · MAD(Δx)/√2
(the median absolute deviation of consecutive differences: robust to the signal's own steps and
ramps, which are few), so that a gap can be judged against what the instruments alone would give.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..compare import INPUT_CHANNELS, log_drive, unwrap_measured
from ..fieldlog import MEASURED_COLUMNS, OPTIONAL_COLUMNS, FieldLog, FieldLogError, read_field_log
from .phases import segment_phases

MIN_DURATION = 1.0  # s
MIN_SAMPLES = 10
MIN_PRESENT = 0.5  # fraction of a channel's samples that must be present
COAST_KEEP = 1.0  # s of each coast phase that enter fits and verdicts
SIGNALS = MEASURED_COLUMNS + OPTIONAL_COLUMNS  # i_left, i_right, speed_ideal, yaw_rate, x, y, heading


class DiagnosisError(ValueError):
    """The diagnosis cannot run (no usable test, bad option); the message says why and where."""


@dataclass(eq=False)
class TestData:
    """One field test, time shifted to start at 0 (``t_offset`` = the log's first time [s])."""

    name: str
    folder: Path
    log: FieldLog
    t: np.ndarray  # (K,) s
    volts: np.ndarray  # (K, 2) V; in speed mode the back-emf equivalent alpha_v omega (phases, figures)
    measured: dict  # signal -> (K,) with NaN where missing
    phase: np.ndarray  # (K,) phase labels
    noise: dict  # signal -> σ (same unit as the signal)
    span: dict  # signal -> robust range (1st-99th percentile spread), the NRMSE denominator
    t_offset: float
    pose0: tuple
    notes: list = field(default_factory=list)
    fit_mask: np.ndarray | None = None  # (K,) samples that enter fits and verdicts (see COAST_KEEP)
    drive_kind: str = "voltage"  # "voltage" or "speed" (the log's input mode)
    drive: np.ndarray | None = None  # (K, 2) the drive input: V, or prescribed sprocket speeds [rad/s]

    @property
    def terrain(self) -> str:
        return self.log.terrain

    @property
    def vehicle(self) -> str:
        return self.log.vehicle

    @property
    def sensor(self) -> str:
        return self.log.current_sensor

    @property
    def drive_values(self) -> np.ndarray:
        """The drive input (K, 2): voltages [V] in voltage mode, sprocket speeds [rad/s] in speed mode."""
        return self.volts if self.drive is None else self.drive

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    @property
    def signals(self) -> list[str]:
        return list(self.measured)


def noise_level(x: np.ndarray) -> float:
    """Robust white-noise σ of a sampled signal from its consecutive differences (NaN-aware)."""
    d = np.diff(x)
    d = d[np.isfinite(d)]
    if d.size < 3:
        return float("nan")
    mad = np.median(np.abs(d - np.median(d)))
    return float(1.4826 * mad / math.sqrt(2.0))


def robust_span(x: np.ndarray) -> float:
    v = x[np.isfinite(x)]
    if v.size == 0:
        return float("nan")
    lo, hi = np.percentile(v, [1.0, 99.0])
    return float(hi - lo)


def prepare_test(log: FieldLog, name: str) -> TestData:
    """Check one read log and derive what the diagnosis needs (raises :class:`DiagnosisError` if unusable)."""
    t_raw = log.t
    if len(t_raw) < MIN_SAMPLES:
        raise DiagnosisError(f"{log.folder / 'log.csv'}: only {len(t_raw)} samples (at least {MIN_SAMPLES} needed)")
    t = t_raw - t_raw[0]
    if t[-1] < MIN_DURATION:
        raise DiagnosisError(f"{log.folder / 'log.csv'}: lasts {t[-1]:.3g} s (at least {MIN_DURATION:g} s needed)")
    kind, drive, volts = _drive(log)
    if not np.all(np.isfinite(volts)):  # read_field_log rejects these already; belt and braces
        k = int(np.argwhere(~np.isfinite(volts))[0][0])
        raise DiagnosisError(f"{log.folder / 'log.csv'}: voltage missing at data row {k + 1}")
    notes, measured, noise, span = [], {}, {}, {}
    for sig, x in log.measured().items():
        if sig in INPUT_CHANNELS[kind]:
            notes.append(f"{sig} not compared: it is the drive input (speed mode: {log.input_mode_reason})")
            continue
        present = np.isfinite(x)
        if present.mean() < MIN_PRESENT:
            notes.append(f"{sig} excluded: only {100 * present.mean():.0f}% of its samples are present")
            continue
        if sig == "heading":
            x = unwrap_measured(x)
        s = robust_span(x)
        if not (s > 0):
            notes.append(f"{sig} excluded: constant (nothing to compare)")
            continue
        runs = _longest_nan_run(present)
        if runs > 0.1 * len(x):
            notes.append(f"{sig}: a run of {runs} missing samples is not compared")
        measured[sig] = x
        sig_noise = noise_level(x)
        noise[sig] = max(sig_noise if np.isfinite(sig_noise) else 0.0, 1e-3 * s)
        span[sig] = s
    if not measured:
        raise DiagnosisError(f"{log.folder / 'log.csv'}: no measured channel has enough samples to compare")
    missing = [c for c in MEASURED_COLUMNS if c not in measured]
    if missing:
        notes.append(f"not compared (absent or excluded): {', '.join(missing)}")
    phase = segment_phases(t, volts)
    return TestData(name=name, folder=log.folder, log=log, t=t, volts=volts, measured=measured,
                    phase=phase, noise=noise, span=span, t_offset=float(t_raw[0]),
                    pose0=log.first_pose(), notes=notes, fit_mask=fit_mask(t, phase), drive_kind=kind,
                    drive=drive)


def _drive(log: FieldLog) -> tuple[str, np.ndarray, np.ndarray]:
    """(kind, drive input, voltage-like series for the phases): in speed mode the phases are cut on the
    back-emf voltage alpha_v omega, which has the voltage's scale and zero where the drive is at rest."""
    if log.input_mode == "voltage":
        return "voltage", log.volts, log.volts
    from ..params import load_params  # noqa: PLC0415

    params = load_params(log.terrain, vehicle=log.vehicle)
    kind, omega = log_drive(log, params)
    return kind, omega, omega * float(params.vehicle.alpha_v)


def fit_mask(t: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Samples used by fits and verdicts: all but coast beyond its first ``COAST_KEEP`` s.

    Why: once the unpowered vehicle has stopped, the model's (and a real vehicle's) rest on the
    ground is a stick-slip balance whose outcome hangs on tiny differences (1e-6 V of input can
    decide whether the model creeps; see the README's model notes), so those samples say nothing
    about the effects and would only add chance. They are still shown in the cells and figures.
    """
    keep = np.ones(len(t), bool)
    start = None
    for k, ph in enumerate(phase):
        if ph == "coast":
            start = t[k] if start is None else start
            keep[k] = (t[k] - start) <= COAST_KEEP
        else:
            start = None
    return keep


def _longest_nan_run(present: np.ndarray) -> int:
    best = cur = 0
    for p in present:
        cur = 0 if p else cur + 1
        best = max(best, cur)
    return best


def load_tests(folder: str | Path, only: list[str] | None = None) -> tuple[list[TestData], list[dict]]:
    """Read every test of a diagnosis folder: ``(tests, excluded)``; ``excluded`` = [{test, reason}].

    ``only``: keep just these sub-folder names (an unknown name is an error).
    """
    folder = Path(folder)
    if not folder.exists():
        raise DiagnosisError(f"{folder}: no such folder (expected one sub-folder per field test)")
    if not folder.is_dir():
        raise DiagnosisError(f"{folder}: not a folder (expected one sub-folder per field test)")
    if (folder / "log.csv").exists():
        subs = [folder]
    else:
        subs = sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
    if only:
        names = {p.name for p in subs}
        unknown = [n for n in only if n not in names]
        if unknown:
            raise DiagnosisError(f"{folder}: no test folder named {', '.join(unknown)} (have: {', '.join(sorted(names))})")
        subs = [p for p in subs if p.name in only]
    tests, excluded = [], []
    for sub in subs:
        if not (sub / "log.csv").exists() and not (sub / "meta.json").exists():
            continue  # not a test folder (e.g. a figures folder)
        try:
            tests.append(prepare_test(read_field_log(sub), sub.name))
        except (FieldLogError, DiagnosisError) as exc:
            excluded.append({"test": sub.name, "reason": str(exc)})
    if not tests:
        why = "; ".join(f"{e['test']}: {e['reason']}" for e in excluded) or "no sub-folder with log.csv + meta.json"
        raise DiagnosisError(f"{folder}: no usable field test ({why})")
    return tests, excluded
