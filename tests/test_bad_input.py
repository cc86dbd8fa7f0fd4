"""The bad-input table: every kind of input a user touches, one parametrised test.

Each row is one bad (or borderline) input: a log folder, a config, a simulate call, an env action or option, a CLI option,
a policy zip, a diagnosis folder or a diagnosis option. A row either expects a clear error (its type, the exit code 2 for a
CLI row, and the file / column / row / key the message must name) or a documented behaviour (a
conversion, a warning), which the row asserts. No row may produce a traceback from deep inside a
library, a message with ``np.float64(...)``, or a changed input file. README "Reliability" lists the
same rows.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import subprocess
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import trackenv as te
from trackenv.cli import main

ROOT = Path(__file__).resolve().parent.parent
TWIN = ROOT / "data" / "field" / "thesis"
SAND = ROOT / "configs" / "terrain" / "dry_sand.yaml"
VEHICLE = ROOT / "configs" / "vehicle" / "packbot.yaml"
DRIVERS = ROOT / "train" / "drivers"


@dataclass
class Outcome:
    """What a row did: ``rc`` (CLI exit code, or None), ``exc`` (an exception, or None), ``text`` (messages)."""

    rc: int | None = None
    exc: BaseException | None = None
    text: str = ""
    warnings: list = field(default_factory=list)
    value: object = None


def cli(*argv) -> Outcome:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc = main([str(a) for a in argv])
    return Outcome(rc=rc, text=err.getvalue() + out.getvalue())


def call(fn: Callable) -> Outcome:
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        try:
            value = fn()
        except Exception as exc:  # noqa: BLE001  (the row checks the type)
            return Outcome(exc=exc, text=str(exc), warnings=[str(x.message) for x in w])
    return Outcome(value=value, warnings=[str(x.message) for x in w])


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


# ----------------------------------------------------------------------------------------------
# inputs


def log_folder(tmp: Path, name="log", edit_csv=None, edit_meta=None) -> Path:
    """A copy of the field twin's go-stop log, optionally edited (csv text -> text, meta dict -> dict)."""
    src = TWIN / "go_stop_dry_sand"
    d = tmp / name
    d.mkdir(parents=True)
    text = (src / "log.csv").read_text()
    meta = json.loads((src / "meta.json").read_text())
    (d / "log.csv").write_text(edit_csv(text) if edit_csv else text)
    meta = edit_meta(meta) if edit_meta else meta
    (d / "meta.json").write_text(meta if isinstance(meta, str) else json.dumps(meta))
    return d


def csv_line(text: str, line: int, new: str) -> str:
    lines = text.splitlines()
    lines[line - 1] = new
    return "\n".join(lines) + "\n"


def csv_cell(text: str, line: int, col: int, value: str) -> str:
    lines = text.splitlines()
    cells = lines[line - 1].split(",")
    cells[col] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


def yaml_variant(tmp: Path, src: Path, key: str, entry: dict) -> Path:
    data = yaml.safe_load(src.read_text())
    data[key] = {**data[key], **entry}
    p = tmp / f"variant_{src.stem}.yaml"
    p.write_text(yaml.safe_dump(data, sort_keys=False))
    return p


def replay_cli(tmp: Path, folder: Path, *extra) -> Outcome:
    return cli("replay", folder, "--out", tmp / "out", *extra)


# ----------------------------------------------------------------------------------------------
# the rows: (id, kind, run(tmp) -> Outcome, check(outcome, tmp))


def expect_error(exc_type=Exception, *names, rc: int | None = None):
    def check(o: Outcome, tmp: Path):
        if rc is not None:
            assert o.rc == rc, f"exit code {o.rc}, expected {rc}; output: {o.text}"
            assert "Traceback" not in o.text, o.text
        else:
            assert o.exc is not None, f"accepted silently (returned {o.value!r})"
            assert isinstance(o.exc, exc_type), f"{type(o.exc).__name__}: {o.exc}"
        for n in names:
            n = n(tmp) if callable(n) else n
            assert str(n) in o.text, f"message does not name {n!r}: {o.text}"
        assert "np.float" not in o.text and "np.int" not in o.text, o.text
    return check


CASES = []


def case(id, kind, run, check, marks=()):
    CASES.append(pytest.param(run, check, id=f"{kind}: {id}", marks=marks))


