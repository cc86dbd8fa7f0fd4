"""Field logs: read, validate and write the docs/model.md §9 format (a folder with ``log.csv`` + ``meta.json``).

    from trackenv.fieldlog import read_field_log, write_field_log
    log = read_field_log("logs/zrt_sand_03")      # FieldLog; raises FieldLogError on bad input
    log.t, log.volts, log.measured()              # (K,), (K, 2), {"i_left": (K,), ...} with NaN gaps
    log.input_mode, log.speed_input               # "voltage", None | "speed", ("track_speed", (K, 2))
    write_field_log("out/sim", traj, {"terrain": "dry_sand", "maneuver": "go_stop"})

``log.csv``: a header row, then one row per sample (any rate, regular or not). Columns (SI):

===================== ======== ===================================================================
column                unit     rule
===================== ======== ===================================================================
``t``                 s        required; every row; strictly increasing (no duplicates); need not start at 0
``v_left``            V        the voltage input pair (with ``v_right``); every row (the replay input);
                               \\|V\\| <= the vehicle's bus limit (24 V)
``v_right``           V        as ``v_left``
``omega_left``        rad/s    a speed input pair (with ``omega_right``): sprocket/wheel speed; every row
``omega_right``       rad/s    as ``omega_left``
``track_speed_left``  m/s      a speed input pair (with ``track_speed_right``): track or wheel surface
                               speed; every row
``track_speed_right`` m/s      as ``track_speed_left``
``i_left``            A        required in the header; empty cells are missing samples; >= 0 if the
                               ammeter is ``absolute``
``i_right``           A        as ``i_left``
``speed_ideal``       m/s      required in the header of a voltage log, optional in a speed log; empty
                               cells allowed (encoder r_s (ω_l+ω_r)/2)
``yaw_rate``          rad/s    required in the header; empty cells allowed (gyro)
``x``, ``y``          m        optional; empty cells allowed
``heading``           rad      optional; empty cells allowed
===================== ======== ===================================================================

**Input mode.** A log gives exactly one input pair: the voltages ``v_left``/``v_right`` (*voltage
mode*, :attr:`FieldLog.input_mode` ``"voltage"``, the input of :func:`trackenv.replay.replay`) or,
when no voltage column is in the header, one speed pair, ``omega_left``/``omega_right`` or
``track_speed_left``/``track_speed_right`` (*speed mode*, ``"speed"``: a vehicle under its own
closed-loop wheel-speed control, whose voltages were not logged; :attr:`FieldLog.speed_input`). A
header with ``v_left`` but not ``v_right`` (or the reverse) is an error; so is, in a log without
voltage columns, half a speed pair, or both speed pairs (which one would be the input is ambiguous). The input pair must be filled on every
row with finite numbers. In speed mode ``speed_ideal`` may be absent from the header: it is the
mean of the input speeds (r_s (ω_l+ω_r)/2), not an independent measurement. A voltage log may
carry speed columns too: it stays in voltage mode and they are measurements (numbers, empty cells
allowed), read with :meth:`FieldLog.speeds`. :attr:`FieldLog.volts` raises :class:`FieldLogError`
on a speed-mode log (there are no voltages to replay).

A measurement column may be entirely empty (a channel that was not logged), but it must be in the
header, so that a missing channel is a decision and never a typo. Empty cells, ``nan``, ``NA`` and
``null`` all mean "missing". Other columns are allowed, kept in :attr:`FieldLog.data` as text and
otherwise ignored. Blank lines are skipped. At least 2 samples.

``meta.json``: a JSON object with ``terrain`` (required; an id of ``configs/terrain``),
``maneuver`` (required; ``go_stop`` | ``j_turn`` | ``lane_change`` | ``zero_radius_turn`` or free
text), ``current_sensor`` (required; ``"absolute"``, the thesis's ammeter that reports \\|i\\|, or
``"signed"``), ``vehicle`` (optional, default ``packbot``; an id of ``configs/vehicle``), ``notes``
(optional text), ``measured`` (optional bool: ``true`` for data recorded on a real vehicle; never
together with ``"synthetic": true``), ``sensors`` (optional object: one entry per channel, usually
a column name, each an object whose optional numbers ``rate_hz`` [Hz], ``quantisation`` and
``resolution`` [the channel's unit] are > 0; other entries are kept), ``data`` (optional text
label, e.g. ``"MEASURED"``). Further keys are allowed, kept in :attr:`FieldLog.meta` and ignored.
Logs written from a simulation carry ``"synthetic": true`` and a ``"source"``.

Every error is a :class:`FieldLogError` (a ``ValueError``) whose message names the file, and for
``log.csv`` the column and the row as ``line L (data row R)``: L is the 1-based line number of the
CSV file (the header is line 1) and R = L - 1 is the 1-based data row.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

__all__ = [
    "FieldLogError",
    "FieldLogWarning",
    "FieldLog",
    "read_field_log",
    "write_field_log",
    "write_log_columns",
    "validate_meta",
    "REQUIRED_COLUMNS",
    "INPUT_COLUMNS",
    "MEASURED_COLUMNS",
    "OPTIONAL_COLUMNS",
    "LOG_COLUMNS",
    "VOLTAGE_PAIR",
    "SPEED_PAIRS",
    "SPEED_COLUMNS",
    "INPUT_MODES",
    "CURRENT_SENSORS",
    "input_mode_of",
]

INPUT_COLUMNS = ("t", "v_left", "v_right")  # must be present in every row
MEASURED_COLUMNS = ("i_left", "i_right", "speed_ideal", "yaw_rate")  # in the header; cells may be empty
REQUIRED_COLUMNS = INPUT_COLUMNS + MEASURED_COLUMNS
OPTIONAL_COLUMNS = ("x", "y", "heading")  # may be absent from the header
LOG_COLUMNS = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
VOLTAGE_PAIR = ("v_left", "v_right")
SPEED_PAIRS = {"omega": ("omega_left", "omega_right"), "track_speed": ("track_speed_left", "track_speed_right")}
SPEED_UNITS = {"omega": "rad/s", "track_speed": "m/s"}
SPEED_COLUMNS = SPEED_PAIRS["omega"] + SPEED_PAIRS["track_speed"]  # the input of a speed log, else measurements
SPEED_MODE_REQUIRED = ("t", "i_left", "i_right", "yaw_rate")  # + one speed pair; speed_ideal optional
INPUT_MODES = ("voltage", "speed")
CURRENT_SENSORS = ("absolute", "signed")
_MISSING = ("", "nan", "na", "n/a", "null", "none")


def _maneuvers() -> tuple[str, ...]:
    """The maneuver names, one per task of the registry (``trackenv.envs.tasks.MANEUVERS``; imported on first
    use: the simulator's modules do not depend on the environments)."""
    from .envs.tasks import MANEUVERS  # noqa: PLC0415

    return MANEUVERS


def __getattr__(name):  # MANEUVERS: the known maneuvers (free text is accepted too), from the task registry
    if name == "MANEUVERS":
        return _maneuvers()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class FieldLogError(ValueError):
    """A field log is missing or invalid; the message names the file, and the column and row."""


class FieldLogWarning(UserWarning):
    """A field log is valid but suspicious (e.g. a long gap between samples); the message names file and row."""


# A sample interval longer than GAP_FACTOR x the log's median interval and longer than GAP_MIN_S is reported
# with a FieldLogWarning (a logger that stopped, or a time column in the wrong unit): replay interpolates the
# voltages linearly across it.
GAP_FACTOR = 100.0
GAP_MIN_S = 1.0


def input_mode_of(columns) -> tuple[str | None, str | None, str]:
    """The input mode that a ``log.csv`` header implies: ``(mode, speed_kind, reason)``.

    ``mode`` is ``"voltage"``, ``"speed"`` or None (no usable input pair: the reason says why);
    ``speed_kind`` is ``"omega"`` or ``"track_speed"`` in speed mode, else None; ``reason`` is one
    sentence naming the columns found.
    """
    cols = set(columns)
    complete = [k for k, pair in SPEED_PAIRS.items() if all(c in cols for c in pair)]
    partial = [c for c in SPEED_COLUMNS if c in cols]
    found = f" (speed columns {'/'.join(partial)} kept as measurements)" if partial else ""
    if all(c in cols for c in VOLTAGE_PAIR):
        return "voltage", None, f"voltage mode: columns v_left/v_right present{found}"
    have_v = [c for c in VOLTAGE_PAIR if c in cols]
    if have_v:
        other = [c for c in VOLTAGE_PAIR if c not in cols]
        return None, None, f"column '{have_v[0]}' is present but '{other[0]}' is not (a voltage pair needs both)"
    if len(complete) == 2:
        return None, None, ("both speed pairs are present (omega_left/omega_right and "
                            "track_speed_left/track_speed_right) and no v_left/v_right: which is the input is ambiguous; "
                            "keep one pair")
    if complete:
        kind = complete[0]
        return "speed", kind, f"speed mode: columns {kind}_left/right present, no v_left/v_right"
    if partial:
        kind = "omega" if partial[0].startswith("omega") else "track_speed"
        other = [c for c in SPEED_PAIRS[kind] if c not in cols]
        return None, None, (f"column '{partial[0]}' is present but '{other[0]}' is not, and there is no v_left/v_right "
                            "(a speed pair needs both)")
    return None, None, ("no input pair: neither v_left/v_right nor a speed pair (omega_left/omega_right or "
                        "track_speed_left/track_speed_right)")


@dataclass(frozen=True, eq=False)
class FieldLog:
    """One field test read from a §9 folder.

    ``data`` holds the log's columns in file order (the §9 columns, speed columns included, as float64,
    NaN = missing sample; any other column as text); the input mode follows from its columns
    (:func:`input_mode_of`); ``meta`` the validated ``meta.json`` (``vehicle`` filled in with its
    default). ``eq=False``: DataFrames have no scalar ==.
    """

    folder: Path
    data: pd.DataFrame
    meta: dict

    @property
    def t(self) -> np.ndarray:
        """(K,) sample times [s] as logged (not shifted to start at 0)."""
        return self.data["t"].to_numpy(np.float64)

    @property
    def input_mode(self) -> str | None:
        """``"voltage"`` (the input is v_left/v_right) or ``"speed"`` (a speed pair); see the module docstring."""
        return input_mode_of(self.data.columns)[0]

    @property
    def input_mode_reason(self) -> str:
        """One sentence: which columns set the input mode (e.g. "speed mode: columns track_speed_left/right
        present, no v_left/v_right")."""
        return input_mode_of(self.data.columns)[2]

    @property
    def volts(self) -> np.ndarray:
        """(K, 2) motor voltages [v_left, v_right] [V]; raises :class:`FieldLogError` on a speed-mode log."""
        if self.input_mode != "voltage":
            raise FieldLogError(f"{self.folder / 'log.csv'}: no voltages to use: {self.input_mode_reason} (this is "
                                "a speed-mode log; its input is FieldLog.speed_input)")
        return self.data[list(VOLTAGE_PAIR)].to_numpy(np.float64)

    @property
    def speed_input(self) -> tuple[str, np.ndarray] | None:
        """``(kind, (K, 2) [left, right])`` of a speed-mode log: kind ``"omega"`` [rad/s] or
        ``"track_speed"`` [m/s]; None for a voltage-mode log."""
        mode, kind, _ = input_mode_of(self.data.columns)
        if mode != "speed":
            return None
        return kind, self.data[list(SPEED_PAIRS[kind])].to_numpy(np.float64)

    def speeds(self) -> dict[str, np.ndarray]:
        """The speed columns in the log (``omega_*``, ``track_speed_*``) that have at least one sample.

        ``{column: (K,) float64}``, NaN where a sample is missing: the input pair of a speed-mode log,
        measurements in a voltage-mode log.
        """
        out = {}
        for col in SPEED_COLUMNS:
            if col in self.data.columns:
                v = self.data[col].to_numpy(np.float64)
                if np.any(np.isfinite(v)):
                    out[col] = v
        return out

    @property
    def terrain(self) -> str:
        return self.meta["terrain"]

    @property
    def maneuver(self) -> str:
        return self.meta["maneuver"]

    @property
    def current_sensor(self) -> str:
        return self.meta["current_sensor"]

    @property
    def vehicle(self) -> str:
        return self.meta["vehicle"]

    @property
    def synthetic(self) -> bool:
        """True if the log says it was written from a simulation (``"synthetic": true``)."""
        return self.meta.get("synthetic") is True

    @property
    def is_measured(self) -> bool:
        """True if the log says it was recorded on a real vehicle (``"measured": true``)."""
        return self.meta.get("measured") is True

    def measured(self) -> dict[str, np.ndarray]:
        """The measurement channels (§9 measured and optional columns) that have at least one sample.

        Returns ``{column: (K,) float64}`` with NaN where a sample is missing.
        """
        out = {}
        for col in MEASURED_COLUMNS + OPTIONAL_COLUMNS:
            if col in self.data.columns:
                v = self.data[col].to_numpy(np.float64)
                if np.any(np.isfinite(v)):
                    out[col] = v
        return out

    def first_pose(self) -> tuple[float, float, float]:
        """(x, y, heading) of the first sample [m, m, rad]; a missing column or value counts as 0."""
        out = []
        for col in ("x", "y", "heading"):
            v = self.data[col].to_numpy(np.float64)[0] if col in self.data.columns else np.nan
            out.append(float(v) if np.isfinite(v) else 0.0)
        return tuple(out)

    def __len__(self) -> int:
        return len(self.data)

    def __repr__(self) -> str:
        t = self.t
        return (f"FieldLog({str(self.folder)!r}, {len(self)} samples, t = {t[0]:g}..{t[-1]:g} s, "
                f"input={self.input_mode!r}, terrain={self.terrain!r}, maneuver={self.maneuver!r}, current_sensor={self.current_sensor!r}, "
                f"measured={list(self.measured())})")


# ----------------------------------------------------------------------------------------------
# meta.json


def validate_meta(meta: Any, where: str = "meta.json") -> dict:
    """Check a ``meta.json`` mapping (docs/model.md §9) and return a copy with defaults filled in.

    Raises :class:`FieldLogError` naming ``where`` and the key.
    """
    from .params import list_terrains, list_vehicles

    if not isinstance(meta, dict):
        raise FieldLogError(f"{where}: the top level must be a JSON object {{...}}, got {type(meta).__name__}")
    meta = dict(meta)
    for key in ("terrain", "maneuver", "current_sensor"):
        if key not in meta:
            raise FieldLogError(f"{where}: missing required key '{key}' (required: terrain, maneuver, current_sensor)")
    terrain = meta["terrain"]
    known = list_terrains()
    if not isinstance(terrain, str) or terrain not in known:
        raise FieldLogError(f"{where}: key 'terrain' = {terrain!r} is not a known terrain id "
                            f"(known: {', '.join(known)})")
    maneuver = meta["maneuver"]
    if not isinstance(maneuver, str) or not maneuver.strip():
        raise FieldLogError(f"{where}: key 'maneuver' must be a non-empty string ({' | '.join(_maneuvers())} or free "
                            f"text), got {maneuver!r}")
    sensor = meta["current_sensor"]
    if sensor not in CURRENT_SENSORS:
        raise FieldLogError(f"{where}: key 'current_sensor' = {sensor!r} must be \"absolute\" (the ammeter reports "
                            f"|i|, as in the thesis) or \"signed\"")
    vehicle = meta.setdefault("vehicle", "packbot")
    vehicles = list_vehicles()
    if not isinstance(vehicle, str) or vehicle not in vehicles:
        raise FieldLogError(f"{where}: key 'vehicle' = {vehicle!r} is not a known vehicle id "
                            f"(known: {', '.join(vehicles)})")
    if "notes" in meta and not isinstance(meta["notes"], str):
        raise FieldLogError(f"{where}: key 'notes' must be a string, got {type(meta['notes']).__name__}")
    if "data" in meta and not isinstance(meta["data"], str):
        raise FieldLogError(f"{where}: key 'data' must be a string label (e.g. \"MEASURED\"), got "
                            f"{type(meta['data']).__name__}")
    if "measured" in meta:
        if not isinstance(meta["measured"], bool):
            raise FieldLogError(f"{where}: key 'measured' must be true or false, got {meta['measured']!r}")
        if meta["measured"] and meta.get("synthetic") is True:
            raise FieldLogError(f"{where}: keys 'measured' and 'synthetic' are both true; a log is either recorded on "
                                "a vehicle or written from a simulation")
    if "sensors" in meta:
        _validate_sensors(meta["sensors"], where)
    return meta


SENSOR_NUMBERS = ("rate_hz", "quantisation", "resolution")  # optional numbers > 0 of a meta.json 'sensors' entry


def _validate_sensors(sensors: Any, where: str) -> None:
    if not isinstance(sensors, dict):
        raise FieldLogError(f"{where}: key 'sensors' must be an object {{channel: {{rate_hz, quantisation, ...}}}}, "
                            f"got {type(sensors).__name__}")
    for name, entry in sensors.items():
        if not isinstance(entry, dict):
            raise FieldLogError(f"{where}: key 'sensors' -> '{name}' must be an object (rate_hz, quantisation, "
                                f"resolution, ...), got {type(entry).__name__}")
        for key in SENSOR_NUMBERS:
            if key in entry:
                x = entry[key]
                ok = isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0
                if not ok:
                    raise FieldLogError(f"{where}: key 'sensors' -> '{name}' -> '{key}' must be a number > 0, got {x!r}")


def _read_meta(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FieldLogError(f"{path}: not UTF-8 text ({exc})") from None
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FieldLogError(f"{path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
    return validate_meta(meta, str(path))


# ----------------------------------------------------------------------------------------------
# log.csv


def _voltage_limit(vehicle: str) -> float:
    from .params import vehicle_voltage_limit

    return vehicle_voltage_limit(vehicle)


def _read_csv(path: Path, meta: dict) -> pd.DataFrame:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FieldLogError(f"{path}: not UTF-8 text ({exc})") from None
    reader = csv.reader(io.StringIO(text, newline=""), skipinitialspace=True)
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    try:
        for fields in reader:
            if not fields or all(not f.strip() for f in fields):
                continue  # blank line
            if header is None:
                header = [f.strip() for f in fields]
                header_line = reader.line_num
                if header_line != 1:
                    raise FieldLogError(f"{path}: line {header_line}: the header row must be line 1")
                continue
            if len(fields) != len(header):
                raise FieldLogError(
                    f"{path}: line {reader.line_num} (data row {reader.line_num - 1}) has {len(fields)} fields but "
                    f"the header has {len(header)} ({','.join(header)})")
            rows.append(fields)
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise FieldLogError(f"{path}: line {reader.line_num}: malformed CSV ({exc})") from None
    if header is None:
        raise FieldLogError(f"{path}: empty file: expected a header row {','.join(REQUIRED_COLUMNS)} and data rows")
    for i, name in enumerate(header):
        if not name:
            raise FieldLogError(f"{path}: line 1 (header): column {i + 1} has an empty name")
        if name in header[:i]:
            raise FieldLogError(f"{path}: line 1 (header): column '{name}' appears twice")
    mode, kind, reason = input_mode_of(header)
    if mode == "speed":
        inputs = ("t",) + SPEED_PAIRS[kind]
        required = SPEED_MODE_REQUIRED[:1] + SPEED_PAIRS[kind] + SPEED_MODE_REQUIRED[1:]
        req_text = f"required in speed mode: {','.join(required)}; speed_ideal optional"
    else:
        inputs = INPUT_COLUMNS
        required = REQUIRED_COLUMNS
        req_text = (f"required: {','.join(REQUIRED_COLUMNS)}, or a speed pair omega_left/omega_right or "
                    "track_speed_left/track_speed_right in place of v_left/v_right")
    if mode is None and not any(c in header for c in VOLTAGE_PAIR) and any(c in header for c in SPEED_COLUMNS):
        raise FieldLogError(f"{path}: line 1 (header): {reason}")
    missing = [c for c in required if c not in header]
    if missing:
        hint = ""
        for sep in (";", "\t", "|"):
            if len(header) == 1 and sep in header[0]:
                name = "tab" if sep == "\t" else repr(sep)
                hint = (f"; the header looks {name}-delimited ({header[0][:60]!r}): log.csv must be comma-separated")
                break
        if not hint:
            lower = {h.lower(): h for h in header}
            found = [f"{lower[c]!r} for {c!r}" for c in missing if c in lower]
            if found:
                hint = f"; column names are case-sensitive (lower case): found {', '.join(found)}"
        raise FieldLogError(
            f"{path}: line 1 (header): missing required column(s) {', '.join(repr(c) for c in missing)} "
            f"({req_text}; a channel that was not logged stays in the header with empty cells){hint}")
    if len(rows) < 2:
        raise FieldLogError(f"{path}: column 't': {len(rows)} data row(s); a log needs at least 2 samples")

    raw = pd.DataFrame(rows, columns=header)
    line = np.asarray(lines)

    def where(col: str, k: int) -> str:
        return f"{path}: column '{col}', line {line[k]} (data row {line[k] - 1})"

    data = {}
    for col in header:
        if col not in LOG_COLUMNS and col not in SPEED_COLUMNS:
            data[col] = raw[col].str.strip()  # extra columns: kept as text, ignored
            continue
        s = raw[col].str.strip()
        empty = s.str.lower().isin(_MISSING).to_numpy()
        vals = pd.to_numeric(s.where(~empty, None), errors="coerce").to_numpy(np.float64)
        bad = ~empty & ~np.isfinite(vals)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FieldLogError(f"{where(col, k)}: {s.iloc[k]!r} is not a finite number")
        if col in inputs and empty.any():
            k = int(np.flatnonzero(empty)[0])
            what = "time" if col == "t" else "voltage" if mode != "speed" else "speed"
            raise FieldLogError(f"{where(col, k)}: the {what} is missing ({s.iloc[k]!r}); '{col}' must be present in "
                                f"every row ({'voltages' if mode != 'speed' else 'speeds'} are the replay input, "
                                "linear between samples)")
        data[col] = vals
    df = pd.DataFrame(data, columns=header)

    t = df["t"].to_numpy()
    dt = np.diff(t)
    if np.any(dt <= 0):
        k = int(np.flatnonzero(dt <= 0)[0]) + 1
        problem = "duplicate time" if dt[k - 1] == 0 else "time goes backwards"
        raise FieldLogError(f"{where('t', k)}: t = {t[k]:.15g} s is not greater than t = {t[k - 1]:.15g} s at line "
                            f"{line[k - 1]} ({problem}); t must be strictly increasing")
    if dt.size >= 1:
        med = float(np.median(dt))
        gaps = np.flatnonzero((dt > GAP_FACTOR * med) & (dt > GAP_MIN_S))
        if gaps.size:
            import warnings

            k = int(gaps[0]) + 1
            warnings.warn(f"{where('t', k)}: a gap of {dt[k - 1]:.6g} s after t = {t[k - 1]:.15g} s (line "
                          f"{line[k - 1]}), {dt[k - 1] / med:.0f}x the median sample interval {med:.6g} s"
                          f"{f' ({gaps.size} such gaps)' if gaps.size > 1 else ''}; replay interpolates the "
                          f"{'voltages' if mode == 'voltage' else 'speeds'} linearly across it", FieldLogWarning,
                          stacklevel=3)
    limit = _voltage_limit(meta["vehicle"])
    for col in VOLTAGE_PAIR if mode == "voltage" else ():
        over = np.abs(df[col].to_numpy()) > limit + 1e-9
        if over.any():
            k = int(np.flatnonzero(over)[0])
            raise FieldLogError(f"{where(col, k)}: |V| = {abs(df[col].iloc[k]):g} V exceeds the ±{limit:g} V bus "
                                f"limit of vehicle '{meta['vehicle']}'")
    if meta["current_sensor"] == "absolute":
        for col in ("i_left", "i_right"):
            neg = df[col].to_numpy() < 0  # NaN compares False
            if neg.any():
                k = int(np.flatnonzero(neg)[0])
                raise FieldLogError(
                    f"{where(col, k)}: current {df[col].iloc[k]:g} A is negative, but meta.json says "
                    f"current_sensor = \"absolute\" (an ammeter that reports |i|); set \"signed\" if it measured "
                    f"signed currents")
    return df


def read_field_log(folder: str | Path) -> FieldLog:
    """Read and validate a field-log folder (``log.csv`` + ``meta.json``, docs/model.md §9).

    Raises :class:`FieldLogError` naming the file, and for ``log.csv`` the column and the row
    (``line L (data row R)``: CSV line, header = line 1; data row R = L - 1).
    """
    folder = Path(folder)
    if not folder.exists():
        raise FieldLogError(f"{folder}: no such field-log folder (expected a folder with log.csv and meta.json)")
    if not folder.is_dir():
        raise FieldLogError(f"{folder}: not a folder (a field log is a folder with log.csv and meta.json)")
    log_path, meta_path = folder / "log.csv", folder / "meta.json"
    for p in (log_path, meta_path):
        if not p.is_file():
            raise FieldLogError(f"{p}: missing file (a field-log folder holds log.csv and meta.json, docs/model.md §9)")
    meta = _read_meta(meta_path)
    data = _read_csv(log_path, meta)
    return FieldLog(folder=folder, data=data, meta=meta)


# ----------------------------------------------------------------------------------------------
# writing


def _fmt(x: float, digits: int = 8) -> str:
    return "" if not math.isfinite(x) else f"{x:.{digits}g}"


def write_log_columns(folder: str | Path, columns: dict, meta: dict, *, digits: int | None = 8) -> tuple[Path, Path]:
    """Write ``log.csv`` and ``meta.json`` from ``{column: (K,) array}`` (NaN = missing) and a meta dict.

    The input pair decides the mode (module docstring): ``v_left``/``v_right``, or, without them,
    one speed pair (then ``speed_ideal`` may be left out). Columns are written in §9 order (``t``
    first, then the speed columns), then any others. ``meta`` is validated (:func:`validate_meta`).
    Times are written with 15 significant digits, the other columns with ``digits`` (default 8,
    float32 precision); ``digits=None`` writes every number, times included, as the shortest text
    that reads back to the same float64 (for measured data copied from another file). Returns the
    two paths.
    """
    folder = Path(folder)
    meta = validate_meta(meta, f"{folder / 'meta.json'} (to be written)")
    mode, kind, reason = input_mode_of(columns)
    if mode == "speed":
        inputs = ("t",) + SPEED_PAIRS[kind]
        required = inputs + SPEED_MODE_REQUIRED[1:]
    elif mode == "voltage":
        inputs, required = INPUT_COLUMNS, REQUIRED_COLUMNS
    else:
        raise ValueError(f"write_log_columns: {reason}")
    missing = [c for c in required if c not in columns]
    if missing:
        raise ValueError(f"write_log_columns: missing column(s) {missing}")
    known = LOG_COLUMNS + SPEED_COLUMNS
    order = [c for c in LOG_COLUMNS if c in columns]
    order = order[:1] + [c for c in SPEED_COLUMNS if c in columns] + order[1:] + [c for c in columns if c not in known]
    df = pd.DataFrame({c: np.asarray(columns[c], np.float64) for c in order})
    for c in inputs:
        if not np.all(np.isfinite(df[c])):
            raise ValueError(f"write_log_columns: column '{c}' has non-finite values")
    if np.any(np.diff(df["t"].to_numpy()) <= 0):
        raise ValueError("write_log_columns: t must be strictly increasing")
    if digits is None:
        out = pd.DataFrame({c: [repr(float(x)) if math.isfinite(x) else "" for x in df[c]] for c in order})
    else:
        out = pd.DataFrame({c: [f"{x:.15g}" for x in df[c]] if c == "t" else [_fmt(x, digits) for x in df[c]]
                            for c in order})
    folder.mkdir(parents=True, exist_ok=True)
    log_path, meta_path = folder / "log.csv", folder / "meta.json"
    out.to_csv(log_path, index=False, lineterminator="\n")
    meta_path.write_text(json.dumps(meta, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    return log_path, meta_path


def _float64_times(t32: np.ndarray) -> np.ndarray:
    """The float64 times of a uniform float32 grid ``t0 + k dt`` (removes float32 noise), else as given."""
    t = np.asarray(t32, np.float64)
    n = t.shape[0]
    if n < 3:
        return t
    step = (t[-1] - t[0]) / (n - 1)
    if not np.allclose(np.diff(t), step, rtol=1e-3, atol=0):
        return t
    nice = float(f"{step:.6g}")
    step = nice if abs(nice - step) <= 1e-6 * step else step
    t0 = float(f"{t[0]:.6g}") if abs(t[0]) < 1e6 else t[0]
    t64 = t0 + np.arange(n) * step
    return t64 if np.allclose(t64, t, rtol=0, atol=1e-5 * max(1.0, abs(t[-1]))) else t


def write_field_log(
    folder: str | Path,
    traj,
    meta: dict,
    current_sensor: str = "absolute",
    channels_optional: bool = True,
    *,
    times=None,
    profile=None,
    t_offset: float = 0.0,
) -> FieldLog:
    """Write a single-vehicle :class:`~trackenv.simulate.Trajectory` as a §9 field log; returns it read back.

    Args:
        folder: the log folder (created; ``log.csv`` and ``meta.json`` are overwritten).
        traj: a single-vehicle trajectory from :func:`trackenv.simulate` (no batch axes, not diverged).
        meta: ``meta.json`` content; needs ``terrain`` and ``maneuver``. ``vehicle`` defaults to
            ``packbot``. ``"synthetic": true`` is always set and ``"source"`` defaults to
            ``"trackenv.simulate"``, so a simulated log is never mistaken for a measured one.
        current_sensor: ``"absolute"`` writes |i| (the thesis's ammeter, ``instruments.ammeter``),
            ``"signed"`` the signed currents; recorded in ``meta.json``.
        channels_optional: also write the optional pose columns ``x``, ``y``, ``heading``.
        times: sample times (in the trajectory's time base) to write instead of the trajectory's own
            grid; channels are interpolated linearly between trajectory samples, so times on the grid
            are exact.
        profile: the :class:`~trackenv.simulate.VoltageProfile` that drove ``traj``: voltages are then
            evaluated from it in float64 (otherwise taken from the trajectory, float32, and with
            ``times`` interpolated between its samples, which cuts the corners of a profile whose
            breakpoints fall between them).
        t_offset: added to the written times (e.g. to restore a log's own time base).
    """
    from .instruments import ammeter

    if current_sensor not in CURRENT_SENSORS:
        raise ValueError(f"current_sensor must be 'absolute' or 'signed', got {current_sensor!r}")
    if "current_sensor" in meta and meta["current_sensor"] != current_sensor:
        raise ValueError(f"meta says current_sensor = {meta['current_sensor']!r} but current_sensor = "
                         f"{current_sensor!r} was passed")
    volts = np.asarray(traj.voltage, np.float64)
    if volts.ndim != 2:
        raise ValueError(f"write_field_log needs a single-vehicle trajectory; got voltages of shape {volts.shape} "
                         "(index the batch first)")
    if bool(np.asarray(traj.diverged)):
        raise ValueError(f"the trajectory diverged at t = {float(np.asarray(traj.t_diverged)):.3f} s; not writing it")
    tg = _float64_times(np.asarray(traj.t))
    ch = {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}
    ch["i_left"] = np.asarray(ammeter(ch["i_left"], current_sensor), np.float64)
    ch["i_right"] = np.asarray(ammeter(ch["i_right"], current_sensor), np.float64)
    names = list(MEASURED_COLUMNS) + (list(OPTIONAL_COLUMNS) if channels_optional else [])
    if times is None:
        t = tg
        vl, vr = volts[:, 0], volts[:, 1]
        cols = {c: ch[c] for c in names}
    else:
        t = np.asarray(times, np.float64)
        if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
            raise ValueError("times must be a strictly increasing 1-D array of at least 2 samples")
        if t[0] < tg[0] - 1e-9 or t[-1] > tg[-1] + 1e-9:
            raise ValueError(f"times {t[0]:g}..{t[-1]:g} s lie outside the trajectory's {tg[0]:g}..{tg[-1]:g} s")
        vl, vr = np.interp(t, tg, volts[:, 0]), np.interp(t, tg, volts[:, 1])
        cols = {c: np.interp(t, tg, ch[c]) for c in names}
    if profile is not None:  # exact voltages (float64) from the profile's breakpoints
        pt, pv = np.asarray(profile.t, np.float64), np.asarray(profile.volts, np.float64)
        if pv.ndim != 2:
            raise ValueError("profile must be a single-vehicle VoltageProfile")
        vl, vr = np.interp(t, pt, pv[:, 0]), np.interp(t, pt, pv[:, 1])
    cols = {"t": t + t_offset, "v_left": vl, "v_right": vr, **cols}
    meta = dict(meta)
    meta["current_sensor"] = current_sensor
    meta["synthetic"] = True
    meta.setdefault("source", "trackenv.simulate")
    write_log_columns(folder, cols, meta)
    return read_field_log(folder)
