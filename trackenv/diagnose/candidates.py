"""The candidate explanations of a gap, each a family of models with a few fitted parameters.

A candidate is the base model plus one docs/model.md §8 effect whose *identifying* parameters are fitted
(the others keep the library's calibrated defaults), or the control ``recalibrate_base`` (no effect;
the uncertain base parameters b*_int, c, φ, K are fitted: the gap that mere tuning closes), or
``none`` (the base model as is). Parameters are searched in a unit cube: each maps to its physical
range linearly or logarithmically (``ParamSpec``). Every candidate contains (a point close to) the base
model — its ``anchor`` — so a fit can only match or improve on ``none`` in-sample; whether it improves
*out of sample* is what the diagnosis measures.

An effect is normally fitted *on top of* the control (:meth:`Candidate.standing_on`): its base model is
the base with the control's factors as fitted on the same fold, or the base itself, whichever branch
fits the fold's calibration data better (:func:`.fit.fit_candidate`; the control can absorb part of a
strong effect with the wrong physics, and the effect must not inherit that). The effect's family then
contains the fitted control (its anchor, :meth:`Candidate.anchor_unit`), so "the effect beats the
control" compares nested models, and a small perturbation of the soil or of b*_int, which the control
absorbs, is not credited to the effect.

Ranges are the physically plausible ones (the effect classes' ``bounds`` are wider, for users):

- ``slip_sinkage``: k_s 0.02-3 1/m, k_b 0.05-5, z_max 0.01-0.1 m (γ, v_s: defaults);
- ``lateral_friction_radius``: μ_max 0.1-1.5, b 0.01-3 1/m, μ_min 0-0.6 (a = 0.925, Wong & Chiang), and
  the law's share of the lateral forces, blend 0-1 (the rest from the shear law: blend = 0 is the base model
  exactly, whatever the terrain; a law alone with fixed μ values is close to the base on no terrain);
- ``internal_resistance``: a monotone function of |ω| (:class:`KnotInternalResistance`):
  τ = sign(ω) · (b0 + s1·min(|ω|, 3) + s2·clip(|ω| − 3, 0, 9) + s3·max(|ω| − 12, 0)) with knots at 3 and
  12 rad/s (0.27 and 1.07 m/s of belt speed); b0 = f0 · b*_int(terrain) with f0 0-3 (f0 scales each terrain's
  Table 5.4 value so one fit serves tests on several terrains; for a vehicle that sets no internal resistance
  of its own, e.g. ``husky``, the reference is its drive's ``stiction_torque``), slopes s1 0-0.5, s2, s3 0-0.2 N m s/rad.
  The family holds the constant law (slopes 0), the viscous one (b0 = 0, equal slopes), speed-linear and
  convex (quadratic-like) or concave (a low-speed knee, tanh-like) laws;
- ``grouser_stiction``: M0 0.5-30 N m, r_fade 0.1-5 rad/s, F0 0-60 N, and the elements' lateral Stribeck
  amplification β 0-1.5 fading over v_e 0.02-0.5 m/s (a body-level and an element-level form of the same
  breakaway, fitted together);
- ``pitch_load_transfer``: height factor 0-3, τ 0.01-0.5 s;
- ``sensor_artifacts``: encoder window 0-1 s, gyro bias ±0.2 rad/s and scale factor ±0.3, ammeter zero
  offsets ±1.5 A per channel (ripple is not fitted: a ripple is indistinguishable from noise in an RMS
  comparison; rectification comes from meta.json);
- ``recalibrate_base``: factors on b*_int (and b_int; on the drive's stiction torque for a vehicle without
  internal resistance) 0.7-1.4, c 0.5-2, φ 0.9-1.1, K 0.5-2 (the
  plausible uncertainty of measured soil values; wider ranges let four parameters chase the noise of
  the calibration tests and lose out of sample, which would blunt the control).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..effects import get_effect
from ..effects.base import Effect
from ..physics.motor import OMEGA_SMOOTHING
from ..physics.terramechanics import smoothsign

IR_KNOTS = (3.0, 12.0)  # rad/s, knots of the internal-resistance family


class KnotInternalResistance(Effect):
    """``internal_resistance`` as a monotone piecewise-linear function of |ω| (knots ``IR_KNOTS``), replacing tau_int."""

    id = "internal_resistance"
    b0: jax.Array
    s1: jax.Array
    s2: jax.Array
    s3: jax.Array

    def torque(self, omega):
        a = jnp.sqrt(omega * omega + OMEGA_SMOOTHING**2) - OMEGA_SMOOTHING
        k1, k2 = IR_KNOTS
        g = (self.b0 + self.s1 * jnp.minimum(a, k1) + self.s2 * jnp.clip(a - k1, 0.0, k2 - k1)
             + self.s3 * jnp.maximum(a - k2, 0.0))
        return smoothsign(omega, OMEGA_SMOOTHING) * g

    def forces(self, ctx, forces, tau_int):
        return forces, self.torque(ctx.state.omega)

NONE = "none"
RECALIBRATE = "recalibrate_base"
ON = "on."  # prefix of the values of the candidate an effect stands on (:attr:`Candidate.on`)
# the parameter leaves the control's factors scale (:meth:`Candidate.apply`)
RECALIBRATE_LEAVES = frozenset({"terrain.cohesion", "terrain.friction_angle", "terrain.shear_modulus",
                                "internal.constant", "internal.viscous", "vehicle.stiction_torque"})
ON_BASE = "@base"  # suffix of the fit of an effect on the base model itself, beside its fit on the control


def effect_of(member: str) -> str:
    """The effect a fitted member is a form of (``"internal_resistance@base"`` -> ``"internal_resistance"``)."""
    return member[: -len(ON_BASE)] if member.endswith(ON_BASE) else member


@dataclass(frozen=True)
class ParamSpec:
    """A fitted parameter's range [lo, hi] and its map from the unit interval: linear, logarithmic (``log``), or,
    with ``log`` and a ``knee``, logarithmic above the knee and linear below it, so that the range can start at
    zero: x = lo + knee · (exp(u · ln(1 + (hi − lo)/knee)) − 1)."""

    name: str
    lo: float
    hi: float
    log: bool = False
    unit: str = ""
    knee: float | None = None

    def __post_init__(self):
        if self.knee is not None and not (self.log and self.knee > 0):
            raise ValueError(f"{self.name}: a knee needs log=True and a positive value, got {self.knee!r}")

    @property
    def _log_span(self) -> float:
        return math.log1p((self.hi - self.lo) / self.knee)

    def _from_unit(self, u, xp):
        """The map from the unit interval with array module ``xp`` (numpy or jax.numpy)."""
        if self.knee is not None:
            return self.lo + self.knee * xp.expm1(u * self._log_span)
        if self.log:
            return xp.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        return self.lo + u * (self.hi - self.lo)

    def to_physical(self, u):
        return self._from_unit(np.clip(np.asarray(u, np.float64), 0.0, 1.0), np)

    def to_physical_jnp(self, u):
        """:meth:`to_physical` in jax (traceable; ``u`` already in [0, 1])."""
        import jax.numpy as jnp  # noqa: PLC0415

        return self._from_unit(u, jnp)

    def to_unit(self, x):
        x = np.asarray(x, np.float64)
        if self.knee is not None:
            return np.clip(np.log1p(np.maximum(x - self.lo, 0.0) / self.knee) / self._log_span, 0.0, 1.0)
        if self.log:
            return np.clip((np.log(x) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo)), 0.0, 1.0)
        return np.clip((x - self.lo) / (self.hi - self.lo), 0.0, 1.0)


@dataclass(frozen=True)
class Candidate:
    """A candidate explanation: ``name`` (effect id, ``recalibrate_base`` or ``none``) and its fitted parameters."""

    name: str
    specs: tuple
    anchor: dict  # physical values of the point closest to the base model
    description: str
    on: Candidate | None = None  # fitted first; its per-fold values (keys prefixed ``ON``) form this one's base

    def standing_on(self, below: Candidate) -> Candidate:
        """This candidate fitted on top of ``below``'s fitted parameters (the values of a batch then carry
        ``below``'s parameters under ``ON``-prefixed keys, one set per fold: :mod:`.fit`)."""
        return dataclasses.replace(self, on=below)

    def split_values(self, values: dict) -> tuple[dict, dict]:
        """(own values, the ``on`` candidate's values with the prefix removed)."""
        own = {k: v for k, v in values.items() if not k.startswith(ON)}
        below = {k[len(ON):]: v for k, v in values.items() if k.startswith(ON)}
        return own, below

    @property
    def n_params(self) -> int:
        return len(self.specs)

    @property
    def encoder_layer(self) -> bool:
        """True if the fit also selects an encoder averaging window (:mod:`.fit`)."""
        return self.name not in (NONE, RECALIBRATE, "sensor_artifacts")

    @property
    def instrument_only(self) -> bool:
        """True if the candidate changes only the instruments (no new simulation needed)."""
        return self.name == "sensor_artifacts"

    def applicable(self, terrains_deformable: list[bool]) -> str | None:
        """None if the candidate can act on these tests, else why not (it would equal the base model)."""
        if self.name == "slip_sinkage" and not any(terrains_deformable):
            return "acts on deformable ground only; every test is on hard ground"
        if self.name == "grouser_stiction" and all(terrains_deformable):
            return "acts on hard ground only; every test is on deformable ground"
        return None

    @property
    def varied_leaves(self) -> frozenset[str]:
        """Paths of the base parameters this candidate's values scale per vehicle (the control's factors, here or
        in the candidate it stands on). Its simulations keep them arrays even where the values coincide
        (:func:`trackenv.simulate.shared_leaves_as_scalars`: asphalt's cohesion is zero whatever the factor),
        so that one compiled program serves every terrain."""
        own = RECALIBRATE_LEAVES if self.name == RECALIBRATE else frozenset()
        return own | (self.on.varied_leaves if self.on is not None else frozenset())

    @property
    def is_effect(self) -> bool:
        return self.name not in (NONE, RECALIBRATE)

    def physical(self, unit: np.ndarray) -> dict:
        """(S, p) unit-cube points -> {name: (S,) physical values}."""
        unit = np.atleast_2d(unit)
        return {s.name: s.to_physical(unit[:, k]) for k, s in enumerate(self.specs)}

    def anchor_unit(self, below: dict | None = None) -> np.ndarray:
        """Unit-cube anchor; with ``below`` (the ``on`` candidate's fitted values), the point of this family
        closest to that fitted model (the internal-resistance family absorbs ``recalibrate_base``'s factor on
        b*_int, since it replaces the base law)."""
        anchor = dict(self.anchor)
        if below and self.name == "internal_resistance" and "internal_resistance_factor" in below:
            k = float(below["internal_resistance_factor"])
            anchor = {n: v * k for n, v in anchor.items()}
        return np.array([s.to_unit(anchor[s.name]) for s in self.specs], np.float64)

    def apply(self, base, values: dict, ref: dict):
        """Params for a batch: ``base`` has (B,) leaves; ``values`` {name: (B,)}; ``ref`` per-vehicle references.
        An effect is added to the effects ``base`` already carries (a fit named by an earlier diagnosis, :class:`NamedFit`).

        ``ref["b_int_constant"]``: (B,) each vehicle's terrain b*_int (Table 5.4), used by ``internal_resistance``.
        """
        dtype = base.dtype
        f = lambda x: jnp.asarray(x, dtype)  # noqa: E731
        if self.on is not None:
            values, below = self.split_values(values)
            base = self.on.apply(base, below, ref)
        if self.name == NONE:
            return base
        if self.name == RECALIBRATE:
            ter, itr = base.terrain, base.internal
            ter = dataclasses.replace(ter, cohesion=ter.cohesion * f(values["cohesion_factor"]),
                                      friction_angle=ter.friction_angle * f(values["friction_angle_factor"]),
                                      shear_modulus=ter.shear_modulus * f(values["shear_modulus_factor"]))
            k = f(values["internal_resistance_factor"])
            itr = dataclasses.replace(itr, constant=itr.constant * k, viscous=itr.viscous * k)
            # a vehicle without internal resistance of its own (both zero): its drive's stiction is the torque
            veh = base.vehicle
            no_int = (base.internal.constant == 0) & (base.internal.viscous == 0)
            veh = dataclasses.replace(veh, stiction_torque=veh.stiction_torque * jnp.where(no_int, k, 1.0))
            return dataclasses.replace(base, terrain=ter, internal=itr, vehicle=veh)
        B = np.shape(next(iter(values.values())))[0]
        if self.name == "internal_resistance":
            return dataclasses.replace(base, effects=base.effects + (KnotInternalResistance(
                b0=f(values["b0_factor"] * ref["b_int_constant"]), s1=f(values["s1"]), s2=f(values["s2"]),
                s3=f(values["s3"])),))
        eff = get_effect(self.name, dtype=dtype)
        fields = {}
        for fl in dataclasses.fields(eff):
            v = getattr(eff, fl.name)
            fields[fl.name] = jnp.broadcast_to(v, (B,)) if eqx.is_array(v) else v
        for k, v in values.items():
            fields[k] = f(v)
        if self.name == "sensor_artifacts":
            fields["ripple_amplitude"] = jnp.zeros((B,), dtype)
            fields["rectify"] = False
        return dataclasses.replace(base, effects=base.effects + (type(eff)(**fields),))


