"""The closed-form diagonal damping of the integrator equals forward-mode derivatives of the force laws.

``integrate.diagonal_damping`` uses hand-derived slopes (``step5_slope``, ``shear_stress_slope``,
``contact.saturation_slopes``/``force_slopes``, ``motor.resistance_slope``). Here the same rates are
computed the other way, by ``jax.jvp`` through the model's own force laws, on random moving states
(including signs of every slip, lateral velocities inside the saturation bands, and near-zero
sprocket speeds), for the three shear laws, in float64.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.integrate import diagonal_damping
from trackenv.physics import contact
from trackenv.physics.model import State, evaluate
from trackenv.physics.motor import friction_torque, internal_resistance_torque


def jvp_damping(params, state, ev):
    """The rates by forward-mode JVPs of saturations, element forces and the resistance torques."""
    veh, kin = params.vehicle, ev.kin
    (sat_z, sat_x), (ds_z, ds_x) = jax.jvp(
        lambda s, v: contact.saturations(kin._replace(slip=s, lateral_velocity=v)),
        (kin.slip, kin.lateral_velocity), (jnp.ones_like(kin.slip), jnp.ones_like(kin.lateral_velocity)))
    jz_sat, jx_sat = state.jz * sat_z, state.jx * sat_x
    _, (dfl_dj, dflat_dj) = jax.jvp(
        lambda a, b: contact.forces_from_saturated(params.terrain, kin.area, ev.forces.normal, a, b),
        (jz_sat, jx_sat), (jnp.ones_like(jz_sat), jnp.ones_like(jx_sat)))
    dfl_ds = dfl_dj * state.jz * ds_z
    dflat_dvy = dflat_dj * state.jx * ds_x
    _, dtau_dw = jax.jvp(lambda w: friction_torque(veh, w) + internal_resistance_torque(params.internal, w),
                         (state.omega,), (jnp.ones_like(state.omega),))
    traction = dfl_ds.sum(axis=1)
    lam_w = (dtau_dw + kin.belt_radius**2 * traction) / veh.drive_inertia
    lam_vel = jnp.stack([traction.sum(axis=0) / veh.mass, -dflat_dvy.sum(axis=(0, 1)) / veh.mass,
                         ((kin.y**2 * traction).sum(axis=0) - (kin.x**2 * dflat_dvy).sum(axis=(0, 1))) / veh.yaw_inertia])
    return jnp.maximum(lam_w, 0.0), jnp.maximum(lam_vel, 0.0)


def terrain_file(tmp_path, law):
    text = open("configs/terrain/dry_sand.yaml").read().replace("value: janosi", f"value: {law}")
    if law == "wong_hump":
        text += 'residual_ratio: {value: 0.6, unit: "-", source: "test"}\n'
    path = tmp_path / f"{law}.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("terrain", ["dry_sand", "asphalt", "wong_hump", "wong_peak"])
def test_closed_form_damping_equals_jvp(terrain, tmp_path):
    with jax.enable_x64(True):
        src = terrain if terrain in ("dry_sand", "asphalt") else terrain_file(tmp_path, terrain)
        params = te.load_params(src, dtype=jnp.float64)
        rng = np.random.default_rng(0)
        n = int(params.vehicle.n_contact)
        checked = 0
        both = jax.jit(lambda st: (diagonal_damping(params, st, evaluate(st, jnp.asarray([11.8, 11.8]), params)),
                                   jvp_damping(params, st, evaluate(st, jnp.asarray([11.8, 11.8]), params))))
        for k in range(40):
            slip_scale = [0.004, 0.02, 0.3][k % 3]  # inside the saturation band, at its edge, beyond
            u = rng.uniform(-1.0, 1.5)
            r = rng.uniform(-2.0, 2.0) * [0.002, 0.01, 1.0][k % 3]
            rb = float(contact.belt_radius(params.vehicle, params.terrain))
            omega = (u + rng.uniform(-slip_scale, slip_scale, 2) + r * np.array([0.165, -0.165])) / rb
            if k % 5 == 0:
                omega = rng.uniform(-0.04, 0.04, 2)  # inside the smoothsign of stiction
            st = State(pose=jnp.zeros(3), vel=jnp.asarray([u, rng.uniform(-0.003, 0.003), r]),
                       omega=jnp.asarray(omega), current=jnp.asarray(rng.uniform(-5, 5, 2)),
                       jz=jnp.asarray(rng.uniform(-0.05, 0.05, (2, n))),
                       jx=jnp.asarray(rng.uniform(-0.04, 0.04, (2, n))), extra={})
            got, want = both(st)
            for g, w in zip(got, want):
                np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=1e-9, atol=1e-9 * (1 + float(jnp.max(w))))
            checked += int(np.asarray(want[0]).max() > 1.0) + int(np.asarray(want[1]).max() > 1.0)
        assert checked > 20  # the states exercised non-trivial rates, not just zeros