# --- log folders (trackenv replay, in-process) --------------------------------------------------
case("folder does not exist", "log folder",
     lambda t: replay_cli(t, t / "no_such_log"),
     expect_error(Exception, "no_such_log", rc=2))
case("log.csv missing", "log folder",
     lambda t: (lambda d: ((d / "log.csv").unlink(), replay_cli(t, d))[1])(log_folder(t)),
     expect_error(Exception, "log.csv", "missing file", rc=2))
case("meta.json not JSON", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_meta=lambda m: '{"terrain": "dry_sand",\n oops}')),
     expect_error(Exception, "meta.json", "line 2", rc=2))
case("meta.json unknown terrain", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_meta=lambda m: {**m, "terrain": "moon_dust"})),
     expect_error(Exception, "meta.json", "'terrain'", "moon_dust", rc=2))
case("missing required column", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: s.replace("yaw_rate", "gyro", 1))),
     expect_error(Exception, "log.csv", "line 1", "'yaw_rate'", rc=2))
case("semicolon-delimited CSV", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: s.replace(",", ";"))),
     expect_error(Exception, "log.csv", "';'-delimited", "comma-separated", rc=2))
case("upper-case header", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_line(s, 1, s.splitlines()[0].upper()))),
     expect_error(Exception, "log.csv", "case-sensitive", "'T' for 't'", rc=2))
case("non-numeric voltage", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_cell(s, 5, 1, "twelve"))),
     expect_error(Exception, "log.csv", "column 'v_left'", "line 5 (data row 4)", "'twelve'", rc=2))
case("time goes backwards", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_cell(s, 10, 0, "0.1"))),
     expect_error(Exception, "log.csv", "column 't'", "line 10", "t = 0.1 s", "t = 0.14 s", rc=2))
case("voltage beyond the 24 V bus", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_cell(s, 7, 2, "30"))),
     expect_error(Exception, "log.csv", "column 'v_right'", "line 7", "24 V", rc=2))
case("negative current, absolute ammeter", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_cell(s, 4, 3, "-1.5"))),
     expect_error(Exception, "log.csv", "column 'i_left'", "line 4", "absolute", rc=2))
case("row with a missing field", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_line(s, 6, "0.1,1,1"))),
     expect_error(Exception, "log.csv", "line 6", "3 fields", rc=2))
case("missing voltage cell", "log folder",
     lambda t: replay_cli(t, log_folder(t, edit_csv=lambda s: csv_cell(s, 8, 1, ""))),
     expect_error(Exception, "log.csv", "column 'v_left'", "line 8", rc=2))


def _gap_log(t):
    d = log_folder(t, edit_csv=lambda s: "\n".join(
        [ln if i < 100 or i == 0 else ",".join([f"{float(ln.split(',')[0]) + 1000:.15g}"] + ln.split(",")[1:])
         for i, ln in enumerate(s.splitlines())]) + "\n")
    from trackenv.fieldlog import read_field_log

    return call(lambda: read_field_log(d))


def _check_gap(o: Outcome, tmp):
    assert o.exc is None, o.text
    assert len(o.value) == 251
    msg = " ".join(o.warnings)
    for n in ("log.csv", "column 't'", "line 101", "gap of 1000", "t = 1.96 s"):
        assert n in msg, msg


case("a 1000 s gap between samples (warning, documented)", "log folder", _gap_log, _check_gap)

# --- configs --------------------------------------------------------------------------------------
case("negative mass in a vehicle YAML", "config",
     lambda t: call(lambda: te.load_params("dry_sand", vehicle=yaml_variant(t, VEHICLE, "mass", {"value": -5.0}))),
     expect_error(te.ConfigError, "variant_packbot.yaml", "key 'mass'", "= -5", "> 0"))
case("negative cohesion in a terrain YAML", "config",
     lambda t: call(lambda: te.load_params(yaml_variant(t, SAND, "cohesion", {"value": -3.0}))),
     expect_error(te.ConfigError, "variant_dry_sand.yaml", "key 'cohesion'", ">= 0"))
case("friction angle 95 deg", "config",
     lambda t: call(lambda: te.load_params(yaml_variant(t, SAND, "friction_angle", {"value": 95.0}))),
     expect_error(te.ConfigError, "variant_dry_sand.yaml", "key 'friction_angle'", "= 95 deg", "< 90 deg"))


