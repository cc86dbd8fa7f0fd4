"""Parameters as immutable JAX pytrees, loaded and validated from ``configs/``.

Every number comes from a YAML file whose entries are ``{value, unit, source}`` (docs/model.md §2).
The loaders reject unknown keys, missing keys and non-physical values with a :class:`ConfigError`
that names the file and the key, so a typo never becomes a silent default.

The pytrees are :class:`equinox.Module` instances: their array leaves can be ``jax.vmap``-ed
(a batch of terrains, a randomised vehicle) and differentiated (``jax.grad`` with respect to,
say, the cohesion), while the few discrete choices (the shear law, the number of contact points)
are static fields that select the compiled program.

Units are SI; angles are stored in radians (the YAML files state degrees). Each YAML key expects one
unit; a value stated in another unit is converted through the declared :data:`UNIT_CONVERSIONS`
(kPa -> Pa, rad -> deg, cm -> m, ...), and any other unit is a :class:`ConfigError` naming file and key.

:data:`BOUNDS` is the one table of physical ranges: :func:`check_value` applies it when YAML is loaded,
in :func:`replace`, to domain-randomisation ranges and (through :func:`validate_params`) in
:func:`load_params`; effects check their own ``bounds`` when they are constructed.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import yaml

CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs"
VEHICLE_DIR = CONFIG_DIR / "vehicle"
TERRAIN_DIR = CONFIG_DIR / "terrain"

InternalResistanceModel = Literal["constant", "viscous"]
ShearLaw = Literal["janosi", "wong_hump", "wong_peak"]


class ConfigError(ValueError):
    """A configuration file or parameter value is invalid; the message names file and key."""


class Vehicle(eqx.Module):
    """Body, contact layout and drive train of a skid-steered vehicle (PackBot: App. A, B; Table 4.1). SI units.

    Each side touches the ground in ``n_patches`` equal contact patches of length ``contact_length``,
    their centres equally spaced from x = +wheelbase/2 (front) to -wheelbase/2 (rear): one patch
    centred at x = 0 is a track (``n_patches = 1``, ``wheelbase = 0``, the thesis's PackBot), two are the
    tyres of a four-wheel skid-steer vehicle (docs/model.md §1.1). ``n_contact`` points per side are
    spread evenly over the patches, ``n_contact / n_patches`` (at least 2) over each.
    """

    mass: jax.Array  # kg
    yaw_inertia: jax.Array  # kg m^2
    cg_height: jax.Array  # m
    track_gauge: jax.Array  # m, B: distance between track centrelines
    contact_length: jax.Array  # m, L: length of one contact patch
    track_width: jax.Array  # m, b
    sprocket_radius: jax.Array  # m, r_s
    grouser_height: jax.Array  # m, h_g
    gear_ratio: jax.Array  # -, G_r
    torque_constant: jax.Array  # N m/A, K_t (motor side)
    back_emf_constant: jax.Array  # V s/rad at the motor, 1/K_v
    motor_inductance: jax.Array  # H, L_m
    motor_resistance: jax.Array  # ohm, R_m
    drive_inertia: jax.Array  # kg m^2 at the sprocket, J_eff
    drive_damping: jax.Array  # N m s/rad, b_eff
    stiction_torque: jax.Array  # N m, tau_stick
    voltage_limit: jax.Array  # V
    gear_efficiency: jax.Array  # -, eta: torque efficiency of the gearing between motor and sprocket
    wheelbase: jax.Array  # m, distance between the first and last patch centres (0 for a track)
    n_contact: int = eqx.field(static=True, default=14)  # contact points per side, N
    n_patches: int = eqx.field(static=True, default=1)  # contact patches per side, P (1: a track)

    @property
    def alpha(self) -> jax.Array:
        """Torque gain at the sprocket, alpha = K_t G_r eta [N m/A] (§5.3.1; eta = 1 in the thesis)."""
        return self.torque_constant * self.gear_ratio * self.gear_efficiency

    @property
    def alpha_v(self) -> jax.Array:
        """Back-emf gain at the sprocket, alpha_v = G_r / K_v [V s/rad] (4.2)."""
        return self.back_emf_constant * self.gear_ratio


class Terrain(eqx.Module):
    """Terrain mechanical properties (Tables 5.1, 5.2, 5.5). SI units, angle in rad.

    ``deformable`` is 1.0 or 0.0 (a float, so that a batch may mix terrains): on deformable terrain
    compaction resistance acts and the belt radius is r_s; on hard terrain no compaction acts and the
    belt rolls on the grouser tips, radius r_s + h_g (§5.3.1).
    """

    deformable: jax.Array  # 1.0 / 0.0
    cohesion: jax.Array  # Pa, c
    friction_angle: jax.Array  # rad, phi
    shear_modulus: jax.Array  # m, K (Janosi) or K_omega (Wong forms)
    sinkage_exponent: jax.Array  # -, n
    k_c: jax.Array  # N/m^(n+1)
    k_phi: jax.Array  # N/m^(n+2)
    residual_ratio: jax.Array  # -, K_r of Wong's (2.11); unused by the other laws
    shear_law: str = eqx.field(static=True, default="janosi")


class InternalResistance(eqx.Module):
    """Internal track resistance tau_int(omega) = constant*smoothsign(omega) + viscous*omega.

    The thesis's two models are the two special cases (docs/model.md §5): ``constant`` (5.10, Table 5.4,
    the default) sets ``viscous = 0``; ``viscous`` (3.41, Table 5.3) sets ``constant = 0``. Keeping
    both as numbers makes the choice differentiable and batchable.
    """

    constant: jax.Array  # N m, b*_int
    viscous: jax.Array  # N m s/rad, b_int


class Params(eqx.Module):
    """Everything a simulation needs: vehicle, terrain, internal resistance, and effects.

    ``effects`` is a tuple of :class:`trackenv.effects.Effect` modules (docs/model.md §8); it is empty
    for the thesis's base model.
    """

    vehicle: Vehicle
    terrain: Terrain
    internal: InternalResistance
    effects: tuple = ()

    @property
    def dtype(self):
        return jnp.result_type(self.vehicle.mass)


# ----------------------------------------------------------------------------------------------
# loading and validation

# One bounds table, one owner: every parameter of :class:`Params` that has a physical range, by its dotted
# path, in the units it is stored in (SI, angles in rad). YAML loading, :func:`replace`, domain-randomisation
# ranges (``trackenv.envs.randomization``) and the effect constructors (their own ``bounds``) all check values
# through :func:`check_value`.
# path: (lower, lower strict, upper, upper strict)
BOUNDS: dict[str, tuple[float | None, bool, float | None, bool]] = {
    "vehicle.mass": (0.0, True, None, False),
    "vehicle.yaw_inertia": (0.0, True, None, False),
    "vehicle.cg_height": (0.0, False, None, False),
    "vehicle.track_gauge": (0.0, True, None, False),
    "vehicle.contact_length": (0.0, True, None, False),
    "vehicle.track_width": (0.0, True, None, False),
    "vehicle.sprocket_radius": (0.0, True, None, False),
    "vehicle.grouser_height": (0.0, False, None, False),
    "vehicle.gear_ratio": (0.0, True, None, False),
    "vehicle.torque_constant": (0.0, True, None, False),
    "vehicle.back_emf_constant": (0.0, True, None, False),
    "vehicle.motor_inductance": (0.0, True, None, False),
    "vehicle.motor_resistance": (0.0, True, None, False),
    "vehicle.drive_inertia": (0.0, True, None, False),
    "vehicle.drive_damping": (0.0, False, None, False),
    "vehicle.stiction_torque": (0.0, False, None, False),
    "vehicle.voltage_limit": (0.0, True, None, False),
    "vehicle.gear_efficiency": (0.0, True, 1.0, False),
    "vehicle.wheelbase": (0.0, False, None, False),
    "vehicle.n_contact": (2.0, False, None, False),
    "vehicle.n_patches": (1.0, False, None, False),
    "terrain.deformable": (0.0, False, 1.0, False),
    "terrain.cohesion": (0.0, False, None, False),
    "terrain.friction_angle": (0.0, False, math.pi / 2, True),
    "terrain.shear_modulus": (0.0, True, None, False),
    "terrain.sinkage_exponent": (0.0, True, None, False),
    "terrain.k_c": (0.0, False, None, False),
    "terrain.k_phi": (0.0, False, None, False),
    "terrain.residual_ratio": (0.0, True, None, False),
    "internal.constant": (0.0, False, None, False),
    "internal.viscous": (0.0, False, None, False),
}

# YAML key -> (Params path, the unit the YAML value is stated in). Values given in another unit are
# converted through UNIT_CONVERSIONS; an unknown or incompatible unit is an error naming file and key.
_VEHICLE_KEYS = {
    "mass": ("vehicle.mass", "kg"),
    "yaw_inertia": ("vehicle.yaw_inertia", "kg m^2"),
    "cg_height": ("vehicle.cg_height", "m"),
    "track_gauge": ("vehicle.track_gauge", "m"),
    "contact_length": ("vehicle.contact_length", "m"),
    "track_width": ("vehicle.track_width", "m"),
    "sprocket_radius": ("vehicle.sprocket_radius", "m"),
    "grouser_height": ("vehicle.grouser_height", "m"),
    "gear_ratio": ("vehicle.gear_ratio", "-"),
    "torque_constant": ("vehicle.torque_constant", "N m/A"),
    "speed_constant": ("vehicle.back_emf_constant", "rpm/V"),  # converted to V s/rad
    "motor_inductance": ("vehicle.motor_inductance", "H"),
    "motor_resistance": ("vehicle.motor_resistance", "ohm"),
    "drive_inertia": ("vehicle.drive_inertia", "kg m^2"),
    "drive_damping": ("vehicle.drive_damping", "N m s/rad"),
    "stiction_torque": ("vehicle.stiction_torque", "N m"),
    "voltage_limit": ("vehicle.voltage_limit", "V"),
    "gear_efficiency": ("vehicle.gear_efficiency", "-"),
    "wheelbase": ("vehicle.wheelbase", "m"),
    "n_contact": ("vehicle.n_contact", "-"),
    "n_patches": ("vehicle.n_patches", "-"),
}
_VEHICLE_INTEGERS = ("n_contact", "n_patches")  # static: they select the compiled program
_TERRAIN_KEYS = {
    "cohesion": ("terrain.cohesion", "Pa"),
    "friction_angle": ("terrain.friction_angle", "deg"),  # stored in rad
    "shear_modulus": ("terrain.shear_modulus", "m"),
    "sinkage_exponent": ("terrain.sinkage_exponent", "-"),
    "k_c": ("terrain.k_c", "N/m^(n+1)"),
    "k_phi": ("terrain.k_phi", "N/m^(n+2)"),
    "residual_ratio": ("terrain.residual_ratio", "-"),
    "internal_resistance_constant": ("internal.constant", "N m"),
    "internal_resistance_viscous": ("internal.viscous", "N m s/rad"),
}

# The declared unit conversions: (unit written in the file, unit expected) -> factor (value x factor).
UNIT_CONVERSIONS: dict[tuple[str, str], float] = {
    ("kPa", "Pa"): 1e3,
    ("MPa", "Pa"): 1e6,
    ("rad", "deg"): 180.0 / math.pi,
    ("cm", "m"): 1e-2,
    ("mm", "m"): 1e-3,
    ("in", "m"): 0.0254,
    ("g", "kg"): 1e-3,
    ("lb", "kg"): 0.45359237,
    ("mH", "H"): 1e-3,
    ("mohm", "ohm"): 1e-3,
    ("kN/m^(n+1)", "N/m^(n+1)"): 1e3,
    ("kN/m^(n+2)", "N/m^(n+2)"): 1e3,
}
_DIMENSIONLESS = ("-", "", "1")

_TERRAIN_REQUIRED = {
    "deformable",
    "shear_law",
    "cohesion",
    "friction_angle",
    "shear_modulus",
    "internal_resistance_constant",
    "internal_resistance_viscous",
}
_TERRAIN_DEFORMABLE = {"sinkage_exponent", "k_c", "k_phi"}
_TERRAIN_OPTIONAL = {"residual_ratio"}
_SHEAR_LAWS = ("janosi", "wong_hump", "wong_peak")


def _norm_unit(unit: str) -> str:
    u = " ".join(str(unit).replace("\u00b7", " ").replace("*", " ").split())
    return "-" if u in _DIMENSIONLESS else u


def convert_unit(value: float, unit: Any, expected: str, where: str) -> float:
    """``value`` stated in ``unit`` expressed in ``expected`` (the declared :data:`UNIT_CONVERSIONS`).

    ``unit`` ``None`` means the expected unit. Unknown or incompatible units raise :class:`ConfigError`
    naming ``where`` (file and key).
    """
    if unit is None:
        return value
    if not isinstance(unit, str):
        raise ConfigError(f"{where}: unit must be a string such as {expected!r}, got {unit!r}")
    u, e = _norm_unit(unit), _norm_unit(expected)
    if u == e:
        return value
    factor = UNIT_CONVERSIONS.get((u, e))
    if factor is None:
        known = sorted(a for a, b in UNIT_CONVERSIONS if b == e)
        alt = f" or {', '.join(known)} (converted)" if known else ""
        raise ConfigError(f"{where}: unit {unit!r} is unknown or incompatible; expected {expected!r}{alt}")
    return value * factor


def fmt_num(x: Any) -> str:
    """A number as plain text for messages (``1``, ``0.25``, ``-5``; never ``np.float64(1.0)``)."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return f"{v:.10g}"


