"""Blind benchmark generator for ``trackenv diagnose`` (sim-to-real gap diagnosis, docs/model.md §8-9).

    from trackenv.diagnose.blind import make_cases
    truth = make_cases("out/blind", n=28, seed=0)      # out/blind/cases/case_000/test_00/{log.csv,meta.json}
                                                       # out/blind/answers.json (the answer key)

A gap diagnosis names which unmodelled effect (one of the six canonical ids of docs/model.md §8, or
``none``) explains the difference between field logs and the base model. Checking it on logs made
with the *candidate library itself* (``trackenv/effects``) would only show that the library can find
its own functional forms. The cases written here therefore carry an effect of each canonical kind in
a DIFFERENT functional form or parameterisation, taken from other literature (one class per label
below; each docstring gives the force law, its source and how it differs from the library):

================================ ========================================================================
label (docs/model.md §8)              alternative form used here
================================ ========================================================================
``slip_sinkage``                 Lyasko's slip-sinkage relation z = z_ref((1+i)/(1-0.5i) - 1) reached by a
                                 first-order lag; Bekker compaction resistance of the extra sinkage on
                                 the track front + a yaw moment ∝ sinkage × weight (library: Rankine
                                 bulldozing q(z), dz/dt = k_s S (1 - z/z_max))
``lateral_friction_radius``      μ_t(R) = μ_min + (μ_max - μ_min) exp(-R/R0), tanh sign (library:
                                 μ_max/(a + bR), STEP5 sign)
``internal_resistance``          τ = b0 tanh(ω/ω0) + b2 ω|ω| (library: b0 smoothsign + b1 ω)
``grouser_stiction``             Gaussian Stribeck amplification of each element's lateral shear force,
                                 1 + β exp(-(v_y/v_s)²) (library: body yaw moment with exp(-|r|/r_fade))
``pitch_load_transfer``          2nd-order pitch (spring-damper) state of the transferred moment, spread
                                 with a power-law weight |x|^q toward the track ends (library: 1st-order
                                 filtered a_x, Winkler-linear pressure gradient)
``sensor_artifacts``             random subset of: 1st-order low-pass on the encoder speed, gyro bias +
                                 scale-factor error, ammeter offsets (library: moving-average window;
                                 its gyro bias + scale and ammeter offsets have the same form)
================================ ========================================================================

Every case also carries nuisance that a diagnosis must not mistake for an effect (null cases too):
±3 % perturbations of the terrain's cohesion, friction angle, shear modulus and of the internal
resistance constant; a random log rate (20, 50, 100 Hz); random Gaussian noise levels; an
``absolute`` (|i|) or ``signed`` ammeter; sometimes pose columns; sometimes a few empty cells.

Sampled effect parameters are checked before a case is written: the case is simulated with and without
the effect (same nuisance, noise-free) and parameters are redrawn until (a) at least one signal of one
test differs by more than ``VISIBILITY_MIN`` × its noise σ (after a 0.25 s moving average, while the
vehicle is driven, i.e. up to the end of the release ramp) and (b) the vehicle still moves in every test
(peak |u| or |r| at least ``MOBILITY_MIN`` of the effect-free run). After three failed draws the
maneuvers are redrawn as well. The resulting "visibility" is part of the answer key.

A case drawn *near the detection limit* (``near_limit``) wants a visibility inside ``NEAR_LIMIT`` (1-3 σ)
instead of above ``VISIBILITY_MIN``. If none of its draws lands there, the closest draw's amplitude is
scaled into the window (:func:`scaled`: the fields that ``neutral()`` sets to 0, or the ``gate`` that
blends an alternative law with the base model's), by a few secant steps on the visibility against the
factor, within [``MIN_SCALE``, ``MAX_SCALE``]; the factor is part of the answer key (``magnitude_scale``).
A case whose window lies outside those factors keeps its closest draw.

The answer key (label, effect class, parameters, nuisance, per-test details) is returned and stored
OUTSIDE the case folder; the case folder's ``meta.json`` files say the logs are synthetic but carry no
effect information.

Numerics: every simulation carries all six alternative effects, the inactive ones with neutral
parameters (``neutral()``: zero amplitude, or ``gate = 0`` for the two forms that replace a base-model
law), and the vehicles of a batch lie on the last axis of the voltage profile and of the parameters
(docs/model.md §6). One batch of ``N_COLS`` = 12 vehicles holds the case's (padded) tests twice: effect-free
and with the effect (or with two draws on a redraw). With the breakpoint arrays padded to a fixed length
every case runs the SAME compiled program (one compilation per process, ~10 s; then ~3-6 s per case on
a 2-core CPU). ``T_SIM`` = 15 s at output step 0.01 s and the default 0.5 ms substep; logs are cut to
each test's duration and decimated to its rate. Breakpoints are snapped to the test's sample grid so
that the logged voltages, linear between samples, reproduce the input exactly.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compare import stack_trees
from ..effects.base import Effect
from ..envs.tasks import MANEUVERS as TASK_MANEUVERS

__all__ = [
    "BLIND_EFFECTS",
    "LABELS",
    "MANEUVERS",
    "BlindSlipSinkage",
    "BlindLateralFriction",
    "BlindInternalResistance",
    "BlindGrouserStiction",
    "BlindPitchLoadTransfer",
    "BlindSensorArtifacts",
    "random_profile",
    "make_case",
    "make_cases",
    "effect_params",
    "balanced_labels",
    "CANONICAL_IDS",
    "SIGNALS",
]

GRAVITY = 9.81  # m/s^2
T_SIM = 15.0  # s, simulated duration of every batch (the longest test)
SIM_DT = 0.01  # s, output step of the simulation (100 Hz; 50 and 20 Hz logs are decimated)
K_PAD = 160  # breakpoints per batch after padding (fixed shapes: one compiled program for every case)
MAX_TESTS = 6
N_COLS = 2 * MAX_TESTS  # vehicles per batch: two sets of the (padded) tests, e.g. effect-free and with the effect
SAMPLE_RATES = (20, 50, 100)  # Hz
VISIBILITY_MIN = 4.0  # × noise σ, after a 0.25 s moving average
VISIBILITY_WINDOW = 0.25  # s
MOBILITY_MIN = 0.35
MAX_TRIES = 7  # effect parameter draws per case (at most)
DRAWS_PER_MANEUVERS = 3  # effect draws per draw of the maneuvers
V_MAX = 22.0  # V, |V| bound of the random profiles (bus 24 V)


def _f(v, dtype=jnp.float32):
    return jnp.asarray(v, dtype)


def _u(rng, lo, hi):
    return float(rng.uniform(lo, hi))


# ----------------------------------------------------------------------------------------------
# alternative effect forms


class BlindSlipSinkage(Effect):
    """Slip sinkage after Lyasko with Bekker compaction of the extra sinkage and a sinkage yaw moment.

    Source: Lyasko, "Slip sinkage effect in soil-vehicle mechanics", J. Terramechanics 47 (2010) 21-31:
    the total sinkage grows with the slip ratio i as z = z_0 (1 + i)/(1 - 0.5 i). Here the extra (slip)
    sinkage of track k has the target

        z_t,k = z_ref · ((1 + i_k)/(1 - 0.5 i_k) - 1)                        [m]
        i_k   = min(S_k / max(|V_t,k|, v_eps), 1),  S_k = sqrt(s_k² + ⟨v_y,k,i²⟩ + ε²) - ε

    (s_k the longitudinal slip velocity, ⟨v_y²⟩ the mean squared lateral sliding speed of the track's
    elements, V_t the belt speed) and is approached with a first-order lag while digging; it is lost
    only by driving onto fresh soil (one contact length L of travel):

        dz_k/dt = max(z_t,k - z_k, 0)/τ_dig + min(z_t,k - z_k, 0) · |u - r y_k| / L

    Resistance: Bekker's compaction resistance of a plate of width b pushed from the static sinkage z_0
    to z_0 + z_k (Bekker 1969; Wong, "Theory of Ground Vehicles" eq. 2.49, R_c = b k z^(n+1)/(n+1)),
    scaled by k_f, opposes the track's ground speed (tanh, 0.05 m/s); the sunken tracks' soil walls add
    a yaw moment proportional to sinkage × weight: M = -κ_M m g (z_L + z_R)/2 · tanh(r / 0.05 rad/s).
    z_0 = (p̄/k)^(1/n) with p̄ = m g / (2 b L) (Bekker). Deformable terrain only (× deformable).

    Differs from the library's ``slip_sinkage``: target sinkage from the slip RATIO via Lyasko's law
    with a first-order lag (library: rate ∝ slip speed × (1 - z/z_max)); Bekker compaction of the extra
    sinkage instead of Rankine passive earth pressure; yaw resistance as a body moment ∝ sinkage instead
    of per-element side-wall forces.
    """

    id: ClassVar[str] = "blind_slip_sinkage"
    label: ClassVar[str] = "slip_sinkage"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("ref_sinkage",)  # scaled by :func:`scaled`

    ref_sinkage: jax.Array  # m, z_ref
    dig_time: jax.Array  # s, τ_dig
    compaction_factor: jax.Array  # -, k_f
    moment_factor: jax.Array  # -, κ_M

    SLIP_EPS: ClassVar[float] = 1e-3  # m/s
    SPEED_EPS: ClassVar[float] = 0.05  # m/s

    @classmethod
    def sample(cls, rng, terrain="dry_sand", dtype=jnp.float32):
        return cls(ref_sinkage=_f(_u(rng, 0.008, 0.018), dtype), dig_time=_f(_u(rng, 1.0, 3.0), dtype),
                   compaction_factor=_f(_u(rng, 0.5, 1.2), dtype), moment_factor=_f(_u(rng, 0.5, 1.2), dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No effect (z_ref = 0: no sinkage, no resistance)."""
        return cls(_f(0.0, dtype), _f(1.0, dtype), _f(0.0, dtype), _f(0.0, dtype))

    @staticmethod
    def lyasko(i):
        """Relative extra sinkage (1 + i)/(1 - 0.5 i) - 1 = 1.5 i/(1 - 0.5 i)."""
        return (1.0 + i) / (1.0 - 0.5 * i) - 1.0

    def slip_ratio(self, kin):
        lat2 = (kin.lateral_velocity**2).mean(axis=1)  # (1, *b)
        s = jnp.sqrt(kin.slip**2 + lat2 + self.SLIP_EPS**2) - self.SLIP_EPS
        return jnp.minimum(s / jnp.maximum(jnp.abs(kin.belt_speed), self.SPEED_EPS), 1.0)

    def static_sinkage(self, params):
        veh, ter = params.vehicle, params.terrain
        k = ter.k_c / veh.track_width + ter.k_phi
        p = veh.mass * GRAVITY / (2.0 * veh.track_width * veh.contact_length)
        return (p / k) ** (1.0 / ter.sinkage_exponent)

    def initial_state(self, params, batch_shape):
        return jnp.zeros((2,) + tuple(batch_shape), params.dtype)

    def state_rate(self, ctx, forces):
        z = ctx.state.extra[self.id]
        target = self.ref_sinkage * self.lyasko(self.slip_ratio(ctx.kin))
        gap = target - z
        travel = jnp.abs(ctx.kin.ground_speed) / ctx.params.vehicle.contact_length
        rate = jnp.maximum(gap, 0.0) / self.dig_time + jnp.minimum(gap, 0.0) * travel
        return rate * ctx.params.terrain.deformable

    def resistance(self, params, z):
        """Bekker compaction resistance of the extra sinkage z (2, *b) per track [N] (≥ 0)."""
        veh, ter = params.vehicle, params.terrain
        k = ter.k_c / veh.track_width + ter.k_phi
        n1 = ter.sinkage_exponent + 1.0
        z0 = self.static_sinkage(params)
        zz = jnp.maximum(z, 0.0)
        return self.compaction_factor * veh.track_width * k * ((z0 + zz) ** n1 - z0**n1) / n1

    def forces(self, ctx, forces, tau_int):
        p = ctx.params
        z = ctx.state.extra[self.id]
        d = p.terrain.deformable
        front = -self.resistance(p, z) * jnp.tanh(ctx.kin.ground_speed / 0.05) * d
        r = ctx.state.vel[2]
        z_mean = jnp.maximum(z, 0.0).mean(axis=0)
        moment = -self.moment_factor * p.vehicle.mass * GRAVITY * z_mean * jnp.tanh(r / 0.05) * d
        return forces._replace(compaction=forces.compaction + front, body_yaw=forces.body_yaw + moment), tau_int


