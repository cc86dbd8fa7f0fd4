"""The BorealTC dataset (a Clearpath Husky A200 on boreal terrains) as speed-mode field logs.

    from trackenv.importers import import_borealtc
    import_borealtc("data/measured/borealtc", "out/borealtc", runs=["ASPHALT/03", "SANDY_LOAM/02"])

**Input.** A dataset folder with one sub-folder per terrain class (``ASPHALT``, ``SANDY_LOAM``, ...),
each holding a pair of files per run ``XX``: ``pro_XX.csv`` (the wheel service, ~6.5 Hz: ``time`` [s],
``curL``, ``curR`` [A, motor current magnitudes], ``velL``, ``velR`` [m/s, wheel surface speeds]) and
``imu_XX.csv`` (100 Hz: ``time`` [s], ``wx``, ``wy``, ``wz`` [rad/s], ``ax``, ``ay``, ``az``).

**Output.** One folder ``<out>/<CLASS>_<XX>/`` per run with a §9.1 ``log.csv`` in *speed mode* on the
wheel service's time base: ``t`` (``time``), ``track_speed_left``/``track_speed_right`` (``velL``/``velR``,
the input), ``i_left``/``i_right`` (``curL``/``curR``), ``yaw_rate`` and an empty ``speed_ideal``.
Numbers are copied exactly (shortest round-trip text). No voltages were logged: the robot ran its own
closed-loop wheel-speed control.

- ``yaw_rate`` is the IMU's ``wz`` (positive = turning left, as in docs/model.md; the sign agrees with
  ``velR - velL``) on the wheel-service time base through an anti-aliasing **box filter**: the mean of
  the 100 Hz samples with ``t_k - T/2 <= time < t_k + T/2`` around each wheel-service time ``t_k``, T
  the run's median wheel-service period (0.1538 s). A window holding fewer than half its nominal
  T/dt_imu samples (where the IMU record has ended) is an empty cell.
- ``speed_ideal`` is in the header with empty cells: in a speed-mode log it would be the mean of the two
  input speeds, not a separate measurement (docs/model.md §9.1).
- **Time bases.** Both files of every run start at ``time`` = 0 (seconds from the run's start) and are
  used as they are (no offset applied); their ends differ by up to ~1.3 s, so the last yaw-rate cells can
  be empty. The importer estimates the lag between ``wz`` and ``velR - velL`` by cross-correlation
  (within ±2 s) and records it in ``meta.json`` (``time_bases``) without applying it: the estimate is
  poor on runs where the speed difference hardly varies.

``meta.json``: ``vehicle`` ``husky``; ``terrain`` from :data:`BOREALTC_TERRAINS` (ASPHALT -> ``asphalt``,
SANDY_LOAM -> ``sandy_loam_1``; the soils' parameters were not measured, so the configs/terrain ids are
stand-ins, Table 5.5's sandy loam 1 for the sandy loam); ``maneuver`` from :func:`classify_maneuver`;
``current_sensor`` ``absolute`` (the currents are magnitudes); ``measured`` true, ``synthetic`` false,
``data`` ``MEASURED``; ``source`` (dataset, paper, licence MIT, run, files); ``sensors`` with each
channel's sample rate measured from the time stamps and the quantisation measured from the values:
the wheel speeds' smallest nonzero step between two logged values over all runs of the import (a run
at one constant speed shows none), the currents' mean step of their value ladder and the decimal
``resolution`` of the file; ``time_bases``; ``notes``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["BOREALTC_TERRAINS", "DatasetError", "classify_maneuver", "import_borealtc", "box_average"]

# terrain class of the dataset -> terrain id of configs/terrain (stand-ins: the soils were not characterised)
BOREALTC_TERRAINS = {"ASPHALT": "asphalt", "SANDY_LOAM": "sandy_loam_1"}
PRO_COLUMNS = ("time", "curL", "curR", "velL", "velR")
IMU_COLUMNS = ("time", "wz")  # the others (wx, wy, ax, ay, az) are not used
SOURCE = {
    "dataset": "BorealTC",
    "repository": "norlab-ulaval/BorealTC (folder data/borealtc)",
    "paper": "D. LaRocque et al., Proprioception Is All You Need: Terrain Classification for Boreal Forests, "
             "IROS 2024, arXiv 2403.16877",
    "licence": "MIT",
}

# classify_maneuver: a sample is "moving" when a side turns faster than MOVING_SPEED; the run is named
# after the kind of at least MANEUVER_SHARE of its moving samples, else "mixed".
MOVING_SPEED = 0.03  # m/s (about 4 speed quanta)
STRAIGHT_TOL = 0.02  # m/s: |velR - velL| / 2 at most this, or 10% of the mean side speed
MANEUVER_SHARE = 0.8
LAG_WINDOW_S = 2.0


class DatasetError(ValueError):
    """A dataset file is missing or invalid; the message names the file (and the column)."""


@dataclass
class _Run:
    cls: str
    xx: str
    pro: Path
    imu: Path

    @property
    def name(self) -> str:
        return f"{self.cls}_{self.xx}"

    @property
    def run_id(self) -> str:
        return f"{self.cls}/{self.xx}"


# ----------------------------------------------------------------------------------------------
# reading


def _read_table(path: Path, columns: tuple[str, ...]) -> pd.DataFrame:
    if not path.is_file():
        raise DatasetError(f"{path}: missing file (each run needs a pro_XX.csv and an imu_XX.csv)")
    try:
        df = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: not a readable CSV file ({str(exc).splitlines()[0]})") from None
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise DatasetError(f"{path}: missing column(s) {', '.join(repr(c) for c in missing)} "
                           f"(expected {','.join(columns)}; found {','.join(map(str, df.columns))})")
    if len(df) < 2:
        raise DatasetError(f"{path}: {len(df)} data row(s); at least 2 are needed")
    out = {}
    for c in columns:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(np.float64)
        bad = ~np.isfinite(v)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise DatasetError(f"{path}: column '{c}', line {k + 2} (data row {k + 1}): {df[c].iloc[k]!r} is not a "
                               "finite number")
        out[c] = v
    dt = np.diff(out["time"])
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0]) + 1
        raise DatasetError(f"{path}: column 'time', line {k + 2} (data row {k + 1}): time {out['time'][k]:.15g} s is "
                           f"not greater than the previous {out['time'][k - 1]:.15g} s")
    return pd.DataFrame(out)


def _find_runs(folder: Path, runs) -> list[_Run]:
    if not folder.exists():
        raise DatasetError(f"{folder}: no such dataset folder (expected one sub-folder per terrain class, e.g. "
                           "ASPHALT/, with pro_XX.csv and imu_XX.csv files)")
    if not folder.is_dir():
        raise DatasetError(f"{folder}: not a folder (expected the BorealTC data folder with ASPHALT/, ...)")
    if runs is None:
        found = []
        for cls_dir in sorted(p for p in folder.iterdir() if p.is_dir()):
            for pro in sorted(cls_dir.glob("pro_*.csv")):
                xx = pro.stem[len("pro_"):]
                found.append(_Run(cls_dir.name, xx, pro, cls_dir / f"imu_{xx}.csv"))
        if not found:
            raise DatasetError(f"{folder}: no runs found (no <CLASS>/pro_XX.csv files)")
        return found
    if isinstance(runs, str):
        runs = [r for r in runs.split(",") if r.strip()]
    out = []
    for r in runs:
        m = re.fullmatch(r"\s*([^/\\\s]+)[/\\](\w+)\s*", str(r))
        if not m:
            raise DatasetError(f"run {r!r}: expected CLASS/XX, e.g. ASPHALT/00")
        cls, xx = m.groups()
        pro = folder / cls / f"pro_{xx}.csv"
        if not pro.is_file():
            raise DatasetError(f"{pro}: missing file (run {cls}/{xx} is not in the dataset folder)")
        out.append(_Run(cls, xx, pro, folder / cls / f"imu_{xx}.csv"))
    if not out:
        raise DatasetError("no runs given")
    return out


# ----------------------------------------------------------------------------------------------
# conversion


def box_average(t: np.ndarray, t_src: np.ndarray, x_src: np.ndarray, width: float,
                min_fraction: float = 0.5) -> np.ndarray:
    """Mean of ``x_src`` over ``t_k - width/2 <= t_src < t_k + width/2`` for each ``t_k`` in ``t``.

    A window with fewer than ``min_fraction`` of its nominal ``width / median(diff(t_src))`` samples
    gives NaN. An anti-aliasing box filter for putting a fast channel on a slow time base.
    """
    t, t_src, x_src = (np.asarray(a, np.float64) for a in (t, t_src, x_src))
    lo = np.searchsorted(t_src, t - width / 2, side="left")
    hi = np.searchsorted(t_src, t + width / 2, side="left")
    csum = np.concatenate([[0.0], np.cumsum(x_src)])
    n = hi - lo
    nominal = width / float(np.median(np.diff(t_src)))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (csum[hi] - csum[lo]) / n
    return np.where(n >= min_fraction * nominal, mean, np.nan)


def classify_maneuver(v_left, v_right) -> tuple[str, dict]:
    """Name a run from its side speeds [m/s]: ``straight``, ``zero_radius_turn``, ``turn``, ``mixed``.

    Samples where a side moves faster than :data:`MOVING_SPEED` count. Each is *straight* when
    ``|vR - vL| / 2 <= max(STRAIGHT_TOL, 0.1 (|vL| + |vR|) / 2)``, a *zero-radius turn* when the sides
    run in opposite directions with ``|vL + vR| / 2 <= 0.25 (|vL| + |vR|) / 2``, else a *turn*. The run
    takes the name of the kind that holds at least :data:`MANEUVER_SHARE` (80%) of its moving samples;
    otherwise it is ``mixed`` (``standstill`` when nothing moves). Returns the name and the shares.
    """
    vl, vr = np.asarray(v_left, np.float64), np.asarray(v_right, np.float64)
    moving = np.maximum(np.abs(vl), np.abs(vr)) > MOVING_SPEED
    n = int(moving.sum())
    if n == 0:
        return "standstill", {"moving": 0.0}
    mean_side = (np.abs(vl) + np.abs(vr)) / 2
    straight = moving & (np.abs(vr - vl) / 2 <= np.maximum(STRAIGHT_TOL, 0.1 * mean_side))
    zrt = moving & ~straight & (vl * vr < 0) & (np.abs(vl + vr) / 2 <= 0.25 * mean_side)
    turn = moving & ~straight & ~zrt
    shares = {"straight": straight.sum() / n, "zero_radius_turn": zrt.sum() / n, "turn": turn.sum() / n}
    shares = {k: round(float(v), 4) for k, v in shares.items()}
    best = max(shares, key=shares.get)
    name = best if shares[best] >= MANEUVER_SHARE else "mixed"
    return name, {"moving": round(n / len(vl), 4), **shares}


def _smallest_step(values: np.ndarray) -> float | None:
    u = np.unique(np.asarray(values, np.float64))
    d = np.diff(u)
    d = d[d > 1e-9]
    return float(d.min()) if d.size else None


def _ladder_step(values: np.ndarray) -> float | None:
    """Mean spacing of neighbouring distinct values whose gap is within 1.5x the smallest one."""
    u = np.unique(np.asarray(values, np.float64))
    d = np.diff(u)
    d = d[d > 1e-9]
    if not d.size:
        return None
    return float(np.mean(d[d <= 1.5 * d.min()]))


def _decimal_resolution(values: np.ndarray) -> float | None:
    v = np.asarray(values, np.float64)
    for digits in range(7):
        scaled = v * 10.0 ** digits
        if np.all(np.abs(scaled - np.round(scaled)) < 1e-6):
            return 10.0 ** -digits
    return None


def _rate(t: np.ndarray) -> float:
    return float(f"{1.0 / float(np.median(np.diff(t))):.6g}")


def _lag_estimate(t: np.ndarray, dv: np.ndarray, t_imu: np.ndarray, wz: np.ndarray) -> tuple[float | None, float | None]:
    """The shift s [s] maximising corr(wz(t + s), velR - velL), within ±LAG_WINDOW_S; None if dv is constant."""
    if np.std(dv) < 1e-6:
        return None, None
    best = (-np.inf, 0.0)
    for s in np.arange(-LAG_WINDOW_S, LAG_WINDOW_S + 1e-9, 0.01):
        w = np.interp(t + s, t_imu, wz, left=np.nan, right=np.nan)
        ok = np.isfinite(w)
        if ok.sum() < 10 or np.std(w[ok]) == 0 or np.std(dv[ok]) == 0:
            continue
        r = float(np.corrcoef(w[ok], dv[ok])[0, 1])
        if r > best[0]:
            best = (r, float(s))
    if not np.isfinite(best[0]):
        return None, None
    return round(best[1], 2), round(best[0], 3)


def _convert(run: _Run, pro: pd.DataFrame, imu: pd.DataFrame, terrain: str, quanta: dict) -> tuple[dict, dict]:
    t = pro["time"].to_numpy()
    t_imu, wz = imu["time"].to_numpy(), imu["wz"].to_numpy()
    period = float(np.median(np.diff(t)))
    yaw = box_average(t, t_imu, wz, period)
    vl, vr = pro["velL"].to_numpy(), pro["velR"].to_numpy()
    maneuver, shares = classify_maneuver(vl, vr)
    lag, r = _lag_estimate(t, vr - vl, t_imu, wz)
    cols = {"t": t, "track_speed_left": vl, "track_speed_right": vr, "i_left": pro["curL"].to_numpy(),
            "i_right": pro["curR"].to_numpy(), "speed_ideal": np.full(t.shape, np.nan), "yaw_rate": yaw}
    rate, rate_imu = _rate(t), _rate(t_imu)
    speed = {"rate_hz": rate, "unit": "m/s"}
    if quanta["speed"] is not None:
        speed["quantisation"] = quanta["speed"]
    current = {"rate_hz": rate, "unit": "A", "note": "magnitudes (always >= 0); quantisation: the mean step of the "
               "logged value ladder; resolution: the decimals in the file"}
    for key in ("current", "current_resolution"):
        if quanta[key] is not None:
            current["quantisation" if key == "current" else "resolution"] = quanta[key]
    sensors = {
        "track_speed_left": {**speed, "file_column": "velL"},
        "track_speed_right": {**speed, "file_column": "velR"},
        "i_left": {**current, "file_column": "curL"},
        "i_right": {**current, "file_column": "curR"},
        "yaw_rate": {"rate_hz": rate_imu, "unit": "rad/s", "file_column": "wz", "written_rate_hz": rate,
                     "filter": f"box average of the IMU samples within ±{period / 2:.4g} s (half a wheel-service "
                               "period) of each wheel-service sample; empty where under half a window is covered"},
    }
    n_empty = int(np.isnan(yaw).sum())
    time_bases = {
        "wheel_service": [float(t[0]), float(t[-1])],
        "imu": [float(t_imu[0]), float(t_imu[-1])],
        "start_difference_s": float(t_imu[0] - t[0]),
        "offset_applied_s": 0.0,
        "lag_estimate_s": lag,
        "lag_estimate_r": r,
        "yaw_rate_empty_cells": n_empty,
        "note": "both files count seconds from the run's start and are used as they are; lag_estimate_s is the "
                "shift s maximising corr(wz(t + s), velR - velL), recorded but not applied",
    }
    soil = ("the soil's parameters were not measured: Table 5.5's sandy loam 1 (configs/terrain/sandy_loam_1.yaml) "
            "is a stand-in" if run.cls == "SANDY_LOAM" else
            f"the surface's parameters were not measured: configs/terrain/{terrain}.yaml is a stand-in")
    notes = (f"MEASURED data: BorealTC run {run.run_id} (Clearpath Husky A200, terrain class {run.cls}), converted "
             f"by trackenv.importers.borealtc without simulation. The input is the wheel surface speeds (no "
             f"voltages were logged: the robot ran its own closed-loop wheel-speed control). Terrain '{terrain}': "
             f"{soil}. yaw_rate: the IMU's wz box-averaged onto the wheel-service time base; speed_ideal left empty "
             f"(it would be the mean of the input speeds). Maneuver '{maneuver}' classified from the side speeds "
             f"(trackenv.importers.borealtc.classify_maneuver).")
    meta = {
        "terrain": terrain,
        "maneuver": maneuver,
        "current_sensor": "absolute",
        "vehicle": "husky",
        "measured": True,
        "synthetic": False,
        "data": "MEASURED",
        "source": {**SOURCE, "run": run.run_id, "files": [f"{run.cls}/{run.pro.name}", f"{run.cls}/{run.imu.name}"]},
        "imported_by": "trackenv.importers.borealtc",
        "terrain_class": run.cls,
        "maneuver_shares": shares,
        "sensors": sensors,
        "time_bases": time_bases,
        "notes": notes,
    }
    return cols, meta


def import_borealtc(folder: str | Path, out: str | Path, terrain_map: dict | None = None, runs=None,
                    force: bool = False, progress: bool = False, report=None) -> list[Path]:
    """Convert BorealTC runs (``<folder>/<CLASS>/pro_XX.csv`` + ``imu_XX.csv``) into §9.1 field-log folders.

    Args:
        folder: the dataset folder (one sub-folder per terrain class).
        out: the output folder; each run becomes ``<out>/<CLASS>_<XX>/`` (log.csv + meta.json).
        terrain_map: terrain class -> terrain id of configs/terrain, added to (and overriding)
            :data:`BOREALTC_TERRAINS`.
        runs: ``["ASPHALT/00", ...]`` (or one comma-separated string); default every run found.
        force: overwrite existing field logs in ``out``.
        progress: show a tqdm progress bar (on a terminal) while converting.
        report: called with one line of text per run (time bases, lag estimate), e.g. ``print``.

    Returns the written folders. Raises :class:`DatasetError` naming the file for a missing or invalid
    input, :class:`~trackenv.outputs.OutputFolderError` for an existing field log without ``force``, and
    :class:`~trackenv.fieldlog.FieldLogError` for an unknown terrain id. Nothing is written unless every
    run converts.
    """
    from tqdm import tqdm

    from ..fieldlog import FieldLogError, write_log_columns
    from ..outputs import OutputFolderError, prepare_output_dir
    from ..params import list_terrains

    folder, out = Path(folder), Path(out)
    terrains = {**BOREALTC_TERRAINS, **(terrain_map or {})}
    todo = _find_runs(folder, runs)
    known = list_terrains()
    for run in todo:
        if run.cls not in terrains:
            raise DatasetError(f"{run.pro}: terrain class '{run.cls}' has no terrain id; pass terrain_map="
                               f"{{'{run.cls}': '<id of configs/terrain>'}} (known ids: {', '.join(known)})")
        if terrains[run.cls] not in known:
            raise FieldLogError(f"terrain_map: '{run.cls}' -> {terrains[run.cls]!r} is not a known terrain id "
                                f"(known: {', '.join(known)})")
    if len({r.name for r in todo}) != len(todo):
        raise DatasetError("runs: a run is listed twice")
    if not force and out.is_dir():
        for run in todo:
            for f in ("log.csv", "meta.json"):
                if (out / run.name / f).exists():
                    raise OutputFolderError(f"{out / run.name / f}: a field log is already there; refusing to "
                                            "overwrite it (pass --force, force=True, to replace it)")
    tables = []
    for run in todo:
        tables.append((run, _read_table(run.pro, PRO_COLUMNS), _read_table(run.imu, IMU_COLUMNS)))
    speeds = np.concatenate([np.concatenate([p["velL"], p["velR"]]) for _, p, _ in tables])
    currents = np.concatenate([np.concatenate([p["curL"], p["curR"]]) for _, p, _ in tables])
    step = _smallest_step(speeds)
    quanta = {"speed": None if step is None else float(f"{step:.10g}"),
              "current": None if _ladder_step(currents) is None else float(f"{_ladder_step(currents):.3g}"),
              "current_resolution": _decimal_resolution(currents)}
    converted = []
    bar = tqdm(tables, desc="import borealtc", unit="run", disable=None if progress and len(tables) > 1 else True)
    for run, pro, imu in bar:
        bar.set_postfix_str(run.run_id)
        converted.append((run, *_convert(run, pro, imu, terrains[run.cls], quanta)))
    bar.close()
    prepare_output_dir(out, "import borealtc", force=force, inputs=(folder,))
    written = []
    for run, cols, meta in converted:
        write_log_columns(out / run.name, cols, meta, digits=None)
        written.append(out / run.name)
        if report is not None:
            tb = meta["time_bases"]
            lag = ("no lag estimate (the speed difference is constant)" if tb["lag_estimate_s"] is None else
                   f"lag estimate {tb['lag_estimate_s']:+.2f} s (r = {tb['lag_estimate_r']:.2f}), not applied")
            report(f"{run.name}: {len(cols['t'])} samples, {meta['maneuver']}, {meta['terrain']}; wheel service "
                   f"{tb['wheel_service'][0]:g}..{tb['wheel_service'][1]:.2f} s, IMU {tb['imu'][0]:g}.."
                   f"{tb['imu'][1]:.2f} s; {lag}; {tb['yaw_rate_empty_cells']} empty yaw-rate cells")
    return written