def is_integer(x: Any) -> bool:
    """True for a Python or numpy integer (not a bool): the type of a count, a seed or an index."""
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def is_real(x: Any) -> bool:
    """True for a finite Python or numpy number (not a bool)."""
    return (isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))
            and bool(np.isfinite(x)))


def is_positive(x: Any) -> bool:
    """True for a finite Python or numpy number > 0 (not a bool): a duration, a rate or a length."""
    return is_real(x) and bool(x > 0)


def _bound_text(lo, lo_strict, hi, hi_strict, scale: float = 1.0, unit: str = "") -> str:
    parts = []
    u = f" {unit}" if unit and unit != "-" else ""
    if lo is not None:
        parts.append(f"{'>' if lo_strict else '>='} {fmt_num(lo * scale)}{u}")
    if hi is not None:
        parts.append(f"{'<' if hi_strict else '<='} {fmt_num(hi * scale)}{u}")
    return " and ".join(parts)


def _is_concrete(value) -> bool:
    return not isinstance(value, jax.core.Tracer)


def check_value(path: str, value: Any, where: str = "", *, label: str | None = None,
                display: tuple[float, str] = (1.0, "")) -> None:
    """Check ``value`` (a number or an array of them, in stored units) against :data:`BOUNDS` [``path``].

    Raises :class:`ConfigError` naming ``where`` (a file, or empty) and ``label`` (default: ``parameter
    'path'``). Traced values (inside ``jit``/``grad``) are not checked. ``display`` = (factor, unit) shows
    the value and bounds in another unit (e.g. degrees for the friction angle).
    """
    if path not in BOUNDS or not _is_concrete(value):
        return
    lo, lo_strict, hi, hi_strict = BOUNDS[path]
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{where + ': ' if where else ''}{label or f'parameter {path!r}'} must be a number, "
                          f"got {value!r}") from None
    flat = arr.reshape(-1)
    bad = ~np.isfinite(flat)
    # compare in the value's own precision: a float32 leaf of 0.1 is float32(0.1), not above a bound of 0.1
    own = np.asarray(value).dtype
    prec = own if np.issubdtype(own, np.floating) else np.float64
    cmp = flat.astype(prec)
    if lo is not None:
        lo_p = np.asarray(lo, prec)
        bad |= (cmp <= lo_p) if lo_strict else (cmp < lo_p)
    if hi is not None:
        hi_p = np.asarray(hi, prec)
        bad |= (cmp >= hi_p) if hi_strict else (cmp > hi_p)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        scale, unit = display
        v = flat[k]
        what = label or f"parameter {path!r}"
        at = f" (element {k})" if arr.ndim else ""
        u = f" {unit}" if unit and unit != "-" else ""
        if not math.isfinite(v):
            msg = f"{what} = {fmt_num(v)}{at} must be finite"
        else:
            msg = (f"{what} = {fmt_num(v * scale)}{u}{at} is non-physical (must be "
                   f"{_bound_text(lo, lo_strict, hi, hi_strict, scale, unit)})")
        raise ConfigError(f"{where}: {msg}" if where else msg)