def _kpa(t):
    return call(lambda: float(te.load_params(yaml_variant(t, SAND, "cohesion",
                                                           {"value": 1.04, "unit": "kPa"})).terrain.cohesion))


def _check_kpa(o, tmp):
    assert o.exc is None, o.text
    assert o.value == pytest.approx(1040.0, rel=1e-6)  # kPa converted by the declared table, not taken as Pa


case("cohesion with unit kPa (converted, documented)", "config", _kpa, _check_kpa)


def _rad(t):
    return call(lambda: float(te.load_params(yaml_variant(t, SAND, "friction_angle",
                                                           {"value": 0.5, "unit": "rad"})).terrain.friction_angle))


case("friction angle with unit rad (converted, documented)", "config", _rad,
     lambda o, t: (o.exc is None and o.value == pytest.approx(0.5, rel=1e-6)) or pytest.fail(o.text or str(o.value)))
case("unknown unit psi", "config",
     lambda t: call(lambda: te.load_params(yaml_variant(t, SAND, "cohesion", {"unit": "psi"}))),
     expect_error(te.ConfigError, "variant_dry_sand.yaml", "key 'cohesion'", "'psi'", "'Pa'", "kPa"))
case("incompatible unit m for a mass", "config",
     lambda t: call(lambda: te.load_params("dry_sand", vehicle=yaml_variant(t, VEHICLE, "mass", {"unit": "m"}))),
     expect_error(te.ConfigError, "variant_packbot.yaml", "key 'mass'", "'m'", "'kg'"))
case("replace(vehicle.mass = -5)", "config",
     lambda t: call(lambda: te.replace(te.load_params("dry_sand"), **{"vehicle.mass": -5.0})),
     expect_error(te.ConfigError, "'vehicle.mass'", "= -5", "> 0"))
case("replace(terrain.cohesion = -100)", "config",
     lambda t: call(lambda: te.replace(te.load_params("dry_sand"), **{"terrain.cohesion": -100.0})),
     expect_error(te.ConfigError, "'terrain.cohesion'", "= -100"))
case("replace(terrain.friction_angle = -0.2), a batch", "config",
     lambda t: call(lambda: te.replace(te.load_params("dry_sand"), **{"terrain.friction_angle": np.array([0.4, -0.2])})),
     expect_error(te.ConfigError, "'terrain.friction_angle'", "= -0.2", "element 1"))
case("replace(terrain.shear_modulus = nan)", "config",
     lambda t: call(lambda: te.replace(te.load_params("dry_sand"), **{"terrain.shear_modulus": float("nan")})),
     expect_error(te.ConfigError, "'terrain.shear_modulus'", "finite"))
case("effect constructor out of bounds", "config",
     lambda t: call(lambda: te.effects.get_effect("slip_sinkage", sinkage_rate=-1.0)),
     expect_error(ValueError, "'slip_sinkage'", "'sinkage_rate'", "= -1", "[0, 10]"))


def _direct_effect(t):
    import jax.numpy as jnp

    from trackenv.effects import InternalResistance

    return call(lambda: InternalResistance(b0=jnp.asarray(-0.5), b1=jnp.asarray(0.0), b2=jnp.asarray(0.0)))


case("effect class built directly out of bounds", "config", _direct_effect,
     expect_error(ValueError, "'internal_resistance'", "'b0'", "= -0.5"))
case("training config unknown key", "config",
     lambda t: (lambda p: (p.write_text(yaml.safe_dump({"default": {"n_timesteps": 1000, "learning_rat": 1e-3}})),
                           cli("train", "go_stop", "--config", p))[1])(t / "ppo_bad.yaml"),
     expect_error(Exception, "ppo_bad.yaml", "learning_rat", rc=2))
case("training config learning-rate schedule that is not lin_<number>", "config",
     lambda t: (lambda p: (p.write_text(yaml.safe_dump({"default": {"n_timesteps": 1000, "learning_rate": "lin_fast"}})),
                           cli("train", "go_stop", "--config", p))[1])(t / "ppo_bad.yaml"),
     expect_error(Exception, "ppo_bad.yaml", "'learning_rate'", "lin_<number>", "'lin_fast'", rc=2))

