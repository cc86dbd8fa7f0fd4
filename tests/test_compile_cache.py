"""The disk cache of compiled programs (trackenv/compile_cache.py): the command line turns it on, a second
process reuses the first one's programs and gets the same numbers, and the settings that choose or disable
the directory are obeyed."""

import json
import os
import subprocess
import sys

import pytest

# one process: enable the cache, simulate 0.5 s of a go-stop, report the directory, the cache hits, the final
# state and JAX's minimum compile time for storing a program
SCRIPT = r"""
import hashlib, json, sys
import jax
import numpy as np
import trackenv as te
hits = []
jax.monitoring.register_event_listener(lambda name, **kw: hits.append(name) if name.endswith("cache_hits") else None)
path = te.enable_compilation_cache(*sys.argv[1:2])
p = te.load_params("dry_sand")
traj = te.simulate(p, te.VoltageProfile.constant(10.0, 10.0), 0.5)
x = np.asarray(traj.channels["speed_ideal"])
print(json.dumps({"path": None if path is None else str(path), "hits": len(hits),
                  "digest": hashlib.sha256(x.tobytes()).hexdigest(), "last": float(x[-1]),
                  "min_compile_s": jax.config.jax_persistent_cache_min_compile_time_secs}))
"""


def clean_env(extra):
    """This process's environment without any cache setting, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "TRACKENV_COMPILATION_CACHE")}
    return env | extra


def run(env_extra, *args):
    r = subprocess.run([sys.executable, "-c", SCRIPT, *args], capture_output=True, text=True, timeout=300,
                       env=clean_env(env_extra))
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_second_process_reuses_the_programs_and_gets_the_same_numbers(tmp_path):
    cache = tmp_path / "cache"
    first = run({"TRACKENV_COMPILATION_CACHE": str(cache)})
    assert first["path"] == str(cache) and first["hits"] == 0
    stored = [f for f in cache.rglob("*") if f.is_file()]
    assert stored, "nothing was written to the cache"
    second = run({"TRACKENV_COMPILATION_CACHE": str(cache)})
    assert second["hits"] >= 1  # the simulation's program came from disk
    assert second["digest"] == first["digest"]  # bit for bit
    assert 0.5 < second["last"] < 3.0  # a go-stop at 10 V is moving after 0.5 s: a real simulation ran


def test_small_programs_are_stored_unless_a_threshold_is_set(tmp_path):
    """Every program is stored (JAX's default stores only those that took at least 1 s to compile: here a 0.5 s
    simulation's core and none of the small operations around it, on a fast machine nothing at all); a
    threshold set for JAX is kept."""
    cache = tmp_path / "cache"
    out = run({"TRACKENV_COMPILATION_CACHE": str(cache)})
    assert out["min_compile_s"] == 0.0
    small = [f for f in cache.rglob("*") if f.is_file() and "_simulate_in_parts" not in f.name]
    assert small, "no program other than the simulation core was stored"
    kept = run({"TRACKENV_COMPILATION_CACHE": str(tmp_path / "other"), "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "30"})
    assert kept["min_compile_s"] == 30.0
    assert not any(f.is_file() for f in (tmp_path / "other").rglob("*"))  # nothing here takes 30 s to compile


@pytest.mark.parametrize("setting", ["off", "0", "no"])
def test_off_disables_it(tmp_path, setting):
    out = run({"TRACKENV_COMPILATION_CACHE": setting, "XDG_CACHE_HOME": str(tmp_path)})
    assert out["path"] is None and out["hits"] == 0
    assert not any(tmp_path.rglob("*"))


def test_jax_setting_wins_and_default_lies_under_xdg_cache(tmp_path):
    own = tmp_path / "jax_own"
    out = run({"JAX_COMPILATION_CACHE_DIR": str(own), "XDG_CACHE_HOME": str(tmp_path / "xdg")})
    assert out["path"] == str(own)
    assert not (tmp_path / "xdg").exists()
    out = run({"XDG_CACHE_HOME": str(tmp_path / "xdg")})
    assert out["path"].startswith(str(tmp_path / "xdg" / "trackenv" / "jax"))
    assert any(p.is_file() for p in (tmp_path / "xdg").rglob("*"))


def test_a_directory_that_cannot_be_made_warns_and_disables(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    env = clean_env({"TRACKENV_COMPILATION_CACHE": str(blocker / "sub")})
    code = ("import warnings, trackenv as te\n"
            "with warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n"
            "    p = te.enable_compilation_cache()\n"
            "print(p, '|', '; '.join(str(x.message) for x in w))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    path, msg = r.stdout.strip().split("|", 1)
    assert path.strip() == "None"
    assert "compilation cache disabled" in msg and str(blocker / "sub") in msg


def test_the_command_line_turns_it_on(tmp_path):
    env = clean_env({"TRACKENV_COMPILATION_CACHE": str(tmp_path / "cache"),
                     "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0"})  # stored however fast this machine compiles
    r = subprocess.run([sys.executable, "-m", "trackenv.cli", "simulate", "--voltages", "10,10", "--t-end", "1",
                        "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert any(p.is_file() for p in (tmp_path / "cache").rglob("*")), "the simulation's program was not stored"