def check_range(path: str, low: float, high: float, where: str = "") -> None:
    """Both ends of a range [low, high] of ``path`` inside its bounds (see :func:`check_value`)."""
    for v in (low, high):
        check_value(path, v, where, label=f"range ({fmt_num(low)}, {fmt_num(high)}) of parameter {path!r}: end")


def _read_yaml(path: Path) -> dict:
    try:
        with open(path) as fh:
            data = yaml.safe_load(fh)
    except FileNotFoundError:
        raise
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of keys at the top level")
    return data


def _entry(path: Path, data: dict, key: str) -> Any:
    if key not in data:
        raise ConfigError(f"{path}: missing key '{key}'")
    entry = data[key]
    if not isinstance(entry, dict) or set(entry) - {"value", "unit", "source"} or "value" not in entry:
        raise ConfigError(f"{path}: key '{key}' must be a mapping {{value, unit, source}}, got {entry!r}")
    if "source" not in entry:
        raise ConfigError(f"{path}: key '{key}' has no 'source' (every number states where it comes from)")
    return entry["value"]


def _entry_si(path: Path, data: dict, key: str, expected_unit: str) -> Any:
    """The entry's value converted from its stated ``unit`` to ``expected_unit`` (numbers only)."""
    value = _entry(path, data, key)
    unit = data[key].get("unit")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return value  # _number reports it
    return convert_unit(float(value), unit, expected_unit, f"{path}: key '{key}'")