# --- the simulate API ----------------------------------------------------------------------------
def _simulate(**kw):
    args = dict(params=te.load_params(), profile=te.VoltageProfile.constant(5.0, 5.0), t_end=1.0) | kw
    return call(lambda: te.simulate(args.pop("params"), args.pop("profile"), args.pop("t_end"), **args))


def _load_params_effect_id(t):
    return call(lambda: [e.id for e in te.load_params("dry_sand", effects=["slip_sinkage"]).effects])


case("load_params effects=['slip_sinkage'], an id (documented: as the environments take it)", "simulate call",
     _load_params_effect_id,
     lambda o, t: (o.exc is None and o.value == ["slip_sinkage"]) or pytest.fail(o.text or str(o.value)))
case("load_params with an unknown effect id", "simulate call",
     lambda t: call(lambda: te.load_params("dry_sand", effects=["slip_sinkag"])),
     expect_error(ValueError, "'slip_sinkag'", "slip_sinkage"))
case("simulate given a dict for params", "simulate call",
     lambda t: _simulate(params={"vehicle.mass": 20.0}),
     expect_error(TypeError, "params", "trackenv.Params", "dict"))
case("simulate given an int for the initial state", "simulate call",
     lambda t: _simulate(initial=3),
     expect_error(TypeError, "initial", "trackenv.State", "int"))
case("simulate t_end=True, a bool (not 1 s)", "simulate call",
     lambda t: _simulate(t_end=True),
     expect_error(ValueError, "t_end", "True"))
case("simulate dt=0", "simulate call",
     lambda t: _simulate(dt=0.0),
     expect_error(ValueError, "dt", "positive"))
case("voltage breakpoints of ragged rows", "simulate call",
     lambda t: call(lambda: te.VoltageProfile.from_breakpoints([(0.0, 1.0, 1.0), (0.5,)])),
     expect_error(ValueError, "breakpoints", "rows [t, v_left, v_right]"))
case("voltages with a text cell", "simulate call",
     lambda t: call(lambda: te.VoltageProfile.from_arrays([0.0, 1.0], [[1.0, "x"], [1.0, 1.0]])),
     expect_error(ValueError, "profile", "voltages", "'x'"))

# --- env actions and options ---------------------------------------------------------------------
case("domain_randomization negative mass range", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", domain_randomization={"vehicle.mass": (-20.0, -10.0)})),
     expect_error(te.ConfigError, "'vehicle.mass'", "(-20, -10)", "> 0"))
case("domain_randomization negative friction angle range", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0",
                                     domain_randomization={"terrain.friction_angle": (-0.1, 0.5)})),
     expect_error(te.ConfigError, "'terrain.friction_angle'", "-0.1"))
case("domain_randomization effect range out of its bounds", "env option",
     lambda t: call(lambda: gym.make("trackenv/ZeroRadiusTurn-v0", effects=["slip_sinkage"],
                                     domain_randomization={"effects.0.max_sinkage": (0.01, 0.5)})),
     expect_error(te.ConfigError, "'effects.0.max_sinkage'", "slip_sinkage"))
case("ground mixture with an unknown terrain", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", domain_randomization={"grounds": ["asphalt", "moon"]})),
     expect_error(te.ConfigError, "'grounds'", "unknown terrain 'moon'", "sandy_loam_1"))
case("ground mixture with ranges beside it", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0",
                                     domain_randomization={"grounds": ["asphalt"], "vehicle.mass": (16.0, 20.0)})),
     expect_error(te.ConfigError, "'grounds' only", "vehicle.mass"))
case("ground mixture given one name, not a list", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", domain_randomization={"grounds": "asphalt"})),
     expect_error(te.ConfigError, "'grounds' must be a non-empty list", "'asphalt'"))
case("mistyped keyword terain=", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", terain="asphalt")),
     expect_error(TypeError, "'terain'", "did you mean 'terrain'", "terrain", "effects", "substep", "target_speed"))


def _effects_string(t):
    return call(lambda: [e.id for e in gym.make("trackenv/ZeroRadiusTurn-v0", effects="slip_sinkage").unwrapped.params.sim.effects])


case("effects='slip_sinkage', a string (one id, documented)", "env option", _effects_string,
     lambda o, t: (o.exc is None and o.value == ["slip_sinkage"]) or pytest.fail(o.text or str(o.value)))
case("unknown effect id", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", effects=["slip_sinkag"])),
     expect_error(ValueError, "'slip_sinkag'", "slip_sinkage"))
