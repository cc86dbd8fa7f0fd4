"""The effect extension point (docs/model.md §8): forces, extra states and instrument transforms added
without editing the base model, checked against the steady-state algebra."""

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.effects import Effect, effect_ids

STRAIGHT = [[0, 0, 0], [0.3, 11.8, 11.8], [6.0, 11.8, 11.8]]


class Drag(Effect):
    """A constant resisting body force [N] along -x while moving forward (test-only)."""

    id: ClassVar[str] = "test_drag"
    force: jax.Array

    def forces(self, ctx, forces, tau_int):
        return forces._replace(body_x=forces.body_x - self.force * jnp.tanh(ctx.state.vel[0] / 0.05)), tau_int


class Odometer(Effect):
    """An extra state integrating the forward speed u [m] (test-only)."""

    id: ClassVar[str] = "test_odometer"

    def initial_state(self, params, batch_shape):
        return jnp.zeros(batch_shape, params.dtype)

    def state_rate(self, ctx, forces):
        return ctx.state.vel[0]


class GyroBias(Effect):
    """Adds a constant bias [rad/s] to the yaw-rate channel (test-only)."""

    id: ClassVar[str] = "test_gyro_bias"
    bias: jax.Array

    def instruments(self, channels, t, params):
        return {**channels, "yaw_rate": channels["yaw_rate"] + self.bias}


def steady(traj, key):
    return float(np.mean(np.asarray(traj.channels[key])[-20:]))


def run(effects=(), terrain="asphalt"):
    p = te.load_params(terrain, effects=effects)
    return p, te.simulate(p, te.VoltageProfile.from_breakpoints(STRAIGHT), 6.0)


def test_drag_raises_current_by_the_torque_balance():
    """With a drag F_d, each track must push F_d/2 more: alpha di = r_s' F_d/2 (4.1 at steady state)."""
    p, base = run()
    drag = 10.0
    _, dragged = run((Drag(jnp.asarray(drag, jnp.float32)),))
    r_belt = float(p.vehicle.sprocket_radius + p.vehicle.grouser_height)  # asphalt (§5.3.1)
    expected = r_belt * drag / 2 / float(p.vehicle.alpha)
    delta = steady(dragged, "i_left") - steady(base, "i_left")
    assert delta == pytest.approx(expected, rel=0.03)
    assert steady(dragged, "speed_ideal") < steady(base, "speed_ideal")  # back-emf: slower at more current


def test_extra_state_is_integrated():
    _, traj = run((Odometer(),))
    odometer = np.asarray(traj.state.extra["test_odometer"])
    assert odometer[-1] == pytest.approx(float(traj.channels["x"][-1]), rel=1e-3)  # straight run: x = ∫u dt
    assert np.all(np.diff(odometer) >= -1e-6)


def test_instrument_transform():
    _, base = run()
    _, biased = run((GyroBias(jnp.asarray(0.02, jnp.float32)),))
    np.testing.assert_allclose(np.asarray(biased.channels["yaw_rate"]), np.asarray(base.channels["yaw_rate"]) + 0.02,
                               atol=1e-6)
    np.testing.assert_allclose(np.asarray(biased.channels["x"]), np.asarray(base.channels["x"]), atol=1e-6)


def test_effect_parameters_vmap_and_grad():
    from trackenv.physics.model import initial_state
    from trackenv.simulate import simulate_core

    prof = te.VoltageProfile.from_breakpoints(STRAIGHT)

    def final_x(force):
        p = te.load_params("asphalt", effects=(Drag(force),))
        traj = simulate_core(p, prof, initial_state(p), n_steps=60, dt=0.05, substeps=50)
        return traj.channels["x"][-1]

    xs = jax.vmap(final_x)(jnp.array([0.0, 10.0, 20.0]))
    assert xs[0] > xs[1] > xs[2]
    g = jax.grad(final_x)(jnp.asarray(10.0))
    fd = (final_x(jnp.asarray(11.0)) - final_x(jnp.asarray(9.0))) / 2.0
    assert np.isfinite(g) and g < 0
    assert float(g) == pytest.approx(float(fd), rel=0.1)


def test_effect_ids_unique():
    assert effect_ids((Odometer(), Drag(jnp.asarray(1.0)))) == ("test_odometer", "test_drag")
    with pytest.raises(ValueError):
        effect_ids((Odometer(), Odometer()))
