"""The assembled vehicle model: state pytree and state derivative, with the effect hooks.

The derivative is returned split for exponential integration (docs/model.md §6): for the stiff linear
terms (motor current, shear displacements) ``dynamics`` returns the *non-stiff drive* N(x) and,
separately, the decay rates lambda, so that dx/dt = N(x) - lambda x; for every other state N is
the whole derivative.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..params import Params
from . import body, contact, loads, motor
from .sums import contact_sum


class State(eqx.Module):
    """Vehicle state (docs/model.md §1), SI units. Shapes carry a trailing batch shape ``*b``.

    pose: (3, *b) X [m], Y [m], psi [rad] (world frame, psi counter-clockwise from X).
    vel: (3, *b) u, v [m/s] (body frame, CG), r [rad/s].
    omega: (2, *b) sprocket speeds, left/right [rad/s].
    current: (2, *b) motor currents, left/right [A] (signed).
    jz, jx: (2, N, *b) longitudinal / lateral shear displacement at each contact point [m].
    extra: ``{effect id: pytree}`` states added by effects (docs/model.md §8).
    """

    pose: Float[Array, " 3 *b"]
    vel: Float[Array, " 3 *b"]
    omega: Float[Array, " 2 *b"]
    current: Float[Array, " 2 *b"]
    jz: Float[Array, " 2 N *b"]
    jx: Float[Array, " 2 N *b"]
    extra: dict

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The trailing batch shape ``*b`` (``()`` for a single vehicle)."""
        return self.vel.shape[1:]


def initial_state(
    params: Params,
    batch_shape: tuple[int, ...] = (),
    pose: Float[ArrayLike, " 3"] | Sequence[float] | None = None,
    vel: Float[ArrayLike, " 3"] | Sequence[float] | None = None,
) -> State:
    """Vehicle at rest (or at the given pose/velocity), zero current and shear displacement.

    **Arguments:**

    - `params`: the model parameters (their ``dtype`` is the state's).
    - `batch_shape`: the trailing batch shape ``*b`` (``()``: one vehicle).
    - `pose`: X [m], Y [m], psi [rad], the same for every vehicle of the batch; default zero.
    - `vel`: u, v [m/s], r [rad/s] (body frame), the same for every vehicle; default zero.

    **Returns:**

    The :class:`State`; effects add their initial states under ``extra``.
    """
    dtype = params.dtype
    n = params.vehicle.n_contact
    z = lambda *s: jnp.zeros(s + tuple(batch_shape), dtype)  # noqa: E731
    extra = {}
    for effect in params.effects:
        s = effect.initial_state(params, tuple(batch_shape))
        if s is not None:
            extra[effect.id] = s
    return State(
        pose=z(3) if pose is None else jnp.broadcast_to(jnp.asarray(pose, dtype).reshape((3,) + (1,) * len(batch_shape)), (3,) + tuple(batch_shape)),  # noqa: E501
        vel=z(3) if vel is None else jnp.broadcast_to(jnp.asarray(vel, dtype).reshape((3,) + (1,) * len(batch_shape)), (3,) + tuple(batch_shape)),  # noqa: E501
        omega=z(2),
        current=z(2),
        jz=z(2, n),
        jx=z(2, n),
        extra=extra,
    )


class Context(NamedTuple):
    """What effects see when they modify loads, forces and rates."""

    params: Params
    state: State
    voltage: Float[Array, " 2 *b"]  # (2, *b) V
    kin: contact.Kinematics
    nb: int


class Evaluation(NamedTuple):
    """One evaluation of the model: the drive terms, the forces, and the torques (SI)."""

    drive: State  # N(x): full derivative for non-stiff states, drive term for stiff ones
    kin: contact.Kinematics
    forces: contact.ContactForces
    tau_back: Float[Array, " 2 *b"]  # N m, (2, *b) shear back torque r_s' sum F_long (3.22)
    tau_int: Float[Array, " 2 *b"]  # N m, (2, *b)