def candidate_set(internal_resistance: str = "constant") -> list[Candidate]:
    """The candidates of a diagnosis (effects in docs/model.md §8 order, then the control, then ``none``)."""
    viscous = internal_resistance == "viscous"
    return [
        Candidate("slip_sinkage", (ParamSpec("sinkage_rate", 0.02, 3.0, True, "1/m"),
                                   ParamSpec("bulldozing_factor", 0.05, 5.0, True, "-"),
                                   ParamSpec("max_sinkage", 0.01, 0.1, False, "m")),
                  {"sinkage_rate": 0.02, "bulldozing_factor": 0.05, "max_sinkage": 0.01},
                  "slip-induced sinkage with bulldozing of the displaced soil (deformable ground)"),
        Candidate("lateral_friction_radius", (ParamSpec("mu_max", 0.1, 1.5, True, "-"),
                                              ParamSpec("b", 0.01, 3.0, True, "1/m"),
                                              ParamSpec("mu_min", 0.0, 0.6, False, "-"),
                                              ParamSpec("blend", 0.0, 1.0, False, "-")),
                  {"mu_max": 0.53, "b": 0.15, "mu_min": 0.0, "blend": 0.0},
                  "lateral coefficient mu_t(R) = mu_min + mu_max/(a + bR), blended with the shear law sideways "
                  "(blend 1: the law alone, 0: the base model)"),
        Candidate("internal_resistance", (ParamSpec("b0_factor", 0.0, 3.0, False, "x b*_int"),
                                          ParamSpec("s1", 0.0, 0.5, False, "N m s/rad"),
                                          ParamSpec("s2", 0.0, 0.2, False, "N m s/rad"),
                                          ParamSpec("s3", 0.0, 0.2, False, "N m s/rad")),
                  {"b0_factor": 0.0 if viscous else 1.0, "s1": 0.076 if viscous else 0.0,
                   "s2": 0.076 if viscous else 0.0, "s3": 0.076 if viscous else 0.0},
                  "internal track resistance, a monotone piecewise-linear function of |omega| (knots 3, 12 rad/s): "
                  "constant / viscous / convex / knee-shaped laws"),
        Candidate("grouser_stiction", (ParamSpec("yaw_moment", 0.0, 30.0, True, "N m", knee=0.5),
                                       ParamSpec("yaw_fade", 0.1, 5.0, True, "rad/s"),
                                       ParamSpec("force", 0.0, 60.0, False, "N"),
                                       ParamSpec("lateral_gain", 0.0, 1.5, False, "-"),
                                       ParamSpec("lateral_slide_speed", 0.02, 0.5, True, "m/s")),
                  {"yaw_moment": 0.0, "yaw_fade": 1.5, "force": 0.0, "lateral_gain": 0.0, "lateral_slide_speed": 0.1},
                  "breakaway resistance of grousers on hard ground: a yaw moment and force fading with yaw/forward "
                  "speed, and the elements' lateral force amplified while they slide slowly"),
        Candidate("pitch_load_transfer", (ParamSpec("height_factor", 0.0, 3.0, False, "x cg height"),
                                          ParamSpec("time_constant", 0.01, 0.5, True, "s")),
                  {"height_factor": 0.0, "time_constant": 0.05},
                  "longitudinal load transfer during acceleration and braking"),
        Candidate("sensor_artifacts", (ParamSpec("window", 0.0, 1.0, False, "s"),
                                       ParamSpec("gyro_bias", -0.2, 0.2, False, "rad/s"),
                                       ParamSpec("gyro_scale", -0.3, 0.3, False, "-"),
                                       ParamSpec("current_offset_left", -1.5, 1.5, False, "A"),
                                       ParamSpec("current_offset_right", -1.5, 1.5, False, "A")),
                  {"window": 0.0, "gyro_bias": 0.0, "gyro_scale": 0.0, "current_offset_left": 0.0,
                   "current_offset_right": 0.0},
                  "encoder averaging window, gyro bias and scale factor, ammeter zero offsets"),
        Candidate(RECALIBRATE, (ParamSpec("internal_resistance_factor", 0.7, 1.4, True, "-"),
                                ParamSpec("cohesion_factor", 0.5, 2.0, True, "-"),
                                ParamSpec("friction_angle_factor", 0.9, 1.1, True, "-"),
                                ParamSpec("shear_modulus_factor", 0.5, 2.0, True, "-")),
                  {"internal_resistance_factor": 1.0, "cohesion_factor": 1.0, "friction_angle_factor": 1.0,
                   "shear_modulus_factor": 1.0},
                  "control: refit the uncertain base parameters b*_int, c, phi, K (no new physics)"),
        Candidate(NONE, (), {}, "the base model as is"),
    ]


