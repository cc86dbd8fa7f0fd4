"""What the field instruments report (docs/model.md §7; thesis §4.4, §5.3).

- ideal speed from the sprocket encoders: r_s (omega_left + omega_right)/2 with the *nominal* r_s (5.1);
- yaw rate from a gyro;
- motor currents (signed here; the field ammeter reports |i|, see ``ammeter``);
- pose (x, y, heading) where a log has it.
"""

from __future__ import annotations

import jax.numpy as jnp

CHANNELS = ("speed_ideal", "yaw_rate", "i_left", "i_right", "x", "y", "heading", "u", "v", "omega_left", "omega_right")


def ideal_speed(vehicle, omega):
    """Encoder 'ideal speed' r_s (omega_l + omega_r)/2 [m/s] (5.1), always with the nominal r_s."""
    return vehicle.sprocket_radius * 0.5 * (omega[0] + omega[1])


def channels(state, params) -> dict:
    """Instrument channels of one state (any batch shape); effects may transform them."""
    out = {
        "speed_ideal": ideal_speed(params.vehicle, state.omega),
        "yaw_rate": state.vel[2],
        "i_left": state.current[0],
        "i_right": state.current[1],
        "x": state.pose[0],
        "y": state.pose[1],
        "heading": state.pose[2],
        "u": state.vel[0],
        "v": state.vel[1],
        "omega_left": state.omega[0],
        "omega_right": state.omega[1],
    }
    return out


def ammeter(current, sensor: str = "absolute"):
    """Field ammeter reading: |i| for the thesis's absolute-value ammeter (§5.3), i if 'signed'."""
    if sensor == "absolute":
        return jnp.abs(current)
    if sensor == "signed":
        return current
    raise ValueError(f"current_sensor must be 'absolute' or 'signed', got {sensor!r}")