def evaluate(state: State, voltage: Float[Array, " 2 *b"], params: Params) -> Evaluation:
    """Evaluate forces and the non-stiff part of the state derivative at one instant.

    **Arguments:**

    - `state`: the vehicle state (SI, shapes as in :class:`State`).
    - `voltage`: motor voltages, left/right [V], shape (2, *b).
    - `params`: the model parameters (vehicle, terrain, internal resistance, effects).

    **Returns:**

    An :class:`Evaluation`: the drive terms N(x) (full derivative of the non-stiff states, drive term
    of the stiff ones, in state units per second), the kinematics, the contact forces [N] and the back
    and internal torques [N m].
    """
    veh, ter = params.vehicle, params.terrain
    nb = state.vel.ndim - 1
    kin = contact.kinematics(veh, ter, state.vel, state.omega, nb)
    ctx = Context(params, state, voltage, kin, nb)

    u, r = state.vel[0], state.vel[2]
    normal = loads.normal_loads(veh, u, r, nb)
    for effect in params.effects:
        normal = effect.normal_loads(ctx, normal)

    longitudinal, lateral = contact.shear_forces(ter, kin, normal, state.jz, state.jx)
    zero = jnp.zeros_like(u)
    forces = contact.ContactForces(
        normal=normal,
        longitudinal=longitudinal,
        lateral=lateral,
        compaction=contact.compaction_force(veh, ter, kin, normal),
        body_x=zero,
        body_y=zero,
        body_yaw=zero,
        sprocket=jnp.zeros_like(state.omega),
    )
    tau_int = motor.internal_resistance_torque(params.internal, state.omega)
    for effect in params.effects:
        forces, tau_int = effect.forces(ctx, forces, tau_int)

    # Rigid body (docs/model.md §5)
    track_long = contact_sum(forces.longitudinal, 1, nb)  # (2, *b)
    track_fx = track_long + forces.compaction  # (2, *b)
    force_x = contact_sum(track_fx, 0, nb) + forces.body_x
    force_y = contact_sum(forces.lateral, (0, 1), nb) + forces.body_y
    moment_z = contact_sum(kin.x * forces.lateral, (0, 1), nb) - contact_sum(kin.y * track_fx, 0, nb) + forces.body_yaw
    vel_rate = body.velocity_rate(veh, state.vel, force_x, force_y, moment_z)
    pose_rate = body.pose_rate(state.pose, state.vel)

    # Drive (4.1, 4.2)
    tau_back = kin.belt_radius * track_long  # (3.22)
    omega_rate = motor.sprocket_acceleration(veh, state.current, state.omega, tau_int, tau_back + forces.sprocket)
    current_drive = motor.current_drive(veh, voltage, state.omega)
    jz_drive, jx_drive = contact.shear_drive(kin)

    extra_rate = {}
    for effect in params.effects:
        if effect.id in state.extra:
            extra_rate[effect.id] = effect.state_rate(ctx, forces)
    drive = State(pose_rate, vel_rate, omega_rate, current_drive, jz_drive, jx_drive, extra_rate)
    return Evaluation(drive, kin, forces, tau_back, tau_int)


def decay_rates(
    params: Params, kin: contact.Kinematics, belt_speed: Float[Array, " 2 *b"]
) -> tuple[Float[Array, " *#b"], Float[Array, " 2 N *b"], Float[Array, " 2 N *b"]]:
    """Decay rates (lambda) of the stiff states: current R_m/L_m, shear |V_t|/z* (docs/model.md §6)."""
    lam_z, lam_x = contact.shear_decay_rates(belt_speed, kin)
    return motor.current_decay_rate(params.vehicle), lam_z, lam_x


def derivative(state: State, voltage: Float[Array, " 2 *b"], params: Params) -> State:
    """The full state derivative dx/dt (for reference solvers and checks).

    **Arguments:**

    - `state`: the vehicle state (SI).
    - `voltage`: motor voltages, left/right [V], shape (2, *b).
    - `params`: the model parameters.

    **Returns:**

    dx/dt as a :class:`State` of rates: [m/s, m/s, rad/s], [m/s^2, m/s^2, rad/s^2], [rad/s^2], [A/s],
    [m/s], [m/s] (and the effects' rates under ``extra``).
    """
    ev = evaluate(state, voltage, params)
    lam_i, lam_z, lam_x = decay_rates(params, ev.kin, ev.kin.belt_speed)
    d = ev.drive
    return State(
        d.pose, d.vel, d.omega,
        d.current - lam_i * state.current,
        d.jz - lam_z * state.jz,
        d.jx - lam_x * state.jx,
        d.extra,
    )