def _number(path: Path, key: str, value: Any, param: str | None = None, display: tuple[float, str] = (1.0, ""),
            to_stored: float = 1.0) -> float:
    """A finite number from the file, checked against :data:`BOUNDS` [``param``] after ``x to_stored``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{path}: key '{key}' must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{path}: key '{key}' must be finite, got {fmt_num(value)}")
    if param is not None:
        check_value(param, value * to_stored, str(path), label=f"key '{key}'", display=display)
    return value


def _resolve(name_or_path: str | Path, directory: Path, kind: str) -> Path:
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        if not p.exists():
            raise ConfigError(f"{kind} file {p} does not exist")
        return p
    candidate = directory / f"{name_or_path}.yaml"
    if not candidate.exists():
        known = ", ".join(sorted(q.stem for q in directory.glob("*.yaml")))
        raise ConfigError(f"unknown {kind} '{name_or_path}' (no {candidate}); known: {known}")
    return candidate


def list_terrains() -> list[str]:
    """Ids of the terrains in ``configs/terrain``."""
    return sorted(p.stem for p in TERRAIN_DIR.glob("*.yaml"))


def list_vehicles() -> list[str]:
    """Ids of the vehicles in ``configs/vehicle``."""
    return sorted(p.stem for p in VEHICLE_DIR.glob("*.yaml"))


def _check_keys(path: Path, data: dict, allowed: set[str], required: set[str]) -> None:
    unknown = sorted(set(data) - allowed - {"id"})
    if unknown:
        raise ConfigError(f"{path}: unknown key '{unknown[0]}' (allowed: {', '.join(sorted(allowed))})")
    missing = sorted(required - set(data))
    if missing:
        raise ConfigError(f"{path}: missing key '{missing[0]}'")


def load_vehicle(name_or_path: str | Path = "packbot", dtype=jnp.float32) -> Vehicle:
    """Load and validate a vehicle config (``configs/vehicle/<id>.yaml`` or a path)."""
    path = _resolve(name_or_path, VEHICLE_DIR, "vehicle")
    data = _read_yaml(path)
    _check_keys(path, data, set(_VEHICLE_KEYS) | set(_VEHICLE_INTERNAL), set(_VEHICLE_KEYS))
    kwargs: dict[str, Any] = {}
    for key, (param, unit) in _VEHICLE_KEYS.items():
        attr = param.split(".", 1)[1]
        value = _number(path, key, _entry_si(path, data, key, unit), None if key == "speed_constant" else param)
        if key == "speed_constant":
            check_value("vehicle.back_emf_constant", value, str(path), label=f"key '{key}'")  # > 0 in rpm/V too
            value = 60.0 / (2.0 * math.pi * value)  # rpm/V -> V s/rad (back-emf constant)
        if key in _VEHICLE_INTEGERS:
            if value != int(value):
                raise ConfigError(f"{path}: key '{key}' must be an integer, got {fmt_num(value)}")
            kwargs[attr] = int(value)
        else:
            kwargs[attr] = jnp.asarray(value, dtype)
    return check_layout(Vehicle(**kwargs), str(path))


# Optional vehicle keys: the vehicle's own internal resistance, replacing the terrain file's values (which the
# thesis tuned for the PackBot's tracks, Tables 5.3-5.4) when that vehicle is simulated on any terrain.
_VEHICLE_INTERNAL = {
    "internal_resistance_constant": ("internal.constant", "N m"),
    "internal_resistance_viscous": ("internal.viscous", "N m s/rad"),
}


def vehicle_internal_resistance(name_or_path: str | Path = "packbot") -> dict:
    """The vehicle config's own internal-resistance values, ``{"constant": b*_int [N m], "viscous": b_int
    [N m s/rad]}`` for the keys it sets (empty: the terrain file's values apply, as for the PackBot)."""
    path = _resolve(name_or_path, VEHICLE_DIR, "vehicle")
    data = _read_yaml(path)
    return {param.split(".")[1]: _number(path, key, _entry_si(path, data, key, unit), param)
            for key, (param, unit) in _VEHICLE_INTERNAL.items() if key in data}


def check_layout(vehicle: Vehicle, where: str = "") -> Vehicle:
    """Check that the contact layout is consistent; return ``vehicle``.

    ``n_contact`` must be a multiple of ``n_patches`` with at least 2 points per patch; one patch (a track)
    must have ``wheelbase`` 0; several patches must not overlap (patch pitch wheelbase/(P-1) >= L).
    Raises :class:`ConfigError` naming ``where`` and the key. Traced leaves are not checked.
    """
    at = f"{where}: " if where else ""
    n, p = vehicle.n_contact, vehicle.n_patches
    if n % p != 0 or n // p < 2:
        raise ConfigError(f"{at}key 'n_contact' = {n} must be a multiple of n_patches = {p} with at least "
                          f"2 contact points per patch")
    if not (_is_concrete(vehicle.wheelbase) and _is_concrete(vehicle.contact_length)):
        return vehicle
    wheelbase = np.asarray(vehicle.wheelbase, np.float64)
    if p == 1 and np.any(wheelbase != 0.0):
        raise ConfigError(f"{at}key 'wheelbase' = {fmt_num(wheelbase.reshape(-1)[0])} m must be 0 with "
                          f"n_patches = 1 (a track is one patch centred at the CG)")
    if p > 1:
        pitch = wheelbase / (p - 1)
        length = np.asarray(vehicle.contact_length, np.float64)
        own = np.asarray(vehicle.wheelbase).dtype  # in the leaves' precision, as check_value does
        if np.any(pitch.astype(own) < length.astype(own)):
            raise ConfigError(f"{at}key 'wheelbase' = {fmt_num(wheelbase.reshape(-1)[0])} m: the {p} patches "
                              f"of length contact_length = {fmt_num(length.reshape(-1)[0])} m overlap "
                              f"(need wheelbase >= (n_patches - 1) contact_length)")
    return vehicle


def load_terrain(name_or_path: str | Path = "dry_sand", dtype=jnp.float32) -> tuple[Terrain, dict]:
    """Load and validate a terrain config; returns the terrain and its internal-resistance values.

    The second value is ``{"constant": b*_int, "viscous": b_int}`` from the same file (the thesis
    tunes the internal resistance per terrain, Tables 5.3-5.4).
    """
    path = _resolve(name_or_path, TERRAIN_DIR, "terrain")
    data = _read_yaml(path)
    deformable = _entry(path, data, "deformable") if "deformable" in data else None
    if not isinstance(deformable, bool):
        raise ConfigError(f"{path}: key 'deformable' must be true or false, got {deformable!r}")
    required = set(_TERRAIN_REQUIRED) | (_TERRAIN_DEFORMABLE if deformable else set())
    _check_keys(path, data, _TERRAIN_REQUIRED | _TERRAIN_DEFORMABLE | _TERRAIN_OPTIONAL, required)
    law = _entry(path, data, "shear_law")
    if law not in _SHEAR_LAWS:
        raise ConfigError(f"{path}: key 'shear_law' = {law!r} is not one of {_SHEAR_LAWS}")
    def num(key):
        param, unit = _TERRAIN_KEYS[key]
        if key == "friction_angle":  # stated in degrees, bounds in rad
            return _number(path, key, _entry_si(path, data, key, unit), param, (180.0 / math.pi, "deg"),
                           math.pi / 180.0)
        return _number(path, key, _entry_si(path, data, key, unit), param)

    phi_deg = num("friction_angle")
    if deformable:
        n = num("sinkage_exponent")
        k_c = num("k_c")
        k_phi = num("k_phi")
        if k_c == 0.0 and k_phi == 0.0:
            raise ConfigError(f"{path}: keys 'k_c', 'k_phi' are both 0: the Bekker modulus k must be > 0")
    else:  # unused on hard ground (compaction is switched off); harmless placeholders
        n, k_c, k_phi = 1.0, 0.0, 1.0
    residual = num("residual_ratio") if "residual_ratio" in data else 0.5
    if law == "wong_hump" and "residual_ratio" not in data:
        raise ConfigError(f"{path}: shear_law 'wong_hump' (2.11) needs key 'residual_ratio' (K_r)")
    f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
    terrain = Terrain(
        deformable=f(1.0 if deformable else 0.0),
        cohesion=f(num("cohesion")),
        friction_angle=f(math.radians(phi_deg)),
        shear_modulus=f(num("shear_modulus")),
        sinkage_exponent=f(n),
        k_c=f(k_c),
        k_phi=f(k_phi),
        residual_ratio=f(residual),
        shear_law=law,
    )
    internal = {
        "constant": num("internal_resistance_constant"),
        "viscous": num("internal_resistance_viscous"),
    }
    return terrain, internal


@functools.cache
def vehicle_voltage_limit(name_or_path: str | Path = "packbot") -> float:
    """The bus voltage limit [V] of a vehicle config (its ``voltage_limit``; ``packbot``: 24 V)."""
    return float(np.max(np.asarray(load_vehicle(name_or_path).voltage_limit)))


def load_params(
    terrain: str | Path = "dry_sand",
    vehicle: str | Path = "packbot",
    internal_resistance: InternalResistanceModel = "constant",
    effects: tuple = (),
    dtype=jnp.float32,
) -> Params:
    """Build :class:`Params` from config ids (or paths).

    Args:
        terrain: a ``configs/terrain`` id (``dry_sand``, ``asphalt``, ``sandy_loam_1`` ...) or a YAML path.
        vehicle: a ``configs/vehicle`` id or a YAML path.
        internal_resistance: ``"constant"`` (Table 5.4, the thesis's final model) or ``"viscous"``
            (Table 5.3, its first model).
        effects: effects to add to the base model (docs/model.md §8): ids (``"slip_sinkage"``, with its
            default parameters) or :class:`trackenv.effects.Effect` modules, as the environments take them.
        dtype: ``jnp.float32`` (default) or ``jnp.float64``; float64 needs ``jax_enable_x64``.
    """
    dtype = jnp.dtype(dtype)
    if dtype == jnp.float64 and not jax.config.jax_enable_x64:
        raise ConfigError(
            "dtype float64 requested but JAX runs in 32-bit mode: set JAX_ENABLE_X64=1 or call "
            "jax.config.update('jax_enable_x64', True) before creating arrays"
        )
    if dtype not in (jnp.float32, jnp.float64):
        raise ConfigError(f"dtype must be float32 or float64, got {dtype}")
    if internal_resistance not in ("constant", "viscous"):
        raise ConfigError(f"internal_resistance must be 'constant' or 'viscous', got {internal_resistance!r}")
    veh = load_vehicle(vehicle, dtype)
    ter, internal = load_terrain(terrain, dtype)
    internal = dict(internal, **vehicle_internal_resistance(vehicle))
    zero = jnp.asarray(0.0, dtype)
    if internal_resistance == "constant":
        ir = InternalResistance(constant=jnp.asarray(internal["constant"], dtype), viscous=zero)
    else:
        ir = InternalResistance(constant=zero, viscous=jnp.asarray(internal["viscous"], dtype))
    from .effects import resolve_effects

    return validate_params(Params(vehicle=veh, terrain=ter, internal=ir, effects=resolve_effects(effects, dtype)))


def replace(params: Params, **changes: Any) -> Params:
    """Return ``params`` with dotted-path leaves replaced, e.g. ``replace(p, **{"terrain.cohesion": 2e3})``.

    Values are cast to the parameters' dtype. Unknown paths raise :class:`ConfigError`.
    """
    for dotted, value in changes.items():
        parts = dotted.split(".")
        node = params
        for part in parts:
            if not hasattr(node, part):
                raise ConfigError(f"unknown parameter '{dotted}'")
            node = getattr(node, part)
        if not isinstance(node, (jax.Array, np.ndarray)):
            raise ConfigError(f"parameter '{dotted}' is not numeric and cannot be replaced this way")

        def where(p, parts=parts):
            for part in parts:
                p = getattr(p, part)
            return p

        check_value(dotted, value)  # the bounds table (concrete values; traced ones are not checked)
        params = eqx.tree_at(where, params, jnp.asarray(value, node.dtype))
    return params


def validate_params(params: Params, where: str = "") -> Params:
    """Check every bounded leaf of ``params`` (:data:`BOUNDS`) and every effect's ``bounds``; return it.

    Raises :class:`ConfigError` naming the parameter (and ``where``). Traced leaves are skipped. The
    contact layout is checked too (:func:`check_layout`).
    """
    check_layout(params.vehicle, where)
    for path in BOUNDS:
        node = params
        for part in path.split("."):
            node = getattr(node, part)
        check_value(path, node, where)
    for eff in params.effects:
        check = getattr(eff, "check_bounds", None)
        if check is not None:
            check()
    return params


def astype(params: Params, dtype) -> Params:
    """Cast every floating leaf of ``params`` to ``dtype``."""
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, dtype) if eqx.is_inexact_array(x) else x, params
    )