@dataclass(frozen=True)
class NamedFit:
    """A fit that an earlier diagnosis named, carried into the base model of the next (``diagnose(after=...)``).

    ``member`` is the fit's name in that report (``"slip_sinkage@base"``, ``"internal_resistance"`` ...),
    ``candidate`` its family (standing on the control where ``values`` holds the control's factors under
    ``ON``-prefixed keys), ``values`` {name: physical value} of its fit on all the data, ``source`` the report,
    ``encoder_window`` [s] the encoder averaging window that fit selected (its instrument layer, carried as a
    window-only ``sensor_artifacts``; the candidates of the next diagnosis may add a window of their own on top).
    """

    member: str
    candidate: Candidate
    values: dict
    source: str
    encoder_window: float = 0.0

    @property
    def effect(self) -> str:
        return effect_of(self.member)

    def apply(self, base, ref: dict):
        """``base`` (leaves (B,)) with this fit added: the control's factors and the effect at its fitted values."""
        B = int(np.shape(base.vehicle.mass)[0])
        full = lambda values: {k: np.full(B, v, np.float64) for k, v in values.items()}  # noqa: E731
        base = self.candidate.apply(base, full(self.values), ref)
        if self.encoder_window > 0:
            window_only = {"window": self.encoder_window, "gyro_bias": 0.0, "gyro_scale": 0.0,
                           "current_offset_left": 0.0, "current_offset_right": 0.0}
            base = _SENSOR_FAMILY.apply(base, full(window_only), ref)
        return base

    def to_json(self) -> dict:
        return {"fit": self.member, "effect": self.effect, "report": self.source,
                "params": {k: float(v) for k, v in self.values.items()}, "encoder_window": self.encoder_window}


