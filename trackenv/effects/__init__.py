"""Unmodelled effects (MODEL.md §8) that extend the base model through :class:`Effect`."""

from .base import Effect, effect_ids

__all__ = ["Effect", "effect_ids"]
