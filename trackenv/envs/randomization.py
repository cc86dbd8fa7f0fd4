"""Domain randomisation: per-episode sampling of terrain and vehicle parameters (jit/vmap-able).

``domain_randomization=True`` samples the default ranges below, uniformly and independently, at every
reset; a dict ``{"terrain.cohesion": (low, high), ...}`` (dotted :class:`trackenv.params.Params`
paths, SI units, angles in radians) sets custom ranges (a plain number pins a parameter); ``False``
(default) keeps the nominal terrain. Sampling uses ``jax.random`` inside ``reset``, so a batch of
environments draws independent parameters in one vmapped call.

Default ranges, deformable terrains (dry sand and the sandy soils of Table 5.5):

====================  ================  =====================================================
terrain.cohesion      0 - 3.04 kPa      Table 5.5 (dry sand 2: 0) to Table 5.6's largest c
terrain.friction_angle 23 - 38 deg      Table 5.6's smallest phi to Table 5.5 (sandy loam 3)
terrain.shear_modulus 0.010 - 0.0508 m  Table 5.5 (sandy loams: 1 cm) to Table 5.6's K = 2 in
internal.constant     0.73 - 1.17 N m   Table 5.4 (asphalt 0.73) to Table 5.6's second b*_int
vehicle.mass          16.3 - 20.0 kg    +-10 % of 18.144 kg: NOT in the thesis (payload, batteries)
====================  ================  =====================================================

Hard ground (asphalt, non-deformable): the thesis gives one asphalt (Table 5.2) and no spans, so the
ranges are relative to the loaded terrain and are guesses: friction angle x [0.85, 1.15], shear
modulus K x [0.55, 1.45], b*_int x [0.94, 1.5] (the same relative span as the sand range above),
mass +-10 %. The yaw inertia is not rescaled with the mass.

**A ground mixture** (``domain_randomization={"grounds": ["asphalt", "dry_sand"]}``): every episode
first draws one of the named terrains (``configs/terrain`` ids), uniformly, then that terrain's default
ranges above. The terrain file supplies all of its parameters (Bekker sinkage, shear law, b*_int,
``deformable``), so one batch mixes hard and deformable ground. ``info["params"]["ground"]`` is the
index of the drawn terrain in the list. The list may omit the env's own terrain, which then only names
the classical gains and the open-loop profile of a driver.

Only constant-model internal resistance is randomised by default; with the viscous model
(``internal_resistance="viscous"``) ``internal.viscous`` is scaled x [0.94, 1.5] instead.

:func:`outside_ranges` gives ranges that lie wholly **outside** the default ones, every parameter at
once (robustness tests of drivers trained on the defaults), each on its harder side where one is
clear, the SI values:

====================  =========================  ============================================
parameter             deformable ground          hard ground (relative to the loaded terrain)
====================  =========================  ============================================
terrain.cohesion      3.04 - 4.5 kPa             (not randomised)
terrain.friction_angle 18 - 23 deg (less grip)   x [0.7, 0.85]
terrain.shear_modulus 0.0508 - 0.075 m (softer)  x [1.45, 2.0]
internal.constant     1.17 - 1.45 N m            x [1.5, 1.85]
vehicle.mass          +10 % to +20 %             +10 % to +20 %
====================  =========================  ============================================
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..params import ConfigError, Params, check_range, fmt_num

_SAND = {
    "terrain.cohesion": (0.0, 3040.0),
    "terrain.friction_angle": (math.radians(23.0), math.radians(38.0)),
    "terrain.shear_modulus": (0.010, 0.0508),
    "internal.constant": (0.73, 1.17),
}
_HARD_REL = {
    "terrain.friction_angle": (0.85, 1.15),
    "terrain.shear_modulus": (0.55, 1.45),
    "internal.constant": (0.94, 1.5),
}
_MASS_REL = (0.9, 1.1)


def _leaf(params: Params, path: str):
    node = params
    for part in path.split("."):
        if isinstance(node, (tuple, list)):
            try:
                node = node[int(part)]
            except (ValueError, IndexError):
                raise ConfigError(f"domain randomisation: unknown parameter '{path}'") from None
        elif hasattr(node, part):
            node = getattr(node, part)
        else:
            raise ConfigError(f"domain randomisation: unknown parameter '{path}'")
    if not isinstance(node, (jax.Array, np.ndarray)) or not jnp.issubdtype(node.dtype, jnp.floating):
        raise ConfigError(f"domain randomisation: parameter '{path}' is not a floating-point leaf")
    return node


def _getter(path: str):
    parts = path.split(".")

    def where(p):
        for part in parts:
            p = p[int(part)] if isinstance(p, (tuple, list)) else getattr(p, part)
        return p

    return where


def default_ranges(params: Params) -> dict[str, tuple[float, float]]:
    """The default ranges for ``params``'s terrain (see the module docstring)."""
    out: dict[str, tuple[float, float]] = {}
    deformable = float(params.terrain.deformable) > 0.5
    viscous = float(params.internal.viscous) > 0.0 and float(params.internal.constant) == 0.0
    if deformable:
        out.update({k: v for k, v in _SAND.items() if not (viscous and k == "internal.constant")})
    else:
        for k, (a, b) in _HARD_REL.items():
            if viscous and k == "internal.constant":
                continue
            nominal = float(_leaf(params, k))
            out[k] = (a * nominal, b * nominal)
    if viscous:
        nominal = float(params.internal.viscous)
        out["internal.viscous"] = (0.94 * nominal, 1.5 * nominal)
    m = float(params.vehicle.mass)
    out["vehicle.mass"] = (_MASS_REL[0] * m, _MASS_REL[1] * m)
    return out