class PowerBalance(NamedTuple):
    """Instantaneous power flows [W] (for the energy-balance check); each (*b)."""

    electrical: Float[Array, " *b"]  # sum V i, into the motors
    copper: Float[Array, " *b"]  # sum R i^2
    friction: Float[Array, " *b"]  # sum (b_eff omega + tau_stick sgn omega) omega
    internal: Float[Array, " *b"]  # sum tau_int omega
    shear_slip: Float[Array, " *b"]  # sum F_long s_k - F_lat v_y: dissipated by shearing the ground
    compaction: Float[Array, " *b"]  # - sum R_c (u - r y_k): dissipated compacting the ground
    conversion: Float[Array, " *b"]  # (alpha - alpha_v) i omega: K_t G_r and G_r/K_v differ by 0.25% (Table B.1)
    external: Float[Array, " *b"]  # power of effect forces/torques on the body and sprockets (effects)
    stored: Float[Array, " *b"]  # kinetic energy of body and drive + magnetic energy of the motors [J]


def power_balance(state: State, voltage: Float[Array, " 2 *b"], params: Params) -> PowerBalance:
    """Power flows of the base model; d(stored)/dt = electrical - all losses (energy balance).

    **Arguments:**

    - `state`: the vehicle state (SI).
    - `voltage`: motor voltages, left/right [V], shape (2, *b).
    - `params`: the model parameters.

    **Returns:**

    A :class:`PowerBalance`: each flow [W] and the stored energy [J], shape (*b).
    """
    veh = params.vehicle
    ev = evaluate(state, voltage, params)
    f, kin = ev.forces, ev.kin
    i, w = state.current, state.omega
    sum_tracks = lambda a: a.sum(axis=0)  # noqa: E731
    shear = (f.longitudinal * kin.slip[:, None]).sum(axis=(0, 1)) - (f.lateral * kin.lateral_velocity).sum(axis=(0, 1))
    compaction = -(f.compaction * kin.ground_speed).sum(axis=0)
    u, v, r = state.vel[0], state.vel[1], state.vel[2]
    external = -(f.body_x * u + f.body_y * v + f.body_yaw * r) + (f.sprocket * w).sum(axis=0)
    stored = (
        body.kinetic_energy(veh, state.vel)
        + sum_tracks(0.5 * veh.drive_inertia * w * w + 0.5 * veh.motor_inductance * i * i)
    )
    return PowerBalance(
        electrical=sum_tracks(voltage * i),
        copper=sum_tracks(veh.motor_resistance * i * i),
        friction=sum_tracks(motor.friction_torque(veh, w) * w),
        internal=sum_tracks(ev.tau_int * w),
        shear_slip=shear,
        compaction=compaction,
        conversion=sum_tracks((veh.alpha - veh.alpha_v) * i * w),
        external=external,
        stored=stored,
    )


def prescribed_speed_current(
    state: State, omega_rate: Float[Array, " 2 *b"], params: Params
) -> Float[Array, " 2 *b"]:
    """Motor current [A] that drives the sprockets along a prescribed speed: (4.1) solved for i.

    alpha i = J_eff domega/dt + b_eff omega + tau_stick sgn(omega) + tau_int + tau_back (+ the effects'
    sprocket torques), with omega and the shear state taken from ``state`` and ``omega_rate``
    [rad/s^2] the prescribed acceleration. This is the current of a speed-controlled drive (a log of
    measured track or wheel speeds, docs/model.md §9) that holds exactly that speed.
    """
    veh = params.vehicle
    ev = evaluate(state, jnp.zeros_like(state.omega), params)
    load = motor.friction_torque(veh, state.omega) + ev.tau_int + ev.tau_back + ev.forces.sprocket
    return (veh.drive_inertia * omega_rate + load) / veh.alpha


def drive_voltage(current: Float[Array, " 2 *b"], omega: Float[Array, " 2 *b"], params: Params) -> Float[Array, " 2 *b"]:
    """Motor voltage V = R_m i + alpha_v omega [V] (4.2 at di/dt = 0): the voltage a speed-controlled
    drive applies; L_m di/dt is left out (L_m/R_m = 0.25 ms for the PackBot, far below a log's sample
    interval)."""
    veh = params.vehicle
    return veh.motor_resistance * current + veh.alpha_v * omega
