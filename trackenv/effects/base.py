"""The extension point for unmodelled effects (docs/model.md §8).

An effect is an :class:`equinox.Module` whose fields are its parameters (array leaves: batchable and
differentiable) and whose class attribute ``id`` is its canonical id. It joins a simulation through
``Params.effects`` and can, without editing the base model:

- add **states** (``initial_state`` + ``state_rate``), integrated by RK4 with the vehicle's states and
  stored in ``State.extra[id]``;
- modify the **normal loads** (``normal_loads``), e.g. pitch load transfer;
- modify or add **forces and torques** (``forces``): replace the element forces, add body forces, a
  yaw moment or resisting sprocket torques, change the internal-resistance torque;
- transform the **instrument channels** (``instruments``) after the simulation, e.g. encoder averaging,
  a rectifying ammeter, gyro bias.

Every hook has a do-nothing default, so an effect overrides only what it changes. Hooks receive a
:class:`trackenv.physics.model.Context` (params, state, voltage, contact kinematics, number of batch
axes) and must be pure ``jax.numpy`` functions of it: effects then work under jit, vmap and grad.
Forces are the fields of :class:`trackenv.physics.contact.ContactForces` (SI, body frame; arrays carry
the trailing batch shape). Energy: forces added through ``body_x/body_y/body_yaw/sprocket`` are booked
as ``external`` in :func:`trackenv.physics.model.power_balance`.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import numpy as np


class Effect(eqx.Module):
    """Base class of effects. Subclasses set ``id`` and override the hooks they need."""

    id: ClassVar[str] = "effect"
    bounds: ClassVar[dict] = {}  # parameter name -> (low, high), inclusive, SI

    def __check_init__(self):
        self.check_bounds()

    def check_bounds(self) -> None:
        """Every concrete parameter inside ``bounds`` and finite; ``ValueError`` naming effect and parameter.

        Runs whenever an effect is constructed (``__check_init__``); traced values (inside ``jit``,
        ``vmap``, ``grad``) are not checked.
        """
        for name, (lo, hi) in type(self).bounds.items():
            value = getattr(self, name, None)
            if value is None or isinstance(value, jax.core.Tracer):
                continue
            try:
                v = np.asarray(value, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise ValueError(f"effect {self.id!r}: parameter {name!r} must be a number, got {value!r}") from None
            # compared in the leaf's own precision: float32(0.1) is not above a bound of 0.1
            own = np.asarray(value).dtype
            prec = own if np.issubdtype(own, np.floating) else np.float64
            c = v.astype(prec)
            bad = ~np.isfinite(v) | (c < np.asarray(lo, prec)) | (c > np.asarray(hi, prec))
            if bad.any():
                x = float(v[np.flatnonzero(bad)[0]])
                raise ValueError(f"effect {self.id!r}: parameter {name!r} = {x:.10g} out of bounds "
                                 f"[{lo:.10g}, {hi:.10g}]")

    def initial_state(self, params, batch_shape: tuple):
        """Initial extra state (a pytree of arrays with trailing ``batch_shape``), or ``None``."""
        return None

    def state_rate(self, ctx, forces):
        """Time derivative of this effect's extra state ``ctx.state.extra[self.id]``."""
        return None

    def normal_loads(self, ctx, normal):
        """Return modified element normal forces [N], shape (2, N, *b)."""
        return normal

    def forces(self, ctx, forces, tau_int):
        """Return ``(forces, tau_int)``: modified contact forces and internal-resistance torque [N m]."""
        return forces, tau_int

    def instruments(self, channels: dict, t, params) -> dict:
        """Return transformed instrument channels; each (T, *b), ``t`` (T,) [s]."""
        return channels


def effect_ids(effects) -> tuple[str, ...]:
    """The ids of a tuple of effects (checked unique)."""
    ids = tuple(e.id for e in effects)
    if len(set(ids)) != len(ids):
        raise ValueError(f"each effect may appear once, got {ids}")
    return ids