class BlindLateralFriction(Effect):
    """Lateral friction coefficient decaying exponentially with the turning radius.

        R     = sqrt(u² + v²) / sqrt(r² + r_eps²)                                  [m]
        μ_t(R) = μ_min + (μ_max - μ_min) exp(-R / R0)
        F_lat,i = -μ_t(R) F_n,i tanh(v_y,i / v_s)                                   [N]

    (replaces the shear-law lateral forces). Source: that the lateral resistance coefficient of skid-steered
    tracks falls with the turning radius is the finding behind Kar's and Wong & Chiang's fits (see the
    library) and of Ehlert, Hug & Schmid, "Field measurements and analytical models as a basis of test
    stand simulation of the turning resistance of tracked vehicles", J. Terramechanics 29 (1992) 57-69.
    The exponential shape with a non-zero floor μ_min for straight running is an ASSUMED alternative
    (a saturating decay, not a fit taken from those papers), chosen to differ from the hyperbola.

    Differs from the library's ``lateral_friction_radius``: exponential decay with a floor instead of the
    hyperbola μ_max/(a + bR) of Wong & Chiang (which → 0 for straight running); speed-based radius; tanh
    instead of STEP5 sign smoothing. v_s = 0.02 m/s, r_eps = 0.01 rad/s.
    """

    id: ClassVar[str] = "blind_lateral_friction"
    label: ClassVar[str] = "lateral_friction_radius"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("gate",)  # a blend of this law and the base model's

    mu_max: jax.Array  # -
    mu_min: jax.Array  # -
    radius_scale: jax.Array  # m, R0
    gate: jax.Array = eqx.field(default=1.0)  # 1: this law; 0: the base shear law (batching of mixed columns)

    V_S: ClassVar[float] = 0.02  # m/s
    R_EPS: ClassVar[float] = 0.01  # rad/s

    @classmethod
    def sample(cls, rng, terrain="dry_sand", dtype=jnp.float32):
        mu_max = _u(rng, 0.45, 1.0)
        return cls(mu_max=_f(mu_max, dtype), mu_min=_f(mu_max * _u(rng, 0.15, 0.5), dtype),
                   radius_scale=_f(_u(rng, 0.2, 1.2), dtype), gate=_f(1.0, dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No effect (gate 0: the base model's shear-law lateral forces)."""
        return cls(_f(0.5, dtype), _f(0.2, dtype), _f(1.0, dtype), gate=_f(0.0, dtype))

    def coefficient(self, radius):
        return self.mu_min + (self.mu_max - self.mu_min) * jnp.exp(-radius / self.radius_scale)

    def turning_radius(self, vel):
        u, v, r = vel[0], vel[1], vel[2]
        return jnp.sqrt(u * u + v * v) / jnp.sqrt(r * r + self.R_EPS**2)

    def forces(self, ctx, forces, tau_int):
        mu = self.coefficient(self.turning_radius(ctx.state.vel))  # (*b)
        lateral = -mu * forces.normal * jnp.tanh(ctx.kin.lateral_velocity / self.V_S)
        return forces._replace(lateral=self.gate * lateral + (1.0 - self.gate) * forces.lateral), tau_int


class BlindInternalResistance(Effect):
    """Internal track resistance with a tanh breakaway and a quadratic (aerodynamic-like) speed term.

        τ_int(ω) = b0 tanh(ω/ω0) + b2 ω|ω|                                          [N m]

    (replaces the base model's τ_int). Source: the internal resistance of tracks grows with speed
    (Wong, "Theory of Ground Vehicles": losses in the track pins, sprocket and road wheels); the
    speed-squared term follows the common empirical rolling-resistance form f = f0 + f2 V² (used for
    tyres and, as an ASSUMED alternative here, for the track's internal losses); tanh is the usual
    smooth Coulomb law.

    Differs from the library's ``internal_resistance``: quadratic instead of linear speed term; tanh
    with a sampled width ω0 instead of smoothsign(ω; 0.05 rad/s).
    """

    id: ClassVar[str] = "blind_internal_resistance"
    label: ClassVar[str] = "internal_resistance"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("gate",)  # a blend of this law and the base model's

    b0: jax.Array  # N m
    omega0: jax.Array  # rad/s
    b2: jax.Array  # N m s^2/rad^2
    gate: jax.Array = eqx.field(default=1.0)  # 1: this law; 0: the base model's τ_int (batching)

    @classmethod
    def sample(cls, rng, terrain="dry_sand", dtype=jnp.float32):
        return cls(b0=_f(_u(rng, 0.3, 1.0), dtype), omega0=_f(_u(rng, 0.3, 3.0), dtype),
                   b2=_f(_u(rng, 1.0e-3, 3.5e-3), dtype), gate=_f(1.0, dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No effect (gate 0: the base model's τ_int)."""
        return cls(_f(0.5, dtype), _f(1.0, dtype), _f(0.0, dtype), gate=_f(0.0, dtype))

    def torque(self, omega):
        return self.b0 * jnp.tanh(omega / self.omega0) + self.b2 * omega * jnp.abs(omega)

    def forces(self, ctx, forces, tau_int):
        return forces, self.gate * self.torque(ctx.state.omega) + (1.0 - self.gate) * tau_int


class BlindGrouserStiction(Effect):
    """Gaussian Stribeck amplification of the lateral shear forces of slowly sliding elements (hard ground).

        F_lat,i ← F_lat,i · (1 + β exp(-(v_y,i / v_s)²) (1 - deformable))

    Source: the Gaussian ("exponential-squared") Stribeck curve, μ(v) = μ_c + (μ_s - μ_c) exp(-(v/v_s)²)
    (Armstrong-Hélouvry, Dupont & Canudas de Wit, "A survey of models, analysis tools and compensation
    methods for the control of machines with friction", Automatica 30 (1994) 1083-1138, eq. 5 with
    δ = 2), applied per contact element: grousers locked against asphalt asperities resist more until the
    element slides faster than v_s; so the start of a turn (all elements slow) is hindered, while in a
    fast steady turn only the elements near the turning centre keep the extra resistance.

    Differs from the library's ``grouser_stiction``: a per-element multiplicative Stribeck factor on the
    shear-law lateral forces with Gaussian fade in the element's sliding speed (library: a body yaw
    moment M0 smoothsign(r) exp(-|r|/r_fade) in the yaw rate).
    """

    id: ClassVar[str] = "blind_grouser_stiction"
    label: ClassVar[str] = "grouser_stiction"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("beta",)

    beta: jax.Array  # -, peak amplification
    slide_speed: jax.Array  # m/s, v_s

    @classmethod
    def sample(cls, rng, terrain="asphalt", dtype=jnp.float32):
        return cls(beta=_f(_u(rng, 0.6, 1.2), dtype), slide_speed=_f(_u(rng, 0.15, 0.3), dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No effect (β = 0)."""
        return cls(beta=_f(0.0, dtype), slide_speed=_f(0.2, dtype))

    def factor(self, vy, hard=1.0):
        return 1.0 + self.beta * jnp.exp(-((vy / self.slide_speed) ** 2)) * hard

    def forces(self, ctx, forces, tau_int):
        hard = 1.0 - ctx.params.terrain.deformable
        return forces._replace(lateral=forces.lateral * self.factor(ctx.kin.lateral_velocity, hard)), tau_int


class BlindPitchLoadTransfer(Effect):
    """Pitch load transfer through a second-order (spring-damper) pitch mode, concentrated at the track ends.

    State (2, *b): the transferred pitch moment M = Σ F_n,i x_i [N m] and its rate. It follows the
    quasi-static demand M_ss = -κ_h m a_x h (a_x = (Σ F_long + Σ R_c + body_x)/m from the body force
    balance, h the CG height) through a damped oscillator of natural frequency f_p and damping ratio ζ:

        d²M/dt² = ω_p² (M_ss - M) - 2 ζ ω_p dM/dt,   ω_p = 2π f_p

    (the sprung body pitching on its suspension: the pitch-plane spring-damper of vehicle ride models,
    e.g. Wong, "Theory of Ground Vehicles", chapter on ride characteristics). The moment is taken up by
    the elements in proportion to
    w_i ∝ A_i sgn(x_i)|2x_i/L|^q, normalised so that Σ_k,i w_i x_i = 1 (q > 1 loads the front and rear
    road wheels/idlers more than the middle, as a bogie suspension does):

        F_n,i ← max(0, F_n,i + M w_i)

    Differs from the library's ``pitch_load_transfer``: a second-order oscillating state instead of a
    first-order lag of a_x, and a power-law distribution (q ≥ 2) instead of the Winkler-linear
    pressure gradient.
    """

    id: ClassVar[str] = "blind_pitch_load_transfer"
    label: ClassVar[str] = "pitch_load_transfer"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("height_factor",)

    frequency: jax.Array  # Hz, f_p
    damping: jax.Array  # -, ζ
    height_factor: jax.Array  # -, κ_h
    exponent: jax.Array  # -, q

    @classmethod
    def sample(cls, rng, terrain="dry_sand", dtype=jnp.float32):
        return cls(frequency=_f(_u(rng, 1.5, 4.0), dtype), damping=_f(_u(rng, 0.15, 0.5), dtype),
                   height_factor=_f(_u(rng, 1.5, 3.0), dtype), exponent=_f(_u(rng, 2.0, 4.0), dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No effect (κ_h = 0: the pitch moment stays 0)."""
        return cls(frequency=_f(2.0, dtype), damping=_f(0.3, dtype), height_factor=_f(0.0, dtype),
                   exponent=_f(2.0, dtype))

    def initial_state(self, params, batch_shape):
        return jnp.zeros((2,) + tuple(batch_shape), params.dtype)

    def state_rate(self, ctx, forces):
        m, mdot = ctx.state.extra[self.id][0], ctx.state.extra[self.id][1]
        veh = ctx.params.vehicle
        fx = forces.longitudinal.sum(axis=(0, 1)) + forces.compaction.sum(axis=0) + forces.body_x
        target = -self.height_factor * veh.cg_height * fx  # -κ m a_x h with m a_x = Σ F_x
        w = 2.0 * jnp.pi * self.frequency
        return jnp.stack([mdot, w * w * (target - m) - 2.0 * self.damping * w * mdot])

    def weights(self, kin, length):
        """w_i (1, N, *b) with Σ over both tracks of w_i x_i = 1."""
        xi = kin.x
        shape = kin.area * jnp.sign(xi) * jnp.abs(2.0 * xi / length) ** self.exponent
        norm = 2.0 * (shape * xi).sum(axis=(0, 1))
        return shape / norm

    def normal_loads(self, ctx, normal):
        m = ctx.state.extra[self.id][0]
        w = self.weights(ctx.kin, ctx.params.vehicle.contact_length)
        return jnp.maximum(normal + m * w, 0.0)


class BlindSensorArtifacts(Effect):
    """Instrument artifacts: 1st-order low-pass encoder speed, gyro bias + scale factor, ammeter offsets.

        speed_m: τ dy/dt = x - y, discretised exactly for a held sample,
                 y_k = y_{k-1} + (1 - exp(-Δt_k/τ)) (x_k - y_{k-1}), y_0 = x_0   (τ = 0: off)
        yaw_m  = (1 + ε) r + β                                       (IEEE Std 952 gyro error model)
        i_m    = i + c_left / c_right     (offset before the |i| of an absolute ammeter)

    Sources: encoder velocity estimation with a first-order filter (Belanger, "Estimation of angular
    velocity and acceleration from shaft encoder measurements", ICRA 1992); gyro bias and scale factor
    (IEEE Std 952-1997); Hall-effect current sensor offset. ``sample`` draws a non-empty random subset of
    the three (unused ones get neutral values).

    Differs from the library's ``sensor_artifacts`` in the encoder smoothing only: exponential (IIR)
    instead of moving-average (FIR). The gyro's bias and scale factor and the ammeters' zero offsets are
    the standard instrument errors and have the same form in both, so a sensor case is a weaker test of
    generality than the other labels.
    """

    id: ClassVar[str] = "blind_sensor_artifacts"
    label: ClassVar[str] = "sensor_artifacts"
    AMPLITUDE: ClassVar[tuple[str, ...]] = ("time_constant", "gyro_bias", "gyro_scale", "current_offset_left",
                                             "current_offset_right")

    time_constant: jax.Array  # s, τ (0: no low-pass)
    gyro_bias: jax.Array  # rad/s, β
    gyro_scale: jax.Array  # -, ε
    current_offset_left: jax.Array  # A
    current_offset_right: jax.Array  # A

    @classmethod
    def sample(cls, rng, terrain="dry_sand", dtype=jnp.float32):
        while True:
            use = rng.random(3) < 0.5
            if use.any():
                break
        sgn = lambda: float(rng.choice([-1.0, 1.0]))  # noqa: E731
        tau = _u(rng, 0.15, 0.5) if use[0] else 0.0
        bias = sgn() * _u(rng, 0.06, 0.15) if use[1] else 0.0
        scale = sgn() * _u(rng, 0.05, 0.15) if use[1] else 0.0
        off_l = sgn() * _u(rng, 0.25, 0.6) if use[2] else 0.0
        off_r = sgn() * _u(rng, 0.25, 0.6) if use[2] else 0.0
        return cls(time_constant=_f(tau, dtype), gyro_bias=_f(bias, dtype), gyro_scale=_f(scale, dtype),
                   current_offset_left=_f(off_l, dtype), current_offset_right=_f(off_r, dtype))

    @classmethod
    def neutral(cls, dtype=jnp.float32):
        """No artifact."""
        z = _f(0.0, dtype)
        return cls(time_constant=z, gyro_bias=z, gyro_scale=z, current_offset_left=z, current_offset_right=z)

    @staticmethod
    def low_pass(t, x, tau):
        """First-order low-pass of x (T, *b) on times t (T,) with time constant tau [s]; tau ≤ 0: x."""
        t = jnp.asarray(t)
        if t.shape[0] < 2:
            return x
        dt = (t[1:] - t[:-1]).reshape((-1,) + (1,) * (x.ndim - 1))
        a = 1.0 - jnp.exp(-dt / jnp.maximum(tau, 1e-9))

        def step(y, inp):
            ak, xk = inp
            y = y + ak * (xk - y)
            return y, y

        _, ys = jax.lax.scan(step, x[0], (a * jnp.ones_like(x[1:]), x[1:]))
        y = jnp.concatenate([x[:1], ys], axis=0)
        return jnp.where(tau > 0.0, y, x)

    def instruments(self, channels, t, params):
        out = dict(channels)
        if "speed_ideal" in out:
            out["speed_ideal"] = self.low_pass(t, out["speed_ideal"], self.time_constant)
        if "yaw_rate" in out:
            out["yaw_rate"] = (1.0 + self.gyro_scale) * out["yaw_rate"] + self.gyro_bias
        if "i_left" in out:
            out["i_left"] = out["i_left"] + self.current_offset_left
        if "i_right" in out:
            out["i_right"] = out["i_right"] + self.current_offset_right
        return out


_SIM_ORDER = (BlindPitchLoadTransfer, BlindSlipSinkage, BlindLateralFriction, BlindGrouserStiction,
              BlindInternalResistance, BlindSensorArtifacts)  # normal loads first, instruments last
BLIND_EFFECTS: dict[str, type[Effect]] = {
    cls.label: cls
    for cls in (BlindSlipSinkage, BlindLateralFriction, BlindInternalResistance, BlindGrouserStiction,
                BlindPitchLoadTransfer, BlindSensorArtifacts)
}
CANONICAL_IDS: tuple[str, ...] = tuple(BLIND_EFFECTS)
LABELS: tuple[str, ...] = CANONICAL_IDS + ("none",)
MANEUVERS = (*TASK_MANEUVERS, "random_steer", "step_steer", "accel_steps")  # the tasks' maneuvers and three more shapes
TURNING = ("j_turn", "lane_change", "zero_radius_turn", "random_steer", "step_steer")
DEFORMABLE_TERRAINS = ("dry_sand", "dry_sand_1", "dry_sand_2", "sandy_loam_1", "sandy_loam_2", "sandy_loam_3")
HARD_TERRAINS = ("asphalt",)
NEAR_LIMIT = (1.0, 3.0)  # × noise σ (0.25 s moving average): the window of a near-detection-limit case


SCALE_ROUNDS = 4  # batches (two scales each) that :func:`_scale_into_window` may spend on one near-limit case
MAX_SCALE = 3.0  # an amplitude may grow at most this much (a gate, a blend of two laws, at most to 1)
# and shrink at most this much: far below its drawn range the visibility measures how sensitive the model is to
# any small change (stick-slip on hard ground), not the effect: one grouser case showed 1.1 sigma at 0.0002 x beta
MIN_SCALE = 0.02


def scaled(effect: Effect, factor: float) -> Effect:
    """``effect`` with its amplitude (``AMPLITUDE``: the fields that are 0 in ``neutral()``) times ``factor``; for the
    two forms that replace a base-model law, the ``gate`` that blends the two laws (at most 1)."""
    changes = {}
    for name in type(effect).AMPLITUDE:
        x = getattr(effect, name)
        val = factor * np.asarray(x, np.float64)
        if name == "gate":
            val = np.minimum(val, 1.0)
        changes[name] = jnp.asarray(val, x.dtype)
    return dataclasses.replace(effect, **changes)


def effect_params(effect: Effect) -> dict:
    """The parameters of an effect as a JSON-able dict of floats (without the batching ``gate``)."""
    return {f.name: float(np.asarray(getattr(effect, f.name))) for f in dataclasses.fields(effect) if f.name != "gate"}


# ----------------------------------------------------------------------------------------------
# random maneuvers


def _quantize(d, grid):
    if grid is None:
        return float(d)
    return float(max(1, round(d / grid)) * grid)


def _build(segments, grid):
    """Breakpoints from [(duration, v_left, v_right), ...] (ramps/holds: linear to the values at the end)."""
    t, rows = [0.0], [(0.0, 0.0)]
    for d, vl, vr in segments:
        t.append(t[-1] + _quantize(d, grid))
        rows.append((vl, vr))
    t = np.round(np.asarray(t), 9)
    return t, np.asarray(rows, np.float64)


def random_profile(rng, maneuver: str, grid: float | None = None, t_max: float | None = None):
    """A random voltage profile of ``maneuver``: ``(t (K,), volts (K, 2))`` breakpoints [s], [V].

    Starts at rest with 0 V, |V| ≤ 22 V, ends with 0 V and a coast; total duration 4-15 s (the last
    breakpoint is the end of the test). ``grid`` [s] snaps every segment to a multiple of it (a log's
    sample interval, so that logged voltages reproduce the profile exactly). Direction random.

    - ``go_stop``: delay 0.2-1 s, ramp 0.1-0.6 s to ±(5-22) V (both tracks), hold 2-5 s, release
      0.1-0.4 s, coast 1-2 s;
    - ``j_turn``: ramp to V = 6-18 V, straight 1-4 s, ramp 0.2-0.5 s to a turn (ΔV = 4-14 V between the
      tracks, random side), hold 2-5 s, release, coast;
    - ``lane_change``: straight at 6-18 V, turn one way (ΔV 3-10 V) 0.6-2 s, the other way for a similar
      time, straight 0.5-2 s, release, coast;
    - ``zero_radius_turn``: ramp 0.1-0.6 s to ±V/∓V (V 6-16 V), hold 3-10 s, release, coast 1-2 s;
    - ``random_steer``: forward at 6-18 V, then 3-6 random steering segments (ΔV uniform ±12 V, 0.5-1.5 s
      each, 0.15-0.4 s transitions), release, coast;
    - ``step_steer``: straight at 6-18 V for 1-3 s, then a step (0.05 s) to ΔV = 4-16 V, hold 2-4 s;
    - ``accel_steps``: straight accelerations at several speeds: 2-3 steps up to V = 5-22 V (ramps
      0.1-0.5 s, holds 1-2.5 s each), optionally a step down, release, coast.
    """
    if maneuver not in MANEUVERS:
        raise ValueError(f"unknown maneuver {maneuver!r}; known: {MANEUVERS}")
    t_max = T_SIM if t_max is None else t_max
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    sgn = float(rng.choice([-1.0, 1.0]))
    delay = u(0.2, 1.0)
    segs = [(delay, 0.0, 0.0)]
    if maneuver == "go_stop":
        v = sgn * u(5.0, V_MAX)
        segs += [(u(0.1, 0.6), v, v), (u(2.0, 5.0), v, v)]
    elif maneuver == "j_turn":
        v = u(6.0, 18.0) * (sgn if rng.random() < 0.25 else 1.0)
        dv = u(4.0, 14.0) * float(rng.choice([-1.0, 1.0]))
        vl = float(np.clip(v + dv / 2, -V_MAX, V_MAX))
        vr = float(np.clip(v - dv / 2, -V_MAX, V_MAX))
        segs += [(u(0.2, 0.6), v, v), (u(1.0, 4.0), v, v), (u(0.2, 0.5), vl, vr), (u(2.0, 5.0), vl, vr)]
    elif maneuver == "lane_change":
        v = u(6.0, 18.0)
        dv = u(3.0, 10.0) * sgn
        t1 = u(0.6, 2.0)
        a = (float(np.clip(v + dv / 2, -V_MAX, V_MAX)), float(np.clip(v - dv / 2, -V_MAX, V_MAX)))
        b = (a[1], a[0])
        segs += [(u(0.2, 0.6), v, v), (u(1.0, 3.0), v, v), (0.2, *a), (t1, *a), (0.2, *b),
                 (t1 * u(0.8, 1.25), *b), (0.2, v, v), (u(0.5, 2.0), v, v)]
    elif maneuver == "zero_radius_turn":
        v = sgn * u(6.0, 16.0)
        segs += [(u(0.1, 0.6), v, -v), (u(3.0, 10.0), v, -v)]
    elif maneuver == "random_steer":
        v = u(6.0, 18.0)
        segs += [(u(0.2, 0.6), v, v), (u(0.5, 1.5), v, v)]
        for _ in range(int(rng.integers(3, 7))):
            dv = u(-12.0, 12.0)
            a = (float(np.clip(v + dv / 2, -V_MAX, V_MAX)), float(np.clip(v - dv / 2, -V_MAX, V_MAX)))
            segs += [(u(0.15, 0.4), *a), (u(0.5, 1.5), *a)]
    elif maneuver == "step_steer":
        v = u(6.0, 18.0)
        dv = u(4.0, 16.0) * sgn
        a = (float(np.clip(v + dv / 2, -V_MAX, V_MAX)), float(np.clip(v - dv / 2, -V_MAX, V_MAX)))
        segs += [(u(0.2, 0.6), v, v), (u(1.0, 3.0), v, v), (0.05, *a), (u(2.0, 4.0), *a)]
    else:  # accel_steps
        levels = np.sort(rng.uniform(5.0, V_MAX, int(rng.integers(2, 4))))
        for lv in levels:
            segs += [(u(0.1, 0.5), sgn * lv, sgn * lv), (u(1.0, 2.5), sgn * lv, sgn * lv)]
        if rng.random() < 0.5:
            lv = sgn * u(4.0, float(levels[-1]))
            segs += [(u(0.2, 0.5), lv, lv), (u(1.0, 2.0), lv, lv)]
    segs += [(u(0.1, 0.4), 0.0, 0.0), (u(1.0, 2.0), 0.0, 0.0)]
    t, volts = _build(segs, grid)
    g = grid if grid is not None else 1e-3
    if t[-1] < 4.0:  # stretch the final coast
        t[-1] = math.ceil(4.0 / g - 1e-9) * g
    d = np.diff(t)
    while t[0] + d.sum() > t_max + 1e-9:  # shorten the longest segments (keeping ≥ 0.3 s) to fit
        k = int(np.argmax(d))
        excess = d.sum() - t_max
        cut = min(math.ceil(excess / g - 1e-9) * g, math.floor((d[k] - 0.3) / g) * g)
        if cut <= 0:
            raise ValueError(f"cannot fit a {maneuver} profile into {t_max} s")
        d[k] -= cut
    t = np.round(np.concatenate([[0.0], np.cumsum(d)]), 9)
    return t, volts


# ----------------------------------------------------------------------------------------------
# simulation of one case


def _perturbed_params(rng, terrain):
    """Nuisance factors (uniform 0.97-1.03) on a few base parameters (dotted paths for ``replace``)."""
    keys = ("terrain.cohesion", "terrain.friction_angle", "terrain.shear_modulus", "internal.constant")
    return {key: float(rng.uniform(0.97, 1.03)) for key in keys}


def _params(terrain, nuisance, effect=None):
    """Base parameters of ``terrain`` with the nuisance factors, and all six blind effects: ``effect`` (if any)
    active, the others neutral. Every case thus has the same pytree structure (one compiled program)."""
    import trackenv as te

    effects = tuple(effect if (effect is not None and isinstance(effect, cls)) else cls.neutral()
                    for cls in _SIM_ORDER)
    p = te.load_params(terrain, effects=effects)
    changes = {}
    for key, f in nuisance.items():
        node = p
        for part in key.split("."):
            node = getattr(node, part)
        changes[key] = float(np.asarray(node)) * f
    return te.replace(p, **changes)


def _batch_profile(col_profiles, t_sim=T_SIM):
    """One VoltageProfile (K_PAD, 2, B) from per-column breakpoint profiles [(t, volts), ...] (B = N_COLS)."""
    import trackenv as te

    tt = np.unique(np.round(np.concatenate([t for t, _ in col_profiles] + [[t_sim]]), 9))
    tt = tt[tt <= t_sim + 1e-9]
    if tt.size > K_PAD:
        raise ValueError(f"too many breakpoints ({tt.size} > {K_PAD})")
    tt = np.concatenate([tt, t_sim + 0.1 * np.arange(1, K_PAD - tt.size + 1)])
    volts = np.zeros((K_PAD, 2, len(col_profiles)))
    for j, (t, v) in enumerate(col_profiles):
        for c in range(2):
            volts[:, c, j] = np.interp(tt, t, v[:, c])
    return te.VoltageProfile.from_arrays(tt, volts, source="blind case")


def _simulate_columns(columns, col_profiles, t_sim=T_SIM):
    """Simulate N_COLS vehicles in one batch; ``columns``: [(terrain, nuisance, effect or None)] per column;
    ``t_sim`` [s]: the simulated duration (the longest test; ``T_SIM`` by default).

    Returns the channels {name: (T, N_COLS)} (float64) and the per-column divergence flags.
    """
    import trackenv as te

    if len(columns) != N_COLS or len(col_profiles) != N_COLS:
        raise ValueError(f"need {N_COLS} columns")
    cache = {}
    trees = []
    for terrain, nuisance, effect in columns:  # identical columns share one parameter build
        key = (terrain, tuple(sorted(nuisance.items())), id(effect))
        if key not in cache:
            cache[key] = _params(terrain, nuisance, effect)
        trees.append(cache[key])
    params = stack_trees(trees, jnp.float32)  # vehicles on the last axis (docs/model.md §6)
    traj = te.simulate(params, _batch_profile(col_profiles, t_sim), t_sim, dt=SIM_DT, on_divergence="flag")
    ch = {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}
    return ch, np.asarray(traj.diverged)


def _half(ch, half):
    """Columns of one half (0: 0..MAX_TESTS-1, 1: MAX_TESTS..N_COLS-1) of batched channels."""
    sl = slice(half * MAX_TESTS, (half + 1) * MAX_TESTS)
    return {k: v[:, sl] for k, v in ch.items()}


def _columns(profiles):
    """The tests' profiles padded (cyclically) to MAX_TESTS columns."""
    return [profiles[j % len(profiles)] for j in range(MAX_TESTS)]


def _moving_average(x, n):
    if n <= 1:
        return x
    c = np.cumsum(np.concatenate([[0.0], x]))
    return (c[n:] - c[:-n]) / n


SIGNALS = ("i_left", "i_right", "speed_ideal", "yaw_rate")


def _visibility(ch_eff, ch_base, tests, noise, sensor):
    """Per test and signal: max |moving-average (0.25 s) of the noise-free difference| / noise σ, while driven.

    Only up to the end of the release ramp (``drive_end``): when the base model coasts to rest at 0 V after a
    turn its yaw rate and currents can chatter (a sensitive, nearly chaotic limit cycle; a 1e-6 V change of the
    input changes them by ~1 rad/s), so differences there say nothing about the effect.
    """
    out = []
    for j, tst in enumerate(tests):
        n = int(round(tst["drive_end"] / SIM_DT)) + 1
        w = max(1, int(round(VISIBILITY_WINDOW / SIM_DT)))
        row = {}
        for s in SIGNALS:
            a, b = ch_eff[s][:n, j], ch_base[s][:n, j]
            if s.startswith("i_") and sensor == "absolute":
                a, b = np.abs(a), np.abs(b)
            row[s] = float(np.max(np.abs(_moving_average(a - b, w))) / noise[s])
        out.append(row)
    return out


def _mobility(ch_eff, ch_base, tests):
    """Per test: max of (peak |u| ratio, peak |r| ratio) of the effect run over the effect-free run."""
    out = []
    for j, tst in enumerate(tests):
        n = int(round(tst["duration"] / SIM_DT)) + 1
        ratios = []
        for s in ("u", "yaw_rate"):
            base = np.max(np.abs(ch_base[s][:n, j]))
            if base > 0.05:
                ratios.append(np.max(np.abs(ch_eff[s][:n, j])) / base)
        out.append(float(max(ratios)) if ratios else 1.0)
    return out


NOTES = ("SYNTHETIC blind case generated by trackenv.diagnose.blind (a benchmark for the sim-to-real gap "
         "diagnosis, docs/model.md §8): a simulation of the PackBot model with random maneuver, noise and small "
         "parameter perturbations, possibly with one unmodelled effect; NOT measured data. Whether an effect "
         "is present, and which, is withheld (the answer key is kept outside this folder).")


def _choose_maneuvers(rng, label, n_tests):
    if label in ("slip_sinkage", "grouser_stiction"):
        first = str(rng.choice(["zero_radius_turn", "random_steer"]))
    elif label == "pitch_load_transfer":  # acceleration/braking (while turning) shows the load transfer best
        first = str(rng.choice(["j_turn", "accel_steps", "step_steer"]))
    else:
        first = str(rng.choice(TURNING))
    rest = [str(m) for m in rng.choice(MANEUVERS, size=n_tests - 1)]
    mans = [first] + rest
    rng.shuffle(mans)
    return mans


def make_case(case_dir, rng, label: str | None = None, n_tests: int | None = None, t_max: float | None = None,
              near_limit: bool = False) -> dict:
    """Write one blind case (3-6 §9 test folders) to ``case_dir``; return its ground truth.

    Args:
        case_dir: the case folder; tests go to ``case_dir/test_00`` ... (``log.csv`` + ``meta.json``).
        rng: a ``numpy.random.Generator`` (or an int seed).
        label: a canonical docs/model.md §8 id, ``"none"`` (no effect) or ``None`` (random among the 7).
        n_tests: number of tests (default random 3-6).
        t_max: longest test [s] (default ``T_SIM``). near_limit: draw the effect's parameters until its
            visibility lies in ``NEAR_LIMIT`` (1-3 noise σ after a 0.25 s average: near the detection limit,
            but systematic); the draw closest to the window is kept.

    Returns:
        ``{"label", "effect", "params", "terrain", "nuisance", "tests", "visibility", "max_visibility",
        "visible", "mobility", "tries"}`` — the answer key, to be stored OUTSIDE ``case_dir`` (nothing of it
        but the terrain, maneuvers, sample rates and sensor type is written to the case folder).
        ``visibility``: per test, {signal: max |0.25 s moving average of (with - without effect)| / noise σ}
        while driven; ``mobility``: per test, peak |u| or |r| with the effect / without; ``visible``: both
        criteria met (``VISIBILITY_MIN``, ``MOBILITY_MIN``); ``None`` for null cases.
    """
    from ..fieldlog import read_field_log, write_log_columns

    rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
    if label is None:
        label = str(rng.choice(LABELS))
    if label not in LABELS:
        raise ValueError(f"unknown label {label!r}; known: {LABELS}")
    if n_tests is None:
        n_tests = int(rng.integers(3, MAX_TESTS + 1))
    if not 1 <= n_tests <= MAX_TESTS:
        raise ValueError(f"n_tests must be 1..{MAX_TESTS}, got {n_tests}")
    case_dir = Path(case_dir)
    t_sim = T_SIM if t_max is None else float(t_max)

    if label == "slip_sinkage":
        terrain = str(rng.choice(DEFORMABLE_TERRAINS))
    elif label == "grouser_stiction":
        terrain = str(rng.choice(HARD_TERRAINS))
    else:
        terrain = str(rng.choice(DEFORMABLE_TERRAINS + HARD_TERRAINS * 3))
    nuisance = _perturbed_params(rng, terrain)
    sensor = str(rng.choice(["absolute", "signed"]))
    noise = {"i_left": _u(rng, 0.03, 0.15), "speed_ideal": _u(rng, 0.003, 0.015), "yaw_rate": _u(rng, 0.005, 0.03)}
    noise["i_right"] = noise["i_left"]
    pose_noise = {"x": 0.01, "y": 0.01, "heading": 0.005}

    def draw_tests():
        tests, profiles = [], []
        for j, man in enumerate(_choose_maneuvers(rng, label, n_tests)):
            rate = int(rng.choice(SAMPLE_RATES))
            t, v = random_profile(rng, man, grid=1.0 / rate, t_max=t_max)
            profiles.append((t, v))
            tests.append({"name": f"test_{j:02d}", "maneuver": man, "sample_rate_hz": rate,
                          "duration": float(t[-1]), "drive_end": float(t[-2]),
                          "breakpoints": np.column_stack([t, v]).tolist(),
                          "pose": bool(rng.random() < 0.4),
                          "n_missing": int(rng.integers(0, 6)) if rng.random() < 0.5 else 0})
        return tests, profiles

    effect, params, visibility, mobility, tries, magnitude_scale = None, {}, None, None, 0, 1.0
    base = (terrain, nuisance, None)
    if label == "none":
        tests, profiles = draw_tests()
        ch, div = _simulate_columns([base] * N_COLS, _columns(profiles) * 2, t_sim)
        if div.any():
            raise RuntimeError("base simulation diverged")
        ch = _half(ch, 0)
    else:
        # Effect parameters are redrawn until the effect is visible and the vehicle still moves. The first batch
        # holds the effect-free run and one draw, the next ones two draws each; after DRAWS_PER_MANEUVERS draws
        # the maneuvers are redrawn too (at most MAX_TRIES draws in all; the best one is kept).
        cls = BLIND_EFFECTS[label]
        best = None
        while tries < MAX_TRIES and not (best is not None and best[0]):
            tests, profiles = draw_tests()
            cols = _columns(profiles)
            ch_base, drawn = None, 0
            while drawn < DRAWS_PER_MANEUVERS and tries < MAX_TRIES and not (best is not None and best[0]):
                if ch_base is None:
                    effs = [None, cls.sample(rng, terrain)]
                else:
                    effs = [cls.sample(rng, terrain), cls.sample(rng, terrain)]
                for eff, (ch_h, div_h) in zip(effs, _simulate_pair(terrain, nuisance, effs, cols, t_sim)):
                    if eff is None:
                        if div_h.any():
                            raise RuntimeError("base simulation diverged")
                        ch_base = ch_h
                        continue
                    tries += 1
                    drawn += 1
                    if div_h[:n_tests].any():
                        continue
                    vis, mob, score = _judge(ch_h, ch_base, tests, noise, sensor)
                    if near_limit:
                        ok = _in_window(score, mob)
                        closeness = -abs(math.log(score / math.sqrt(NEAR_LIMIT[0] * NEAR_LIMIT[1]))) if score > 0 else -99
                    else:
                        ok = _visible(score, mob)
                        closeness = score
                    cand = (ok, closeness if min(mob) >= MOBILITY_MIN else -100.0, eff, ch_h, vis, mob, tests, profiles,
                            ch_base)
                    if best is None or (cand[0], cand[1]) > (best[0], best[1]):
                        best = cand
                    if ok:
                        break
        if best is None:
            raise RuntimeError(f"{label}: every sampled effect diverged")
        ok, _, eff, ch, visibility, mobility, tests, profiles, ch_base = best
        if near_limit and not ok:  # no draw landed in the window: scale the closest one's amplitude into it
            found = _scale_into_window(eff, terrain, nuisance, tests, profiles, ch_base, noise, sensor, t_sim,
                                       _peak(visibility))
            if found is not None:
                magnitude_scale, eff, ch, visibility, mobility = found
        effect, params = eff.id, effect_params(eff)

    # write the test folders
    for j, tst in enumerate(tests):
        rate = tst["sample_rate_hz"]
        step = int(round(100 / rate))
        n = int(round(tst["duration"] / SIM_DT)) + 1
        idx = np.arange(0, n, step)
        ts = np.round(idx * SIM_DT, 9)
        t_b, v_b = profiles[j]
        cols = {"t": ts, "v_left": np.interp(ts, t_b, v_b[:, 0]), "v_right": np.interp(ts, t_b, v_b[:, 1])}
        for s in SIGNALS:
            cols[s] = ch[s][idx, j] + rng.normal(0.0, noise[s], idx.size)
        if sensor == "absolute":
            cols["i_left"], cols["i_right"] = np.abs(cols["i_left"]), np.abs(cols["i_right"])
        if tst["pose"]:
            for s in ("x", "y", "heading"):
                cols[s] = ch[s][idx, j] + rng.normal(0.0, pose_noise[s], idx.size)
        for _ in range(tst["n_missing"]):
            s = str(rng.choice(SIGNALS))
            cols[s][int(rng.integers(1, idx.size))] = np.nan
        meta = {"terrain": terrain, "maneuver": tst["maneuver"], "current_sensor": sensor, "vehicle": "packbot",
                "synthetic": True, "sample_rate_hz": float(rate), "notes": NOTES}
        folder = case_dir / tst["name"]
        write_log_columns(folder, cols, meta)
        read_field_log(folder)

    return {
        "label": label,
        "effect": effect,
        "params": params,
        "terrain": terrain,
        "nuisance": {"params": nuisance, "noise_std": noise, "pose_noise_std": pose_noise, "current_sensor": sensor},
        "tests": tests,
        "visibility": visibility,
        "max_visibility": None if visibility is None else _peak(visibility),
        "visible": None if visibility is None else _visible(_peak(visibility), mobility),
        "near_limit": bool(near_limit),
        "magnitude_scale": magnitude_scale,
        "mobility": mobility,
        "tries": tries,
    }


def _scale_into_window(eff, terrain, nuisance, tests, profiles, ch_base, noise, sensor, t_sim, score):
    """Scale ``eff``'s amplitude (:func:`scaled`) until its visibility lies in ``NEAR_LIMIT``: each round simulates
    two factors, the log-log secant (or, in the first round, linear) guess toward the window's geometric middle
    from the two points closest to it, and that guess's square root (a shorter step, since the visibility is not
    linear in the amplitude). Returns ``(factor, effect, channels, visibility, mobility)`` of the first factor in
    the window whose vehicle still moves, or None after ``SCALE_ROUNDS`` rounds or when the window needs a factor
    outside [``MIN_SCALE``, ``MAX_SCALE``] (the case then keeps its draw)."""
    target = math.sqrt(NEAR_LIMIT[0] * NEAR_LIMIT[1])
    hi = 1.0 if type(eff).AMPLITUDE == ("gate",) else MAX_SCALE
    pts = [(1.0, score)]  # (factor, visibility)
    cols = _columns(profiles)
    n_tests = len(tests)
    for _ in range(SCALE_ROUNDS):
        pts.sort(key=lambda p: abs(math.log(max(p[1], 1e-9) / target)))
        (s0, v0), slope = pts[0], 1.0
        if len(pts) > 1 and pts[1][1] > 0 and v0 > 0 and pts[1][0] != s0 and pts[1][1] != v0:
            slope = math.log(pts[1][1] / v0) / math.log(pts[1][0] / s0)
            slope = min(max(slope, 0.25), 4.0)
        step = math.log(target / max(v0, 1e-9)) / slope
        factors = [float(np.clip(s0 * math.exp(step), MIN_SCALE, hi)),
                   float(np.clip(s0 * math.exp(step / 2), MIN_SCALE, hi))]
        if all(any(abs(f - p[0]) < 1e-12 for p in pts) for f in factors):
            break  # both guesses already simulated: the window lies outside [MIN_SCALE, hi]
        effs = [scaled(eff, f) for f in factors]
        for f, e, (ch_h, div_h) in zip(factors, effs, _simulate_pair(terrain, nuisance, effs, cols, t_sim)):
            if div_h[:n_tests].any():
                continue
            vis, mob, v = _judge(ch_h, ch_base, tests, noise, sensor)
            if _in_window(v, mob):
                return f, e, ch_h, vis, mob
            pts.append((f, v))
    return None


def _simulate_pair(terrain, nuisance, effs, cols, t_sim):
    """Two effects (None: effect-free) on the case's (padded) tests in one batch: per effect, its channels
    {name: (T, MAX_TESTS)} and per-column divergence flags."""
    ch2, div2 = _simulate_columns([(terrain, nuisance, effs[0])] * MAX_TESTS
                                  + [(terrain, nuisance, effs[1])] * MAX_TESTS, cols * 2, t_sim)
    return [(_half(ch2, h), div2[h * MAX_TESTS:(h + 1) * MAX_TESTS]) for h in (0, 1)]


def _peak(vis) -> float:
    """The largest visibility [noise σ] over a case's tests and signals (:func:`_visibility`)."""
    return max(max(r.values()) for r in vis)


def _judge(ch, ch_base, tests, noise, sensor):
    """(visibility, mobility, peak visibility) of channels ``ch`` against the effect-free ``ch_base``."""
    vis = _visibility(ch, ch_base, tests, noise, sensor)
    return vis, _mobility(ch, ch_base, tests), _peak(vis)


def _visible(peak: float, mobility: list) -> bool:
    """An effect case's criterion: peak visibility at least ``VISIBILITY_MIN`` and the vehicle still moving."""
    return bool(peak >= VISIBILITY_MIN and min(mobility) >= MOBILITY_MIN)


def _in_window(peak: float, mobility: list) -> bool:
    """A near-limit case's criterion: peak visibility inside ``NEAR_LIMIT`` and the vehicle still moving."""
    return NEAR_LIMIT[0] <= peak <= NEAR_LIMIT[1] and min(mobility) >= MOBILITY_MIN


def balanced_labels(n: int, rng, null_fraction: float = 0.2) -> list[str]:
    """``n`` labels: ``none`` for max(round(n·null_fraction), n // 6), the rest spread evenly over the 6 ids."""
    n_none = max(int(round(n * null_fraction)), n // 6) if n >= 6 else int(round(n * null_fraction))
    n_none = min(n_none, n)
    k = n - n_none
    ids = list(CANONICAL_IDS)
    labels = ids * (k // 6) + [str(x) for x in rng.permutation(ids)[: k % 6]]
    labels += ["none"] * n_none
    return [str(x) for x in rng.permutation(labels)]


def make_cases(out_dir, n: int, seed: int = 0, null_fraction: float = 0.2, n_tests: int | None = None,
               t_max: float | None = None, near_limit_fraction: float = 0.0) -> list[dict]:
    """Write ``n`` blind cases to ``out_dir/cases/case_000`` ... and the answer key ``out_dir/answers.json``.

    Labels are balanced over the six canonical ids plus ``none`` (:func:`balanced_labels`); case k uses
    ``numpy.random.default_rng([seed, k])``. ``near_limit_fraction`` of the effect cases (every
    1/fraction-th, in order) are drawn near the detection limit (:func:`make_case`). Returns the list of
    answers (each with its ``"case"`` name).
    """
    from tqdm import tqdm

    out_dir = Path(out_dir)
    labels = balanced_labels(n, np.random.default_rng([seed, 10**6]), null_fraction)
    answers = []
    k_eff = 0
    for k in tqdm(range(n), desc="blind cases", unit="case"):
        name = f"case_{k:03d}"
        near = False
        if labels[k] != "none" and near_limit_fraction > 0:
            near = (k_eff % max(1, round(1 / near_limit_fraction))) == 0
            k_eff += 1
        truth = make_case(out_dir / "cases" / name, np.random.default_rng([seed, k]), label=labels[k],
                          n_tests=n_tests, t_max=t_max, near_limit=near)
        answers.append({"case": name, **truth})
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "answers.json").write_text(json.dumps(answers, indent=1) + "\n", encoding="utf-8")
    return answers
