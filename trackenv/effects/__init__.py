"""Unmodelled effects (docs/model.md §8) that extend the base model through :class:`Effect`.

``EFFECTS`` maps each canonical id to its class; ``get_effect(id, **params)`` builds one with its
calibrated defaults, overriding parameters by keyword (checked against the class's ``bounds``).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from .base import Effect, effect_ids
from .grouser_stiction import GrouserStiction
from .internal_resistance import InternalResistance
from .lateral_friction_radius import LateralFrictionRadius
from .pitch_load_transfer import PitchLoadTransfer
from .sensor_artifacts import SensorArtifacts
from .slip_sinkage import SlipSinkage

EFFECTS: dict[str, type[Effect]] = {
    cls.id: cls
    for cls in (SlipSinkage, LateralFrictionRadius, InternalResistance, GrouserStiction, PitchLoadTransfer,
                SensorArtifacts)
}
EFFECT_IDS: tuple[str, ...] = tuple(EFFECTS)


def get_effect(effect_id: str, dtype=jnp.float32, **params) -> Effect:
    """The effect ``effect_id`` with default parameters, overridden by ``params`` (validated against ``bounds``
    by the effect's constructor, :meth:`Effect.check_bounds`)."""
    if not isinstance(effect_id, str) or effect_id not in EFFECTS:
        raise ValueError(f"unknown effect id {effect_id!r}; known ids: {', '.join(EFFECT_IDS)}")
    cls = EFFECTS[effect_id]
    effect = cls.default(dtype=dtype)
    if not params:
        return effect
    fields = {f.name: getattr(effect, f.name) for f in dataclasses.fields(effect)}
    for key, value in params.items():
        if key not in fields:
            raise ValueError(f"effect {effect_id!r} has no parameter {key!r}; parameters: {', '.join(fields)}")
        if key in cls.bounds:
            try:
                fields[key] = jnp.asarray(value, dtype)
            except (TypeError, ValueError):
                raise ValueError(f"effect {effect_id!r}: parameter {key!r} must be a number, got {value!r}") from None
        else:
            fields[key] = value  # static choices (e.g. sensor_artifacts.rectify)
    return cls(**fields)


__all__ = ["resolve_effects", "Effect", "effect_ids", "EFFECTS", "EFFECT_IDS", "get_effect", "SlipSinkage", "LateralFrictionRadius",
           "InternalResistance", "GrouserStiction", "PitchLoadTransfer", "SensorArtifacts"]


def resolve_effects(effects, dtype=jnp.float32) -> tuple:
    """Effect ids (docs/model.md §8) or :class:`Effect` modules -> a tuple of modules for ``load_params``.

    Ids get their default parameters in ``dtype`` (:func:`get_effect`); an unknown id raises ``ValueError``
    listing the known ones; anything that is neither raises ``TypeError``. A single id or module may be
    given without a list (``effects="slip_sinkage"`` is ``("slip_sinkage",)``).
    """
    if isinstance(effects, (str, Effect)):
        effects = (effects,)
    out = []
    for e in tuple(effects or ()):
        if isinstance(e, str):
            out.append(get_effect(e, dtype))
        elif isinstance(e, Effect):
            out.append(e)
        else:
            raise TypeError(f"effects must be docs/model.md §8 ids or Effect modules, got {e!r}")
    effect_ids(out)
    return tuple(out)
