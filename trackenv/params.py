"""Parameters as immutable JAX pytrees, loaded and validated from ``configs/``.

Every number comes from a YAML file whose entries are ``{value, unit, source}`` (MODEL.md §2).
The loaders reject unknown keys, missing keys and non-physical values with a :class:`ConfigError`
that names the file and the key, so a typo never becomes a silent default.

The pytrees are :class:`equinox.Module` instances: their array leaves can be ``jax.vmap``-ed
(a batch of terrains, a randomised vehicle) and differentiated (``jax.grad`` with respect to,
say, the cohesion), while the few discrete choices (the shear law, the number of contact points)
are static fields that select the compiled program.

Units are SI; angles are stored in radians (the YAML files state degrees).
"""

from __future__ import annotations

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
    """PackBot body, track geometry and drive train (App. A, B; Table 4.1). SI units."""

    mass: jax.Array  # kg
    yaw_inertia: jax.Array  # kg m^2
    cg_height: jax.Array  # m
    track_gauge: jax.Array  # m, B: distance between track centrelines
    contact_length: jax.Array  # m, L
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
    n_contact: int = eqx.field(static=True, default=14)

    @property
    def alpha(self) -> jax.Array:
        """Torque gain at the sprocket, alpha = K_t G_r [N m/A] (§5.3.1)."""
        return self.torque_constant * self.gear_ratio

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

    The thesis's two models are the two special cases (MODEL.md §5): ``constant`` (5.10, Table 5.4,
    the default) sets ``viscous = 0``; ``viscous`` (3.41, Table 5.3) sets ``constant = 0``. Keeping
    both as numbers makes the choice differentiable and batchable.
    """

    constant: jax.Array  # N m, b*_int
    viscous: jax.Array  # N m s/rad, b_int


class Params(eqx.Module):
    """Everything a simulation needs: vehicle, terrain, internal resistance, and effects.

    ``effects`` is a tuple of :class:`trackenv.effects.Effect` modules (MODEL.md §8); it is empty
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

_VEHICLE_KEYS = {
    # key: (attribute, lower bound, strict)
    "mass": ("mass", 0.0, True),
    "yaw_inertia": ("yaw_inertia", 0.0, True),
    "cg_height": ("cg_height", 0.0, False),
    "track_gauge": ("track_gauge", 0.0, True),
    "contact_length": ("contact_length", 0.0, True),
    "track_width": ("track_width", 0.0, True),
    "sprocket_radius": ("sprocket_radius", 0.0, True),
    "grouser_height": ("grouser_height", 0.0, False),
    "gear_ratio": ("gear_ratio", 0.0, True),
    "torque_constant": ("torque_constant", 0.0, True),
    "speed_constant": ("back_emf_constant", 0.0, True),  # converted from rpm/V
    "motor_inductance": ("motor_inductance", 0.0, True),
    "motor_resistance": ("motor_resistance", 0.0, True),
    "drive_inertia": ("drive_inertia", 0.0, True),
    "drive_damping": ("drive_damping", 0.0, False),
    "stiction_torque": ("stiction_torque", 0.0, False),
    "voltage_limit": ("voltage_limit", 0.0, True),
    "n_contact": ("n_contact", 2.0, False),
}

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


def _number(path: Path, key: str, value: Any, lower: float | None = None, strict: bool = True,
            upper: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{path}: key '{key}' must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f"{path}: key '{key}' must be finite, got {value}")
    if lower is not None and (value <= lower if strict else value < lower):
        rel = ">" if strict else ">="
        raise ConfigError(f"{path}: key '{key}' = {value} is non-physical (must be {rel} {lower})")
    if upper is not None and value >= upper:
        raise ConfigError(f"{path}: key '{key}' = {value} is non-physical (must be < {upper})")
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
    _check_keys(path, data, set(_VEHICLE_KEYS), set(_VEHICLE_KEYS))
    kwargs: dict[str, Any] = {}
    for key, (attr, lower, strict) in _VEHICLE_KEYS.items():
        value = _number(path, key, _entry(path, data, key), lower, strict)
        if key == "speed_constant":
            value = 60.0 / (2.0 * math.pi * value)  # rpm/V -> V s/rad (back-emf constant)
        if key == "n_contact":
            if value != int(value):
                raise ConfigError(f"{path}: key 'n_contact' must be an integer, got {value}")
            kwargs[attr] = int(value)
        else:
            kwargs[attr] = jnp.asarray(value, dtype)
    return Vehicle(**kwargs)


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
    num = lambda key, lo, strict=True, hi=None: _number(path, key, _entry(path, data, key), lo, strict, hi)  # noqa: E731
    phi_deg = num("friction_angle", 0.0, False, 90.0)
    if deformable:
        n = num("sinkage_exponent", 0.0)
        k_c = num("k_c", 0.0, False)
        k_phi = num("k_phi", 0.0, False)
        if k_c == 0.0 and k_phi == 0.0:
            raise ConfigError(f"{path}: keys 'k_c', 'k_phi' are both 0: the Bekker modulus k must be > 0")
    else:  # unused on hard ground (compaction is switched off); harmless placeholders
        n, k_c, k_phi = 1.0, 0.0, 1.0
    residual = num("residual_ratio", 0.0) if "residual_ratio" in data else 0.5
    if law == "wong_hump" and "residual_ratio" not in data:
        raise ConfigError(f"{path}: shear_law 'wong_hump' (2.11) needs key 'residual_ratio' (K_r)")
    f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
    terrain = Terrain(
        deformable=f(1.0 if deformable else 0.0),
        cohesion=f(num("cohesion", 0.0, False)),
        friction_angle=f(math.radians(phi_deg)),
        shear_modulus=f(num("shear_modulus", 0.0)),
        sinkage_exponent=f(n),
        k_c=f(k_c),
        k_phi=f(k_phi),
        residual_ratio=f(residual),
        shear_law=law,
    )
    internal = {
        "constant": num("internal_resistance_constant", 0.0, False),
        "viscous": num("internal_resistance_viscous", 0.0, False),
    }
    return terrain, internal


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
        effects: effect modules to add to the base model (MODEL.md §8).
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
    zero = jnp.asarray(0.0, dtype)
    if internal_resistance == "constant":
        ir = InternalResistance(constant=jnp.asarray(internal["constant"], dtype), viscous=zero)
    else:
        ir = InternalResistance(constant=zero, viscous=jnp.asarray(internal["viscous"], dtype))
    return Params(vehicle=veh, terrain=ter, internal=ir, effects=tuple(effects))


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

        params = eqx.tree_at(where, params, jnp.asarray(value, node.dtype))
    return params


def astype(params: Params, dtype) -> Params:
    """Cast every floating leaf of ``params`` to ``dtype``."""
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, dtype) if eqx.is_inexact_array(x) else x, params
    )