case("substep above the stable limit", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", substep=0.03)),
     expect_error(ValueError, "substep", "0.01"))
case("negative control_dt", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", control_dt=-0.05)),
     expect_error(ValueError, "control_dt"))
case("unknown terrain", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", terrain="moon_dust")),
     expect_error(te.ConfigError, "moon_dust", "dry_sand"))
case("control_dt=True, a bool (not 1 s)", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", control_dt=True)),
     expect_error(ValueError, "control_dt", "True"))
case("normalize_action='yes', a string (not a bool)", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0", normalize_action="yes")),
     expect_error(ValueError, "normalize_action", "'yes'"))
case("make_vec num_envs=True, a bool (not 1 environment)", "env option",
     lambda t: call(lambda: gym.make_vec("trackenv/GoStop-v0", num_envs=True, vectorization_mode="vector_entry_point")),
     expect_error(ValueError, "num_envs", "True"))


def _env(t, **kw):
    env = gym.make("trackenv/GoStop-v0", **kw)
    env.reset(seed=0)
    return env


case("NaN action", "env action",
     lambda t: call(lambda: _env(t).step(np.array([np.nan, 1.0]))),
     expect_error(ValueError, "finite", "nan"))
case("action of the wrong shape", "env action",
     lambda t: call(lambda: _env(t).step(np.zeros(3))),
     expect_error(ValueError, "shape (2,)", "(3,)"))
case("non-numeric action", "env action",
     lambda t: call(lambda: _env(t).step(["a", "b"])),
     expect_error(ValueError, "two numbers"))
case("reset options", "env option",
     lambda t: call(lambda: gym.make("trackenv/GoStop-v0").reset(seed=0, options={"terrain": "asphalt"})),
     expect_error(ValueError, "options", "terrain"))


def _after_end(t):
    from gymnasium.error import ResetNeeded

    env = _env(t, max_time=0.15)
    rewards = []
    for _ in range(3):
        *_, term, trunc, _info = env.step(np.zeros(2))
        if term or trunc:
            break
    o = call(lambda: env.step(np.zeros(2)))
    env.reset(seed=1)
    rewards.append(env.step(np.zeros(2))[1])  # usable again after reset
    assert isinstance(o.exc, ResetNeeded), o
    return o


case("step after the episode ended, no reset", "env action", _after_end,
     expect_error(Exception, "after the episode ended", "truncated=True", "reset()"))

# --- CLI options ----------------------------------------------------------------------------------


def _into_other_log(t):
    a = log_folder(t, "A")
    b = log_folder(t, "B", edit_meta=lambda m: {**m, "notes": "measured"})
    before = digest(b)
    o = cli("replay", a, "--out", b)
    o.value = (before, digest(b))
    return o


def _check_into_other(o, t):
    expect_error(Exception, "B", "field log trackenv did not write", "--force", rc=2)(o, t)
    assert o.value[0] == o.value[1], "the other log folder was changed"


case("replay --out into another field-log folder", "CLI option", _into_other_log, _check_into_other)


def _into_parent(t):
    a = log_folder(t / "logs", "A")
    o = cli("replay", a, "--out", t / "logs")
    return o


case("replay --out the folder that holds the input", "CLI option", _into_parent,
     expect_error(Exception, "logs", rc=2))
case("replay --out its own input folder, even with --force", "CLI option",
     lambda t: (lambda a: cli("replay", a, "--out", a, "--force"))(log_folder(t, "A")),
     expect_error(Exception, "input log's folder", rc=2))
case("replay --out an existing file", "CLI option",
     lambda t: ((t / "F").write_text("x"), cli("replay", "go_stop_dry_sand", "--out", t / "F"))[1],
     expect_error(Exception, "F", "existing file", rc=2))
case("simulate --out an existing file", "CLI option",
     lambda t: ((t / "F").write_text("x"), cli("simulate", "--voltages", "1,1", "--t-end", "0.1", "--out", t / "F"))[1],
     expect_error(Exception, "existing file", rc=2))
case("simulate --out into a field-log folder", "CLI option",
     lambda t: cli("simulate", "--voltages", "1,1", "--t-end", "0.1", "--out", log_folder(t)),
     expect_error(Exception, "log.csv", "--force", rc=2))
