"""Reconstructed motor-voltage profiles of the thesis's nine field tests (``configs/field/``).

The thesis (§4.4, §5.3, §5.4.1) never measured the motor voltages of its field tests: it guessed
them by matching simulated to logged motor currents, and its plots were not digitised. The files
in ``configs/field/`` are therefore **reconstructions** from the numbers its text states (a steady
current of 1.98 A over 1-3 s at 1.1 m/s, 2.23 A over 1-2.3 s at 2 m/s, a turn during 2-3 s,
r_s/α = 0.099 so 10 V ≈ 1 m/s, ...) plus documented guesses about what a joystick operator did.
They are not measured data. Each file says which of its numbers are which.

File format (YAML, one file per test, named ``<id>.yaml``; exactly these top-level keys)::

    id: go_stop_dry_sand            # must equal the file name's stem
    maneuver: go_stop               # go_stop | j_turn | lane_change | zero_radius_turn
    terrain: dry_sand               # a terrain id of configs/terrain (dry_sand | asphalt)
    internal_resistance: constant   # constant | viscous (docs/model.md §2, §5)
    t_end: 5.0                      # s, simulated duration, >= the last breakpoint's t
    source: "thesis §5.3.1, Fig. 5.2; §5.4.1"
    reconstructed: true
    reconstruction: >
      what comes from the thesis text and what was inferred or guessed
    anchors:                        # thesis-stated field numbers the test should reproduce
      - {signal: current, stat: mean, t0: 1.0, t1: 3.0, value: 1.98, unit: A, source: "§5.4.1"}
    breakpoints:                    # [t s, v_left V, v_right V], piecewise linear
      - [0.0, 0.0, 0.0]
      - [0.3, 11.8, 11.8]

Voltages are linear between breakpoints. The first breakpoint is at t = 0; times are strictly
increasing; |V| <= 24 V (the bus voltage, docs/model.md §2). When ``t_end`` lies beyond the last
breakpoint the voltages **hold the last breakpoint's values** up to ``t_end`` (every shipped
profile ends at 0 V, so the tail is the vehicle coasting/braking to rest); before t = 0 they
hold the first values. :meth:`FieldProfile.voltages_at` implements exactly this.

Anchor entries have the keys ``signal, stat, t0, t1, value, unit, source`` and optionally
``note``. ``t0``/``t1`` may be ``null`` where the thesis names no window. Vocabulary:

- ``signal``: ``current`` (mean of |i_left| and |i_right|: the field ammeter reads absolute
  values, §5.3), ``speed_ideal`` (r_s·(ω_l+ω_r)/2, (5.1)), ``yaw_rate`` (gyro), ``sinkage``
  (observed, not logged);
- ``stat``: ``mean`` (time average of the logged signal over [t0, t1]),
  ``sim_over_field`` (the thesis's ratio of its simulated to the measured signal; unit ``"-"``),
  ``stall_after`` (time after which the signal stopped: value in s from t0),
  ``observed`` (a value the thesis reports as observed during the test, not measured).

Usage::

    from trackenv.field_profiles import list_field_tests, load_field_profile
    prof = load_field_profile("go_stop_dry_sand")
    v = prof.voltages_at(np.arange(0.0, prof.t_end, 0.05))   # (K, 2) [v_left, v_right]

This module needs only numpy and pyyaml (no JAX), so data tools can import it cheaply.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .params import vehicle_voltage_limit

__all__ = [
    "FIELD_DIR",
    "V_LIMIT",
    "FieldProfileError",
    "FieldProfile",
    "list_field_tests",
    "load_field_profile",
]

FIELD_DIR: Path = Path(__file__).resolve().parent.parent / "configs" / "field"

V_LIMIT = vehicle_voltage_limit("packbot")  # V, the PackBot's bus voltage (configs/vehicle, docs/model.md §2)

def _maneuvers() -> tuple[str, ...]:
    """The maneuver names, one per task of the registry (``trackenv.envs.tasks.MANEUVERS``; imported on first
    use: the simulator's modules do not depend on the environments)."""
    from .envs.tasks import MANEUVERS  # noqa: PLC0415

    return MANEUVERS


def __getattr__(name):  # MANEUVERS: the maneuvers a profile may name, from the task registry
    if name == "MANEUVERS":
        return _maneuvers()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


INTERNAL_RESISTANCE_MODELS = ("constant", "viscous")

_TOP_KEYS = (
    "id",
    "maneuver",
    "terrain",
    "internal_resistance",
    "t_end",
    "source",
    "reconstructed",
    "reconstruction",
    "anchors",
    "breakpoints",
)
_ANCHOR_KEYS = ("signal", "stat", "t0", "t1", "value", "unit", "source")
_ANCHOR_OPTIONAL = ("note",)
ANCHOR_SIGNALS = ("current", "speed_ideal", "yaw_rate", "sinkage")
ANCHOR_STATS = ("mean", "sim_over_field", "stall_after", "observed")


class FieldProfileError(ValueError):
    """A field-profile file is invalid or unknown; the message names the file and the key/row."""


@dataclass(frozen=True, eq=False)
class FieldProfile:
    """One reconstructed field test: piecewise-linear motor voltages plus provenance.

    ``t`` is (K,) float64, strictly increasing from 0; ``volts`` is (K, 2) float64 with columns
    [v_left, v_right]. Both arrays are read-only. ``eq=False`` because arrays have no scalar ==.
    """

    id: str
    maneuver: str
    terrain: str
    internal_resistance: str
    t_end: float
    t: np.ndarray
    volts: np.ndarray
    reconstruction: str
    source: str
    anchors: tuple[dict[str, Any], ...]

    def voltages_at(self, times: Any) -> np.ndarray:
        """Voltages [v_left, v_right] at ``times`` (any shape → shape + (2,)).

        Linear between breakpoints; holds the last breakpoint's values after it (up to and
        beyond ``t_end``) and the first before t = 0.
        """
        tt = np.asarray(times, dtype=np.float64)
        left = np.interp(tt, self.t, self.volts[:, 0])
        right = np.interp(tt, self.t, self.volts[:, 1])
        return np.stack([left, right], axis=-1)

    def sample(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Uniform samples ``(t, volts)`` over [0, t_end] (inclusive where dt divides t_end)."""
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        n = int(math.floor(self.t_end / dt + 1e-9)) + 1
        tt = np.arange(n, dtype=np.float64) * dt
        return tt, self.voltages_at(tt)


def list_field_tests() -> list[str]:
    """Sorted ids of the field tests shipped in :data:`FIELD_DIR`."""
    if not FIELD_DIR.is_dir():
        return []
    return sorted(p.stem for p in FIELD_DIR.glob("*.yaml"))


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite_number(x: Any) -> bool:
    return _is_number(x) and math.isfinite(float(x))


def _resolve(test_id_or_path: str | Path) -> Path:
    if isinstance(test_id_or_path, Path):
        path = test_id_or_path
    else:
        s = str(test_id_or_path)
        looks_like_path = s.endswith((".yaml", ".yml")) or "/" in s or "\\" in s
        if not looks_like_path:
            known = list_field_tests()
            if s not in known:
                raise FieldProfileError(
                    f"unknown field test {s!r} (KeyError-like): known ids are {known} "
                    f"in {FIELD_DIR}"
                )
            return FIELD_DIR / f"{s}.yaml"
        path = Path(s)
        if not path.is_file() and not path.is_absolute() and (FIELD_DIR / path).is_file():
            path = FIELD_DIR / path  # "go_stop_dry_sand.yaml" relative to configs/field
    if not path.is_file():
        raise FieldProfileError(f"{path}: no such field-profile file")
    return path


def load_field_profile(test_id_or_path: str | Path) -> FieldProfile:
    """Load and validate one field profile, by id (``"go_stop_dry_sand"``) or by path.

    Raises :class:`FieldProfileError` (a ``ValueError``) naming the file and the offending
    key, breakpoint row or column.
    """
    path = _resolve(test_id_or_path)
    where = str(path)

    def fail(msg: str) -> FieldProfileError:
        return FieldProfileError(f"{where}: {msg}")

    try:
        with open(path, encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise fail(f"not valid YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise fail("top level must be a mapping")

    unknown = [k for k in doc if k not in _TOP_KEYS]
    if unknown:
        raise fail(f"unknown key(s) {unknown}; allowed keys are {list(_TOP_KEYS)}")
    missing = [k for k in _TOP_KEYS if k not in doc]
    if missing:
        raise fail(f"missing key(s) {missing}")

    tid = doc["id"]
    if not isinstance(tid, str) or not tid:
        raise fail("key 'id' must be a non-empty string")
    if tid != path.stem:
        raise fail(f"key 'id' is {tid!r} but the file is named {path.name!r}")
    maneuver = doc["maneuver"]
    if maneuver not in _maneuvers():
        raise fail(f"key 'maneuver' is {maneuver!r}; expected one of {list(_maneuvers())}")
    terrain = doc["terrain"]
    if not isinstance(terrain, str) or not terrain:
        raise fail("key 'terrain' must be a non-empty terrain id string")
    ir = doc["internal_resistance"]
    if ir not in INTERNAL_RESISTANCE_MODELS:
        raise fail(
            f"key 'internal_resistance' is {ir!r}; expected one of "
            f"{list(INTERNAL_RESISTANCE_MODELS)}"
        )
    for key in ("source", "reconstruction"):
        if not isinstance(doc[key], str) or not doc[key].strip():
            raise fail(f"key {key!r} must be a non-empty string")
    if not isinstance(doc["reconstructed"], bool):
        raise fail("key 'reconstructed' must be true or false")

    # --- breakpoints -------------------------------------------------------------------
    rows = doc["breakpoints"]
    if not isinstance(rows, list) or len(rows) < 2:
        raise fail("key 'breakpoints' must be a list of at least 2 rows [t, v_left, v_right]")
    cols = ("t", "v_left", "v_right")
    for r, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != 3:
            raise fail(f"breakpoints row {r}: expected [t, v_left, v_right], got {row!r}")
        for c, x in enumerate(row):
            if not _finite_number(x):
                raise fail(
                    f"breakpoints row {r}, column {c} ({cols[c]}): expected a finite number, "
                    f"got {x!r}"
                )
    arr = np.asarray(rows, dtype=np.float64)
    t = arr[:, 0].copy()
    volts = arr[:, 1:].copy()
    if t[0] != 0.0:
        raise fail(f"breakpoints row 0: t must start at 0.0, got {t[0]!r}")
    for r in range(1, len(t)):
        if not t[r] > t[r - 1]:
            raise fail(
                f"breakpoints row {r}: t = {t[r]!r} is not strictly greater than "
                f"row {r - 1}'s t = {t[r - 1]!r}"
            )
    for r in range(len(t)):
        for c in (0, 1):
            if abs(volts[r, c]) > V_LIMIT:
                raise fail(
                    f"breakpoints row {r}, column {c + 1} ({cols[c + 1]}): |V| = "
                    f"{abs(volts[r, c])!r} exceeds the {V_LIMIT} V limit"
                )

    t_end = doc["t_end"]
    if not _finite_number(t_end) or t_end <= 0:
        raise fail(f"key 't_end' must be a positive finite number, got {t_end!r}")
    t_end = float(t_end)
    if t_end < t[-1]:
        raise fail(f"key 't_end' = {t_end} is before the last breakpoint's t = {t[-1]}")

    # --- anchors -----------------------------------------------------------------------
    anchors_raw = doc["anchors"]
    if anchors_raw is None:
        anchors_raw = []
    if not isinstance(anchors_raw, list):
        raise fail("key 'anchors' must be a list (possibly empty)")
    anchors: list[dict[str, Any]] = []
    for a, anc in enumerate(anchors_raw):
        if not isinstance(anc, dict):
            raise fail(f"anchors entry {a}: expected a mapping, got {anc!r}")
        bad = [k for k in anc if k not in _ANCHOR_KEYS + _ANCHOR_OPTIONAL]
        if bad:
            raise fail(f"anchors entry {a}: unknown key(s) {bad}")
        miss = [k for k in _ANCHOR_KEYS if k not in anc]
        if miss:
            raise fail(f"anchors entry {a}: missing key(s) {miss}")
        if anc["signal"] not in ANCHOR_SIGNALS:
            raise fail(f"anchors entry {a}: key 'signal' must be one of {list(ANCHOR_SIGNALS)}")
        if anc["stat"] not in ANCHOR_STATS:
            raise fail(f"anchors entry {a}: key 'stat' must be one of {list(ANCHOR_STATS)}")
        if not _finite_number(anc["value"]):
            raise fail(f"anchors entry {a}: key 'value' must be a finite number")
        for k in ("t0", "t1"):
            if anc[k] is not None and not (_finite_number(anc[k]) and 0 <= anc[k] <= t_end):
                raise fail(f"anchors entry {a}: key {k!r} must be null or a time in [0, t_end]")
        if anc["t0"] is not None and anc["t1"] is not None and not anc["t0"] < anc["t1"]:
            raise fail(f"anchors entry {a}: t0 must be < t1")
        if anc["stat"] == "mean" and (anc["t0"] is None or anc["t1"] is None):
            raise fail(f"anchors entry {a}: stat 'mean' needs both t0 and t1")
        anchors.append(dict(anc))

    t.setflags(write=False)
    volts.setflags(write=False)
    return FieldProfile(
        id=tid,
        maneuver=maneuver,
        terrain=terrain,
        internal_resistance=ir,
        t_end=t_end,
        t=t,
        volts=volts,
        reconstruction=" ".join(doc["reconstruction"].split()),
        source=doc["source"],
        anchors=tuple(anchors),
    )
