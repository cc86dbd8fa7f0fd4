"""Configuration loading and validation (configs/, trackenv.params).

Every bad file must raise ``te.ConfigError`` naming the file and the key, so that a typo never
becomes a silent default.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import trackenv as te

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
VEHICLE = CONFIGS / "vehicle" / "packbot.yaml"
SAND = CONFIGS / "terrain" / "dry_sand.yaml"


def write_variant(tmp_path: Path, source: Path, edit) -> Path:
    data = yaml.safe_load(source.read_text())
    edit(data)
    out = tmp_path / source.name
    out.write_text(yaml.safe_dump(data, sort_keys=False))
    return out


def set_value(key, value):
    def edit(d):
        d[key]["value"] = value
    return edit


def test_every_terrain_loads():
    terrains = te.list_terrains()
    on_disk = sorted(p.stem for p in (CONFIGS / "terrain").glob("*.yaml"))
    assert terrains == on_disk
    assert {"dry_sand", "asphalt", "lifted"} <= set(terrains)
    for name in terrains:
        raw = {k: v["value"] for k, v in yaml.safe_load((CONFIGS / "terrain" / f"{name}.yaml").read_text()).items()
               if isinstance(v, dict)}
        for internal in ("constant", "viscous"):
            p = te.load_params(name, internal_resistance=internal)
            assert p.dtype == jnp.float32
            t = p.terrain
            assert float(t.cohesion) == pytest.approx(raw["cohesion"])
            assert float(t.friction_angle) == pytest.approx(math.radians(raw["friction_angle"]))
            assert float(t.shear_modulus) == pytest.approx(raw["shear_modulus"])
            assert float(t.deformable) == (1.0 if raw["deformable"] else 0.0)
            if raw["deformable"]:
                assert float(t.k_phi) == pytest.approx(raw["k_phi"])
                assert float(t.sinkage_exponent) == pytest.approx(raw["sinkage_exponent"])
            want_c = raw["internal_resistance_constant"] if internal == "constant" else 0.0
            want_v = raw["internal_resistance_viscous"] if internal == "viscous" else 0.0
            assert float(p.internal.constant) == pytest.approx(want_c)
            assert float(p.internal.viscous) == pytest.approx(want_v)


def test_vehicle_units_and_derived_gains():
    raw = {k: v["value"] for k, v in yaml.safe_load(VEHICLE.read_text()).items() if isinstance(v, dict)}
    v = te.load_params("dry_sand").vehicle
    assert float(v.mass) == pytest.approx(18.144)
    assert float(v.alpha) == pytest.approx(raw["torque_constant"] * raw["gear_ratio"], rel=1e-6)
    # K_v in rpm/V -> back-emf constant in V s/rad at the sprocket
    assert float(v.alpha_v) == pytest.approx(raw["gear_ratio"] * 60.0 / (2 * math.pi * raw["speed_constant"]), rel=1e-6)
    assert float(v.alpha) == pytest.approx(0.902, rel=1e-3)  # docs/model.md §2
    assert float(v.alpha_v) / float(v.alpha) == pytest.approx(1.0 - 0.0025, abs=5e-4)  # differ by 0.25 %
    assert v.n_contact == 14
    # drive damping: thesis Table 4.1 (0.024221; Table B.3 prints 0.0244221)
    assert float(v.drive_damping) == pytest.approx(0.024221, rel=1e-6)


def test_load_from_path(tmp_path):
    path = write_variant(tmp_path, SAND, lambda d: None)
    p = te.load_params(path)
    assert float(p.terrain.cohesion) == pytest.approx(1040.0)


def _expect_config_error(call, path, key):
    with pytest.raises(te.ConfigError) as info:
        call()
    msg = str(info.value)
    assert str(path) in msg, msg
    assert key in msg, msg
    return msg


@pytest.mark.parametrize("case,key,edit", [
    ("unknown key", "masss", lambda d: d.__setitem__("masss", {"value": 1.0, "unit": "kg", "source": "typo"})),
    ("missing key", "yaw_inertia", lambda d: d.pop("yaw_inertia")),
    ("negative mass", "mass", set_value("mass", -18.0)),
    ("zero mass", "mass", set_value("mass", 0.0)),
    ("non-numeric", "mass", set_value("mass", "forty pounds")),
    ("boolean", "motor_resistance", set_value("motor_resistance", True)),
    ("infinite", "drive_inertia", set_value("drive_inertia", float("inf"))),
    ("non-integer n_contact", "n_contact", set_value("n_contact", 14.5)),
    ("no source", "mass", lambda d: d["mass"].pop("source")),
    ("bare number", "mass", lambda d: d.__setitem__("mass", 18.144)),
])
def test_bad_vehicle_file(tmp_path, case, key, edit):
    path = write_variant(tmp_path, VEHICLE, edit)
    _expect_config_error(lambda: te.load_params("dry_sand", vehicle=path), path, key)


@pytest.mark.parametrize("case,key,edit", [
    ("unknown key", "cohesoin", lambda d: d.__setitem__("cohesoin", {"value": 1.0, "unit": "Pa", "source": "typo"})),
    ("missing key", "shear_modulus", lambda d: d.pop("shear_modulus")),
    ("missing deformable-only key", "k_phi", lambda d: d.pop("k_phi")),
    ("phi = 90 deg", "friction_angle", set_value("friction_angle", 90.0)),
    ("phi > 90 deg", "friction_angle", set_value("friction_angle", 120.0)),
    ("negative phi", "friction_angle", set_value("friction_angle", -5.0)),
    ("K = 0", "shear_modulus", set_value("shear_modulus", 0.0)),
    ("K < 0", "shear_modulus", set_value("shear_modulus", -0.01)),
    ("negative cohesion", "cohesion", set_value("cohesion", -1.0)),
    ("non-numeric", "cohesion", set_value("cohesion", "soft")),
    ("n = 0", "sinkage_exponent", set_value("sinkage_exponent", 0.0)),
    ("unknown shear law", "shear_law", set_value("shear_law", "coulomb")),
    ("deformable not bool", "deformable", set_value("deformable", "yes")),
])
def test_bad_terrain_file(tmp_path, case, key, edit):
    path = write_variant(tmp_path, SAND, edit)
    _expect_config_error(lambda: te.load_params(path), path, key)


def test_not_a_mapping(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("- just\n- a list\n")
    _expect_config_error(lambda: te.load_params(path), path, "")
    path.write_text("mass: {value: [unclosed\n")
    _expect_config_error(lambda: te.load_params(path), path, "")


def test_unknown_terrain_and_vehicle_ids():
    with pytest.raises(te.ConfigError) as info:
        te.load_params("moon_dust")
    msg = str(info.value)
    assert "moon_dust" in msg and str(CONFIGS / "terrain") in msg and "dry_sand" in msg  # lists the known ones
    with pytest.raises(te.ConfigError) as info:
        te.load_params("dry_sand", vehicle="talon")
    assert "talon" in str(info.value)
    with pytest.raises(te.ConfigError):
        te.load_params("/nonexistent/dir/sand.yaml")


def test_bad_options():
    with pytest.raises(te.ConfigError, match="internal_resistance"):
        te.load_params("dry_sand", internal_resistance="quadratic")
    with pytest.raises(te.ConfigError, match="dtype"):
        te.load_params("dry_sand", dtype=jnp.int32)


def test_float64_without_x64_raises():
    """In a fresh process (jax_enable_x64 is process-global)."""
    code = (
        "import jax, jax.numpy as jnp, trackenv as te\n"
        "assert not jax.config.jax_enable_x64\n"
        "try:\n"
        "    te.load_params('dry_sand', dtype=jnp.float64)\n"
        "except te.ConfigError as e:\n"
        "    assert 'x64' in str(e) or 'X64' in str(e), e\n"
        "    print('RAISED')\n"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "RAISED" in out.stdout


def test_replace():
    p = te.load_params("dry_sand")
    q = te.replace(p, **{"terrain.cohesion": 2000.0, "vehicle.mass": 20.0})
    assert float(q.terrain.cohesion) == 2000.0 and float(q.vehicle.mass) == 20.0
    assert q.terrain.cohesion.dtype == p.terrain.cohesion.dtype
    assert float(p.terrain.cohesion) == pytest.approx(1040.0)  # the original is untouched
    with pytest.raises(te.ConfigError, match="terrain.cohesoin"):
        te.replace(p, **{"terrain.cohesoin": 1.0})
    with pytest.raises(te.ConfigError, match="vehicle.n_contact"):
        te.replace(p, **{"vehicle.n_contact": 28})  # static: selects the compiled program
    with pytest.raises(te.ConfigError):
        te.replace(p, **{"nothing": 1.0})
    # a batch of values is allowed (for vmap-free batching)
    r = te.replace(p, **{"terrain.cohesion": np.array([0.0, 1000.0])})
    assert r.terrain.cohesion.shape == (2,)
