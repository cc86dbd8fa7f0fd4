"""DC motor and drive train of each track (4.1, 4.2; App. B). SI units."""

from __future__ import annotations

from jaxtyping import Array, Float

from ..params import InternalResistance, Vehicle
from .sums import divide_by_parameter
from .terramechanics import smoothsign, step5_slope

OMEGA_SMOOTHING = 0.05  # rad/s, width of smoothsign(omega) for stiction and b*_int (docs/model.md §5)


def internal_resistance_torque(internal: InternalResistance, omega: Float[Array, " 2 *b"]) -> Float[Array, " 2 *b"]:
    """Internal track resistance tau_int [N m]: b*_int smoothsign(omega) (5.10) + b_int omega (3.41)."""
    return internal.constant * smoothsign(omega, OMEGA_SMOOTHING) + internal.viscous * omega


def friction_torque(vehicle: Vehicle, omega: Float[Array, " 2 *b"]) -> Float[Array, " 2 *b"]:
    """Drive-train friction b_eff omega + tau_stick smoothsign(omega) [N m] (4.1, Table 4.1)."""
    return vehicle.drive_damping * omega + vehicle.stiction_torque * smoothsign(omega, OMEGA_SMOOTHING)


def resistance_slope(
    vehicle: Vehicle,
    internal: InternalResistance,
    omega: Float[Array, " 2 *b"],
) -> Float[Array, " 2 *b"]:
    """d/domega of friction_torque + internal_resistance_torque [N m s/rad] (closed form)."""
    ds = step5_slope(omega, -OMEGA_SMOOTHING, -1.0, OMEGA_SMOOTHING, 1.0)
    return vehicle.drive_damping + internal.viscous + (vehicle.stiction_torque + internal.constant) * ds


def sprocket_acceleration(
    vehicle: Vehicle,
    current: Float[Array, " 2 *b"],
    omega: Float[Array, " 2 *b"],
    tau_int: Float[Array, " 2 *b"],
    tau_back: Float[Array, " 2 *b"],
) -> Float[Array, " 2 *b"]:
    """J_eff domega/dt = alpha i - b_eff omega - tau_int - tau_stick sgn(omega) - tau_back (4.1) [rad/s^2]."""
    torque = vehicle.alpha * current - friction_torque(vehicle, omega) - tau_int - tau_back
    return divide_by_parameter(torque, vehicle.drive_inertia)  # a division in every batch


def current_drive(
    vehicle: Vehicle,
    voltage: Float[Array, " 2 *b"],
    omega: Float[Array, " 2 *b"],
) -> Float[Array, " 2 *b"]:
    """The non-stiff part of L_m di/dt = V - R_m i - alpha_v omega (4.2): (V - alpha_v omega)/L_m [A/s].

    The stiff part -R_m/L_m i (time constant 0.25 ms) is integrated exactly (see ``integrate``).
    """
    return (voltage - vehicle.alpha_v * omega) / vehicle.motor_inductance


def current_decay_rate(vehicle: Vehicle) -> Float[Array, " *#b"]:
    """R_m / L_m [1/s], the motor circuit's linear decay rate."""
    return vehicle.motor_resistance / vehicle.motor_inductance
