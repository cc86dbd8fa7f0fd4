"""Vehicles as configs and the contact layout option (docs/model.md §1.1, trackenv.params.Vehicle).

- Every shipped vehicle config loads, validates and drives.
- A track (n_patches = 1, wheelbase = 0) reduces *exactly* to the thesis's closed forms
  x_i = L/2 - (i-1) L/(N-1) and the trapezoid areas (App. C.2).
- The Husky's two tyre patches per side: points within each patch around x = +-wheelbase/2, normal loads
  summing to m g at rest and symmetric front/rear, z* restarting at each patch's leading edge.
- A straight Husky run on asphalt does not yaw; swapping the voltages mirrors the trajectory; and the
  steady speed is the one the motor equation (4.2) and the torque balance (4.1) predict.
- Bad layout and gear-efficiency values are ConfigErrors naming the file and the key.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import trackenv as te
from trackenv.params import validate_params
from trackenv.physics import contact, geometry, loads

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
HUSKY = CONFIGS / "vehicle" / "husky.yaml"
PACKBOT = CONFIGS / "vehicle" / "packbot.yaml"
G = 9.81


def write_variant(tmp_path: Path, source: Path, **values) -> Path:
    data = yaml.safe_load(source.read_text())
    for key, value in values.items():
        data[key]["value"] = value
    out = tmp_path / source.name
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def run(vehicle: str, terrain: str, v_left: float, v_right: float, t_end: float = 2.0):
    p = te.load_params(terrain, vehicle=vehicle)
    rows = [[0.0, 0.0, 0.0], [0.3, v_left, v_right]]
    traj = te.simulate(p, te.VoltageProfile.from_breakpoints(rows), t_end)
    return p, traj, {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}


@pytest.mark.parametrize("name", te.list_vehicles())
def test_every_vehicle_loads_and_drives(name):
    assert {"packbot", "husky", "rover5"} <= set(te.list_vehicles())
    data = yaml.safe_load((CONFIGS / "vehicle" / f"{name}.yaml").read_text())
    for key, entry in data.items():
        if isinstance(entry, dict):
            assert str(entry.get("source", "")).strip(), f"{name}: key {key!r} has no source"
    p = validate_params(te.load_params("asphalt", vehicle=name))
    v = p.vehicle
    assert v.n_contact % v.n_patches == 0 and v.n_contact // v.n_patches >= 2
    assert 0.0 < float(v.gear_efficiency) <= 1.0
    volts = float(v.voltage_limit)  # the terrains' internal resistance b*_int is the PackBot's (§1.1)
    _, traj, ch = run(name, "asphalt", volts, volts, t_end=1.0)
    assert not bool(traj.diverged)
    assert ch["u"][-1] > 0.01  # it moves forward


def test_track_layout_reduces_exactly_to_the_closed_forms():
    v = te.load_params("dry_sand").vehicle
    assert v.n_patches == 1 and float(v.wheelbase) == 0.0 and float(v.gear_efficiency) == 1.0
    n, length, width = v.n_contact, v.contact_length, v.track_width
    i = jnp.arange(n, dtype=jnp.float32)
    spacing = length / (n - 1)
    x_closed = 0.5 * length - i * spacing  # x_i = L/2 - (i-1) L/(N-1)
    weights = jnp.ones(n, jnp.float32).at[0].set(0.5).at[-1].set(0.5)
    area_closed = weights * (width * spacing)
    assert np.array_equal(np.asarray(geometry.contact_x(v, 0))[0], np.asarray(x_closed))
    assert np.array_equal(np.asarray(geometry.contact_area(v, 0))[0], np.asarray(area_closed))
    assert float(v.alpha) == float(v.torque_constant * v.gear_ratio)  # eta = 1: alpha = K_t G_r exactly
    # z* from the front (driving forward) is L/2 - x_i; from the rear (reverse) x_i + L/2
    ter = te.load_params("dry_sand").terrain
    for omega, z_closed in ((5.0, 0.5 * length - x_closed), (-5.0, x_closed + 0.5 * length)):
        kin = contact.kinematics(v, ter, jnp.zeros(3), jnp.full(2, omega), 0)
        assert np.array_equal(np.asarray(kin.z_star), np.broadcast_to(np.asarray(z_closed), (2, n)))


@pytest.fixture(scope="module")
def husky():
    return te.load_params("asphalt", vehicle="husky")


def test_husky_points_lie_in_each_tyre_patch(husky):
    v = husky.vehicle
    n, patches, per = v.n_contact, v.n_patches, v.n_contact // v.n_patches
    assert (n, patches, per) == (14, 2, 7)
    x = np.asarray(geometry.contact_x(v, 0), np.float64)[0]
    half, centre = 0.5 * float(v.contact_length), 0.5 * float(v.wheelbase)
    front, rear = x[:per], x[per:]
    assert np.all(np.diff(x) < 0.0)  # front to rear
    np.testing.assert_allclose([front[0], front[-1]], [centre + half, centre - half], atol=1e-6)
    np.testing.assert_allclose([rear[0], rear[-1]], [-centre + half, -centre - half], atol=1e-6)
    np.testing.assert_allclose(front, -rear[::-1], atol=1e-6)  # the two patches mirror each other
    area = np.asarray(geometry.contact_area(v, 0), np.float64)[0]
    np.testing.assert_allclose(area[:per].sum(), float(v.track_width * v.contact_length), rtol=1e-6)
    np.testing.assert_allclose(area.sum(), patches * float(v.track_width * v.contact_length), rtol=1e-6)
    assert area[0] == area[per - 1] == area[per] == 0.5 * area[1]  # trapezoid weights per patch


def test_husky_loads_at_rest(husky):
    v = husky.vehicle
    per = v.n_contact // v.n_patches
    fn = np.asarray(loads.normal_loads(v, jnp.float32(0.0), jnp.float32(0.0), 0), np.float64)
    assert fn.shape == (2, v.n_contact)
    np.testing.assert_allclose(fn.sum(), float(v.mass) * G, rtol=1e-5)
    np.testing.assert_allclose(fn[:, :per].sum(axis=1), 0.25 * float(v.mass) * G, rtol=1e-5)  # each tyre: m g/4
    np.testing.assert_allclose(fn[:, :per], fn[:, per:][:, ::-1], rtol=1e-6)  # front/rear symmetric
    np.testing.assert_allclose(fn[0], fn[1], rtol=1e-6)
    # the pressure is m g / (2 b P L): the total contact area of one side
    p0 = float(v.mass) * G / (2 * float(v.track_width) * v.n_patches * float(v.contact_length))
    area = np.asarray(geometry.contact_area(v, 0), np.float64)[0]
    np.testing.assert_allclose(fn[0], area * p0, rtol=1e-5)
    # a left turn at speed moves load to the right (outer) side; the total stays m g
    turn = np.asarray(loads.normal_loads(v, jnp.float32(1.0), jnp.float32(0.5), 0), np.float64)
    np.testing.assert_allclose(turn.sum(), float(v.mass) * G, rtol=1e-5)
    assert turn[1].sum() > turn[0].sum()


@pytest.mark.parametrize("omega", [4.0, -4.0])
def test_husky_z_star_restarts_at_each_patch(husky, omega):
    v, ter = husky.vehicle, husky.terrain
    per, length = v.n_contact // v.n_patches, float(v.contact_length)
    # a turning, side-slipping state so that z-bar is active on some patch
    kin = contact.kinematics(v, ter, jnp.array([0.2, 0.05, 0.6]), jnp.full(2, omega), 0)
    z = np.asarray(kin.z_star, np.float64).reshape(2, v.n_patches, per)
    local = np.arange(per) * length / (per - 1)  # distance from the front edge of a patch
    expected = local if omega > 0 else local[::-1]  # driving backwards the rear edge leads
    np.testing.assert_allclose(z, np.broadcast_to(expected, z.shape), atol=1e-6)
    assert np.all(z >= -1e-7) and np.all(z <= length + 1e-6)
    zt = np.asarray(kin.z_tilde, np.float64)
    assert np.all(zt <= np.asarray(kin.z_star) + 1e-7) and np.all(zt >= -1e-7)
    # z-bar per patch: the lateral velocity v + r x changes sign inside the front patch at x = -v/r
    x_bar = -0.05 / 0.6
    assert not (0.256 - length / 2 < x_bar < 0.256 + length / 2)  # not in either patch: z-tilde = z*
    np.testing.assert_allclose(zt, np.asarray(kin.z_star), atol=1e-7)
    kin = contact.kinematics(v, ter, jnp.array([0.2, -0.6 * 0.256, 0.6]), jnp.full(2, omega), 0)
    zt, zs = np.asarray(kin.z_tilde).reshape(2, 2, per), np.asarray(kin.z_star).reshape(2, 2, per)
    assert np.any(zt[:, 0] < zs[:, 0] - 1e-4)  # the front patch has its sign change at its centre
    np.testing.assert_allclose(zt[:, 1], zs[:, 1], atol=1e-7)  # the rear patch has none


def test_husky_straight_run_and_mirror():
    _, traj, a = run("husky", "asphalt", 12.0, 12.0)
    assert np.max(np.abs(a["yaw_rate"])) < 1e-6 and np.max(np.abs(a["v"])) < 1e-6
    assert a["u"][-1] > 0.3
    _, _, left = run("husky", "asphalt", 8.0, 14.0)
    _, _, right = run("husky", "asphalt", 14.0, 8.0)
    for key, sign in (("u", 1), ("v", -1), ("yaw_rate", -1), ("x", 1), ("y", -1)):
        scale = np.max(np.abs(left[key]))
        assert scale > 1e-3, key  # the lateral speed v is a few mm/s
        assert np.max(np.abs(left[key] - sign * right[key])) < 1e-4 * scale, key
    assert left["yaw_rate"][-1] > 0.05  # faster right side: a left turn


def test_husky_steady_speed_from_the_motor_equation():
    """Steady straight run on asphalt: no compaction and no drag, so the traction and tau_back vanish and
    alpha i = b_eff omega + tau_stick + b*_int (4.1), V = R i + alpha_v omega (4.2), u = r_s' omega.

    The smooth signs are 1 to within 1e-9 at omega ~ 3 rad/s; the mechanical time constant is
    (J_eff + m r^2/2) R/(alpha alpha_v) ~ 0.06 s, so 2 s is steady to float32 precision: omega and i within
    0.2 % (measured ~1e-5). The body speed is r_s' omega less a slip that carries no force, inside the
    saturation band of j_z, 0 <= s < 1.5e-2 m/s (3.17; measured 2 mm/s, 0.4 %).
    """
    volts = 12.0
    p, traj, _ = run("husky", "asphalt", volts, volts)
    v, internal = p.vehicle, p.internal
    alpha, alpha_v, res = float(v.alpha), float(v.alpha_v), float(v.motor_resistance)
    tau = float(v.stiction_torque) + float(internal.constant)
    omega = (volts - res * tau / alpha) / (alpha_v + res * (float(v.drive_damping) + float(internal.viscous)) / alpha)
    current = (volts - alpha_v * omega) / res
    radius = float(v.sprocket_radius + v.grouser_height)  # hard ground: r_s + h_g
    s = traj.state
    np.testing.assert_allclose(np.asarray(s.omega[-1]), [omega, omega], rtol=2e-3)
    np.testing.assert_allclose(np.asarray(s.current[-1]), [current, current], rtol=2e-3)
    # the residual slip r_s' omega - u carries no force once it is inside the saturation band of j_z (3.17)
    slip = radius * float(s.omega[-1, 0]) - float(s.vel[-1, 0])
    assert 0.0 <= slip < contact.SLIP_SAT_END, slip
    # gear efficiency: the same current gives eta times the torque of an ideal gearbox
    assert alpha == pytest.approx(float(v.torque_constant * v.gear_ratio) * 0.7, rel=1e-6)
    assert float(v.stiction_torque) == pytest.approx(1.35 * alpha, rel=1e-3)  # no-load current x alpha


def _config_error(path: Path, key: str, call):
    with pytest.raises(te.ConfigError) as info:
        call()
    msg = str(info.value)
    assert str(path) in msg and key in msg, msg
    return msg


@pytest.mark.parametrize("source,key,values", [
    (HUSKY, "n_contact", {"n_contact": 15}),  # not a multiple of n_patches = 2
    (HUSKY, "n_contact", {"n_contact": 2}),  # one point per patch
    (HUSKY, "n_patches", {"n_patches": 0}),
    (HUSKY, "n_patches", {"n_patches": 1.5}),
    (HUSKY, "wheelbase", {"wheelbase": -0.1}),
    (HUSKY, "wheelbase", {"wheelbase": 0.05}),  # the two 0.06 m patches would overlap
    (PACKBOT, "wheelbase", {"wheelbase": 0.3}),  # a track is centred at the CG
    (PACKBOT, "gear_efficiency", {"gear_efficiency": 0.0}),
    (PACKBOT, "gear_efficiency", {"gear_efficiency": 1.2}),
    (HUSKY, "gear_efficiency", {"gear_efficiency": -0.7}),
])
def test_bad_layout_values(tmp_path, source, key, values):
    path = write_variant(tmp_path, source, **values)
    _config_error(path, key, lambda: te.load_params("asphalt", vehicle=path))


def test_bounds_apply_to_replace():
    p = te.load_params("asphalt", vehicle="husky")
    with pytest.raises(te.ConfigError, match="gear_efficiency"):
        te.replace(p, **{"vehicle.gear_efficiency": 1.5})
    with pytest.raises(te.ConfigError, match="vehicle.n_patches"):
        te.replace(p, **{"vehicle.n_patches": 3})  # static: selects the compiled program
    q = te.replace(p, **{"vehicle.gear_efficiency": 0.5})
    assert float(q.vehicle.alpha) == pytest.approx(float(p.vehicle.alpha) * 0.5 / 0.7, rel=1e-6)
    assert math.isclose(float(q.vehicle.alpha_v), float(p.vehicle.alpha_v))  # back-emf unchanged


def test_vehicle_internal_resistance_replaces_the_terrain_files():
    from trackenv.params import load_params, vehicle_internal_resistance

    assert vehicle_internal_resistance("packbot") == {}
    packbot = load_params("asphalt")
    assert float(packbot.internal.constant) == pytest.approx(0.73)  # Table 5.4 (the PackBot's tracks)
    husky = load_params("asphalt", vehicle="husky")
    assert float(husky.internal.constant) == 0.0
    assert float(load_params("dry_sand", vehicle="husky", internal_resistance="viscous").internal.viscous) == 0.0