case("simulate --voltages not two numbers", "CLI option",
     lambda t: cli("simulate", "--voltages", "12", "--out", t / "o"),
     expect_error(Exception, "--voltages", "'12'", rc=2))
case("replay --terrain unknown", "CLI option",
     lambda t: cli("replay", "go_stop_dry_sand", "--terrain", "moon_dust", "--out", t / "o"),
     expect_error(Exception, "moon_dust", rc=2))
case("replay --effects unknown id", "CLI option",
     lambda t: cli("replay", "go_stop_dry_sand", "--out", t / "o", "--effects", "slip_sinkag"),
     expect_error(Exception, "slip_sinkag", "slip_sinkage", rc=2))
case("replay --substep negative", "CLI option",
     lambda t: cli("replay", "go_stop_dry_sand", "--out", t / "o", "--substep", "-0.001"),
     expect_error(Exception, "substep", "-0.001", rc=2))
case("train --timesteps below one rollout", "CLI option",
     lambda t: cli("train", "go_stop", "--timesteps", 256, "--out", t / "o"),
     expect_error(Exception, "--timesteps = 256", "8192", "rollout", rc=2))
case("train unknown task", "CLI option",
     lambda t: cli("train", "go_stopp", "--out", t / "o"),
     expect_error(Exception, "go_stopp", rc=2))
case("evaluate --log-dir into a field-log folder", "CLI option",
     lambda t: cli("evaluate", "none", "--task", "go_stop", "--log-dir", log_folder(t)),
     expect_error(Exception, "log.csv", "--force", rc=2))
case("evaluate --json into a field-log folder", "CLI option",
     lambda t: cli("evaluate", "none", "--task", "go_stop", "--json", log_folder(t) / "meta.json"),
     expect_error(Exception, "meta.json", "--force", rc=2))

# --- policy zips ----------------------------------------------------------------------------------
case("policy file is not a zip", "policy zip",
     lambda t: ((t / "p.zip").write_text("not a zip"), cli("evaluate", t / "p.zip", "--task", "go_stop"))[1],
     expect_error(Exception, "p.zip", "not a Stable-Baselines3 zip", rc=2))
case("policy zip missing", "policy zip",
     lambda t: cli("evaluate", t / "nothing.zip", "--task", "go_stop"),
     expect_error(Exception, "nothing.zip", rc=2))
case("zip without SB3 data", "policy zip",
     lambda t: (__import__("zipfile").ZipFile(t / "z.zip", "w").close(), cli("evaluate", t / "z.zip", "--task", "go_stop"))[1],
     expect_error(Exception, "z.zip", rc=2))
case("policy zip of another task", "policy zip",
     lambda t: cli("evaluate", DRIVERS / "JTurn-v0-dry_sand.zip", "--task", "zero_radius_turn", "--episodes", 1),
     expect_error(Exception, "JTurn-v0-dry_sand.zip", "observation space", rc=2))

# --- diagnosis folders ----------------------------------------------------------------------------
case("diagnose an empty folder", "diagnosis folder",
     lambda t: ((t / "empty").mkdir(), cli("diagnose", t / "empty", "--out", t / "d"))[1],
     expect_error(Exception, "empty", "no usable field test", rc=2))
case("diagnose a folder whose only log is broken", "diagnosis folder",
     lambda t: cli("diagnose", log_folder(t / "tests", "x", edit_meta=lambda m: {"maneuver": "go_stop"}).parent,
                   "--out", t / "d"),
     expect_error(Exception, "meta.json", "'terrain'", rc=2))
case("diagnose --out into the field-log folder", "diagnosis folder",
     lambda t: (lambda d: cli("diagnose", d.parent, "--out", d))(log_folder(t / "tests", "x")),
     expect_error(Exception, "x", rc=2))
case("diagnose --out into another log collection", "diagnosis folder",
     lambda t: cli("diagnose", log_folder(t / "tests", "x").parent, "--out", log_folder(t / "other", "y").parent),
     expect_error(Exception, "other", "--force", rc=2))
case("diagnose --vehicle unknown id", "diagnosis folder",
     lambda t: cli("diagnose", log_folder(t / "tests", "x").parent, "--out", t / "d", "--vehicle", "tank"),
     expect_error(Exception, "tank", rc=2))