def named_fits_from_report(path, internal_resistance: str) -> tuple[NamedFit, ...]:
    """The fits an earlier diagnosis's ``report.json`` adds to the base model: the ones its own base carried
    (``base_model.after``), then the fit it named. Raises :class:`.data.DiagnosisError` naming the file where it
    cannot be read, names no effect, or was made on another base model (``internal_resistance``)."""
    import json
    from pathlib import Path

    from .data import DiagnosisError

    path = Path(path)
    if path.is_dir():
        path = path / "report.json"
    try:
        rep = json.loads(path.read_text())
    except FileNotFoundError:
        raise DiagnosisError(f"{path}: no such report (after= needs the report.json of an earlier diagnosis)") from None
    except (OSError, ValueError) as exc:
        raise DiagnosisError(f"{path}: not a readable diagnosis report ({exc})") from None
    if isinstance(rep, dict) and rep.get("mode") == "each terrain":
        raise DiagnosisError(f"{path}: a summary of one diagnosis per terrain; continue it with one diagnosis per "
                             "terrain (trackenv diagnose --terrains each or auto, diagnose_each_terrain: each terrain "
                             "starts from the fit its own diagnosis named), or pass one terrain's report.json from "
                             "its sub-folder")
    try:
        verdict, ranking, base_model = rep["verdict"], rep["ranking"], rep["base_model"]
        named, member = verdict["effect"], verdict.get("after_model") or verdict["effect"]
    except (KeyError, TypeError):
        raise DiagnosisError(f"{path}: not a trackenv diagnosis report (no verdict, ranking and base_model)") from None
    if base_model.get("internal_resistance") != internal_resistance:
        raise DiagnosisError(f"{path}: that diagnosis used the {base_model.get('internal_resistance')!r} internal "
                             f"resistance as base, this one {internal_resistance!r}: use the same base model")
    if named in (None, NONE, RECALIBRATE):
        raise DiagnosisError(f"{path}: its verdict names no effect ({named!r}), so there is no fit to add to the base "
                             "model")
    entry = next((r for r in ranking if r.get("effect") == member), None)
    if entry is None or not isinstance(entry.get("params"), dict):
        raise DiagnosisError(f"{path}: the named fit {member!r} has no parameters in the ranking")
    cands = {c.name: c for c in candidate_set(internal_resistance)}
    cand = cands[effect_of(member)]
    own = {sp.name: entry["params"].get(sp.name) for sp in cand.specs}
    below = {k.split(".", 1)[1]: v for k, v in entry["params"].items() if k.startswith(RECALIBRATE + ".")}
    values = dict(own) | {ON + k: v for k, v in below.items()}
    bad = [k for k, v in values.items() if not (isinstance(v, (int, float)) and math.isfinite(v))]
    if bad:
        raise DiagnosisError(f"{path}: the named fit {member!r} lacks a finite value for {', '.join(bad)}")
    if below:
        cand = cand.standing_on(cands[RECALIBRATE])
    earlier = []
    try:
        window = float(entry["params"].get("encoder_window") or 0.0)
        for e in base_model.get("after") or []:
            c = cands[e["effect"]]
            vals = {k: float(v) for k, v in e["params"].items()}
            if any(k.startswith(ON) for k in vals):
                c = c.standing_on(cands[RECALIBRATE])
            earlier.append(NamedFit(e["fit"], c, vals, e["report"], float(e.get("encoder_window") or 0.0)))
    except (KeyError, TypeError, ValueError, AttributeError):
        raise DiagnosisError(f"{path}: base_model.after or the encoder window of the named fit is not as a trackenv "
                             "diagnosis writes it") from None
    return (*earlier, NamedFit(member, cand, values, str(path), window))


_SENSOR_FAMILY = next(c for c in candidate_set() if c.name == "sensor_artifacts")