_SAND_OUTSIDE = {
    "terrain.cohesion": (3040.0, 4500.0),
    "terrain.friction_angle": (math.radians(18.0), math.radians(23.0)),
    "terrain.shear_modulus": (0.0508, 0.075),
    "internal.constant": (1.17, 1.45),
}
_HARD_OUTSIDE_REL = {
    "terrain.friction_angle": (0.7, 0.85),
    "terrain.shear_modulus": (1.45, 2.0),
    "internal.constant": (1.5, 1.85),
}
_MASS_OUTSIDE_REL = (1.1, 1.2)


def outside_ranges(params: Params) -> dict[str, tuple[float, float]]:
    """Ranges wholly outside :func:`default_ranges` for ``params``'s terrain, for every parameter it
    randomises (table in the module docstring): a draw from them is outside the training box in every
    coordinate. Constant-model internal resistance only (a viscous model raises ``ConfigError``)."""
    if float(params.internal.viscous) > 0.0 and float(params.internal.constant) == 0.0:
        raise ConfigError("outside_ranges: defined for the constant internal-resistance model only")
    if float(params.terrain.deformable) > 0.5:
        out = dict(_SAND_OUTSIDE)
    else:
        out = {k: (a * float(_leaf(params, k)), b * float(_leaf(params, k))) for k, (a, b) in _HARD_OUTSIDE_REL.items()}
    m = float(params.vehicle.mass)
    out["vehicle.mass"] = (_MASS_OUTSIDE_REL[0] * m, _MASS_OUTSIDE_REL[1] * m)
    return out


GROUND = "ground"  # the pseudo-path of a ground mixture's drawn terrain (its index in the list)


def resolve_grounds(spec: dict, load) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, Params]:
    """A ground mixture ``{"grounds": names}`` -> (paths, low (K, n), high (K, n), grounds), validated.

    ``load(name)`` builds the :class:`Params` of terrain ``name`` with the env's vehicle, internal
    resistance model and effects. ``grounds`` stacks them on a leading axis of K terrains. The paths are
    the union of the terrains' default ranges, then :data:`GROUND`; a path that a terrain does not
    randomise is pinned at that terrain's value.
    """
    if set(spec) != {"grounds"}:
        raise ConfigError(f"domain randomisation: a ground mixture takes the key 'grounds' only, got {sorted(spec)}")
    names = spec["grounds"]
    if isinstance(names, str) or not isinstance(names, (list, tuple)) or not names:
        raise ConfigError(f"domain randomisation: 'grounds' must be a non-empty list of terrain names, got {names!r}")
    if len(set(names)) != len(names):
        raise ConfigError(f"domain randomisation: 'grounds' lists a terrain twice: {list(names)}")
    loaded = []
    for name in names:
        if not isinstance(name, str):
            raise ConfigError(f"domain randomisation: 'grounds' entries are terrain names, got {name!r}")
        try:
            loaded.append(load(name))
        except ConfigError as exc:
            raise ConfigError(f"domain randomisation: 'grounds': {exc}") from None
    structure = {jax.tree_util.tree_structure(p) for p in loaded}
    if len(structure) > 1:
        raise ConfigError(f"domain randomisation: the terrains of 'grounds' {list(names)} differ in structure (shear "
                          f"law {[p.terrain.shear_law for p in loaded]} or effects), so they cannot share one program")
    boxes = [default_ranges(p) for p in loaded]
    paths = tuple(dict.fromkeys(k for box in boxes for k in box))
    low = np.zeros((len(loaded), len(paths)), np.float32)
    high = np.zeros_like(low)
    for g, (p, box) in enumerate(zip(loaded, boxes, strict=True)):
        for n, path in enumerate(paths):
            value = float(_leaf(p, path))
            low[g, n], high[g, n] = box.get(path, (value, value))
    grounds = jax.tree_util.tree_map(lambda *leaves: jnp.stack(leaves), *loaded)
    return (*paths, GROUND), low, high, grounds