# --- diagnosis options: refused before any log is read, any folder made or any fit started ----------------------
def no_output(check):
    """``check``, and nothing was written to the ``--out`` folder ``d``."""
    def both(o: Outcome, tmp: Path):
        check(o, tmp)
        assert not (tmp / "d").exists(), "the output folder was made before the option was refused"
    return both


case("diagnose --alpha 2", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--alpha", 2),
     no_output(expect_error(Exception, "alpha", "strictly between 0 and 1", "2.0", rc=2)))
case("diagnose --alpha 0 (nothing could ever be significant)", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--alpha", 0),
     no_output(expect_error(Exception, "alpha", "strictly between 0 and 1", rc=2)))
case("diagnose --polish-iters -1", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--polish-iters", -1),
     no_output(expect_error(Exception, "polish_iters", ">= 0", "-1", rc=2)))
case("diagnose --seed -3", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--seed", -3),
     no_output(expect_error(Exception, "seed", ">= 0", "-3", rc=2)))
case("diagnose(rounds=-1)", "diagnosis option",
     lambda t: call(lambda: __import__("trackenv.diagnose", fromlist=["diagnose"]).diagnose(TWIN, None, rounds=-1, progress=False)),
     expect_error(ValueError, "rounds", "-1"))
case("diagnose(search_points=0)", "diagnosis option",
     lambda t: call(lambda: __import__("trackenv.diagnose", fromlist=["diagnose"]).diagnose(TWIN, None, search_points=0, progress=False)),
     expect_error(ValueError, "search_points", ">= 1"))
case("diagnose --candidates , (an empty list, not 'all')", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--candidates", ","),
     no_output(expect_error(Exception, "candidates is empty", "slip_sinkage", rc=2)))


def _report(folder: Path, effect: str = "slip_sinkage") -> Path:
    """An earlier diagnosis's report.json (the fields ``--after`` reads), naming ``effect``."""
    folder.mkdir(parents=True, exist_ok=True)
    params = {} if effect == "none" else {"sinkage_rate": 0.4, "bulldozing_factor": 1.5, "max_sinkage": 0.03}
    (folder / "report.json").write_text(json.dumps({
        "verdict": {"effect": effect, "after_model": effect}, "ranking": [{"effect": effect, "params": params}],
        "base_model": {"internal_resistance": "constant"}}))
    return folder / "report.json"


case("diagnose --after a report whose verdict is none", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--after", _report(t / "first", "none")),
     no_output(expect_error(Exception, lambda t: t / "first" / "report.json", "names no effect", rc=2)))
case("diagnose --after a report that does not exist", "diagnosis option",
     lambda t: cli("diagnose", TWIN, "--out", t / "d", "--after", t / "nowhere" / "report.json"),
     no_output(expect_error(Exception, "nowhere", "no such report", rc=2)))
case("diagnose --after, --out into the folder of that report", "diagnosis option",
     lambda t: (lambda r: cli("diagnose", TWIN, "--out", r.parent, "--after", r))(_report(t / "first")),
     expect_error(Exception, "first", "overwrite the input", rc=2))

case("diagnose-benchmark --cases 0", "diagnosis option",
     lambda t: cli("diagnose-benchmark", "--out", t / "d", "--cases", 0),
     no_output(expect_error(Exception, "n_cases", ">= 1", rc=2)))
case("diagnose-benchmark --near-limit-fraction 2", "diagnosis option",
     lambda t: cli("diagnose-benchmark", "--out", t / "d", "--near-limit-fraction", 2),
     no_output(expect_error(Exception, "near_limit_fraction", "[0, 1]", rc=2)))
case("diagnose-benchmark --tests-per-case 9", "diagnosis option",
     lambda t: cli("diagnose-benchmark", "--out", t / "d", "--tests-per-case", 9),
     no_output(expect_error(Exception, "n_tests", "from 1 to 6", "9", rc=2)))
case("diagnose-benchmark --rescore --alpha 1.5", "diagnosis option",
     lambda t: cli("diagnose-benchmark", "--out", t / "d", "--rescore", "--alpha", 1.5),
     expect_error(Exception, "alpha", "1.5", rc=2))