def resolve(params: Params, spec: Any) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """``domain_randomization`` option -> (paths, low, high), validated (a ground mixture: :func:`resolve_grounds`)."""
    if spec is None or spec is False:
        return (), np.zeros(0, np.float32), np.zeros(0, np.float32)
    if spec is True:
        spec = default_ranges(params)
    if not isinstance(spec, dict):
        raise ConfigError(f"domain_randomization must be True, False, a dict of ranges or {{'grounds': [...]}}, "
                          f"got {spec!r}")
    paths, lows, highs = [], [], []
    for path, rng in spec.items():
        leaf = _leaf(params, path)
        if leaf.ndim != 0:
            raise ConfigError(f"domain randomisation: parameter '{path}' is not a scalar")
        if isinstance(rng, (int, float)) and not isinstance(rng, bool):
            lo = hi = float(rng)
        else:
            try:
                lo, hi = (float(v) for v in rng)
            except (TypeError, ValueError):
                raise ConfigError(f"domain randomisation: range for '{path}' must be (low, high), got {rng!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
            raise ConfigError(f"domain randomisation: range for '{path}' = ({fmt_num(lo)}, {fmt_num(hi)}) needs "
                              "finite low <= high")
        _check_bounds(params, path, lo, hi)
        paths.append(path)
        lows.append(lo)
        highs.append(hi)
    return tuple(paths), np.asarray(lows, np.float32), np.asarray(highs, np.float32)


def _check_bounds(params: Params, path: str, lo: float, hi: float) -> None:
    """Both ends of a range inside the parameter's physical bounds (the params bounds table, or an effect's)."""
    parts = path.split(".")
    if parts[0] == "effects" and len(parts) == 3:
        eff = params.effects[int(parts[1])]
        b = type(eff).bounds.get(parts[2])
        if b is not None and not (b[0] <= lo and hi <= b[1]):
            raise ConfigError(f"domain randomisation: range ({fmt_num(lo)}, {fmt_num(hi)}) of '{path}' leaves the "
                              f"bounds [{fmt_num(b[0])}, {fmt_num(b[1])}] of effect {eff.id!r}")
        return
    try:
        check_range(path, lo, hi)
    except ConfigError as exc:
        raise ConfigError(f"domain randomisation: {exc}") from None


def sample(params: Params, key, paths: tuple[str, ...], low, high, grounds: Params | None = None
           ) -> tuple[Params, jax.Array]:
    """Draw one parameter set; returns the new params and the sampled values (n,).

    With ``grounds`` (a ground mixture, :func:`resolve_grounds`) one terrain is drawn first: the params
    become that terrain's, ``low``/``high`` its row, and the last value its index.
    """
    if not paths:
        return params, jnp.zeros((0,), jnp.float32)
    if grounds is not None:
        k_ground, key = jax.random.split(key)
        g = jax.random.randint(k_ground, (), 0, low.shape[0])
        params = jax.tree_util.tree_map(lambda leaf: leaf[g], grounds)
        values = _draw(key, paths[:-1], low[g], high[g])
        params = _apply(params, paths[:-1], values)
        return params, jnp.concatenate([values, g.astype(values.dtype)[None]])
    values = _draw(key, paths, low, high)
    return _apply(params, paths, values), values


def _draw(key, paths, low, high):
    u = jax.random.uniform(key, (len(paths),), jnp.float32)
    return low + u * (high - low)


def _apply(params: Params, paths, values) -> Params:
    for i, path in enumerate(paths):
        where = _getter(path)
        old = where(params)
        params = eqx.tree_at(where, params, values[i].astype(old.dtype))
    return params