def anchors_without_nan(o: Outcome, tmp: Path):
    """A replay whose output step is longer than the thesis anchors' 1-3 s window: it runs, says so per anchor,
    and its metrics.json holds no NaN (the anchor's simulated value is null, with the note)."""
    assert o.rc == 0, o.text
    assert "replay with a smaller dt" in o.text and "nan" not in o.text.lower(), o.text
    met = (tmp / "out" / "metrics.json").read_text()
    assert "NaN" not in met
    assert all(a["simulated"] is None and a["missing"] == "output_step" and "dt = 5 s" in a["note"]
               for a in json.loads(met)["anchors"])


case("replay of a thesis test with --dt 5 (longer than its anchors' window)", "CLI option",
     lambda t: replay_cli(t, "go_stop_dry_sand", "--dt", 5), anchors_without_nan)
case("evaluate --seed -5", "CLI option",
     lambda t: cli("evaluate", DRIVERS / "GoStop-v0-dry_sand.zip", "--task", "go_stop", "--episodes", 1, "--seed", -5),
     expect_error(Exception, "seed", ">= 0", "-5", rc=2))
case("field-twin --seed -1", "CLI option",
     lambda t: cli("field-twin", "--out", t / "twin", "--seed", -1),
     expect_error(Exception, "seed", ">= 0", "-1", rc=2))
case("import borealtc from a missing folder", "CLI option",
     lambda t: cli("import", "borealtc", t / "nope", "--out", t / "o"),
     expect_error(Exception, "nope", rc=2))
case("calibration bounds reversed", "config",
     lambda t: call(lambda: __import__("trackenv.calibrate", fromlist=["calibrate"]).calibrate(
         [log_folder(t)], {"vehicle.mass": (20.0, 10.0)}, progress=False)),
     expect_error(Exception, "vehicle.mass", "high 10 must exceed low 20"))


@pytest.mark.parametrize("run,check", CASES)
def test_bad_input(run, check, tmp_path):
    check(run(tmp_path), tmp_path)


def test_table_covers_every_input_kind():
    kinds = {p.id.split(":")[0] for p in CASES}
    assert kinds >= {"log folder", "config", "simulate call", "env option", "env action", "CLI option", "policy zip",
                     "diagnosis folder", "diagnosis option"}


def test_real_process_exit_code_and_no_traceback(tmp_path):
    """Two rows as real processes: the exit status is 2 and stderr is one clear line, no traceback."""
    (tmp_path / "F").write_text("x")
    for argv in (["replay", "go_stop_dry_sand", "--out", str(tmp_path / "F")],
                 ["replay", str(tmp_path / "missing_log"), "--out", str(tmp_path / "o")]):
        r = subprocess.run([sys.executable, "-m", "trackenv.cli", *argv], capture_output=True, text=True, timeout=300,
                           cwd=ROOT)
        assert r.returncode == 2, r.stderr
        last = r.stderr.strip().splitlines()[-1]
        assert "Traceback" not in r.stderr and last.startswith("trackenv: error: "), r.stderr
        assert str(tmp_path) in r.stderr


def test_force_overrides_the_guard_and_own_output_is_reused(tmp_path):
    """--force writes into a folder that holds a foreign log; a folder trackenv wrote is reused without it."""
    from trackenv.outputs import MANIFEST

    a = log_folder(tmp_path, "A")
    b = log_folder(tmp_path, "B")
    assert cli("replay", a, "--out", b, "--force").rc == 0
    assert json.loads((b / MANIFEST).read_text())["command"] == "replay"
    assert json.loads((b / "meta.json").read_text())["simulated"] is True
    assert cli("replay", a, "--out", b).rc == 0  # now trackenv's own output folder


def test_float32_values_at_a_bound_are_accepted():
    """A float32 leaf equal to a decimal bound (float32(0.1) > 0.1 in float64) lies on the bound, not above it."""
    import jax.numpy as jnp

    from trackenv.effects import SlipSinkage

    f = jnp.float32
    SlipSinkage(sinkage_rate=f(0.3), max_sinkage=f(0.1), unit_weight=f(15e3), bulldozing_factor=f(1.0),
                side_speed_smoothing=f(0.01))
    te.replace(te.load_params("dry_sand"), **{"terrain.friction_angle": f(0.6)})
    with pytest.raises(ValueError, match="max_sinkage"):
        SlipSinkage(sinkage_rate=f(0.3), max_sinkage=f(0.1001), unit_weight=f(15e3), bulldozing_factor=f(1.0),
                    side_speed_smoothing=f(0.01))
