"""Determinism across processes and between the vector env and the single env.

- The same seed gives a bit-identical trajectory (observations, rewards, flags, randomised parameters,
  full physical state) in two separate Python processes.
- Sub-environment i of a vector env reset with seed s plays the same episode as a single env reset
  with seed s + i, driven by the same actions: the randomised parameters and the first observation
  are bit-identical. The steps are **not** bit-identical: the vmapped program rounds differently from
  the single-env program (float32, ~1e-7 relative after the first step), and the model's sensitivity
  (stick-slip near zero slip) grows that to ~1 % of a channel's range within 1.5 s of random voltages.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import trackenv  # noqa: F401
from trackenv.envs.vector import TrackVectorEnv

ROOT = Path(__file__).resolve().parent.parent

SCRIPT = r"""
import hashlib, sys
import gymnasium as gym, numpy as np
import trackenv
SEED = int(sys.argv[1]) if "SEED" not in globals() else SEED
env = gym.make("trackenv/ZeroRadiusTurn-v0", domain_randomization=True, effects=["slip_sinkage"], max_time=1.0)
h = hashlib.sha256()
obs, info = env.reset(seed=SEED)
rng = np.random.default_rng(SEED)
for k in range(40):
    h.update(obs.tobytes()); h.update(repr(sorted(info["params"].items())).encode())
    for name in sorted(info["state"]):
        h.update(np.ascontiguousarray(info["state"][name]).tobytes())
    obs, r, term, trunc, info = env.step(rng.uniform(-24, 24, 2).astype(np.float32))
    h.update(np.float32(r).tobytes() + bytes([term, trunc]))
    if term or trunc:
        obs, info = env.reset()
print(h.hexdigest())
"""


def _digest(seed: int) -> str:
    r = subprocess.run([sys.executable, "-c", SCRIPT, str(seed)], capture_output=True, text=True, timeout=300,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip().splitlines()[-1]


def _digest_here(seed: int) -> str:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(SCRIPT, "determinism-script", "exec"), {"__name__": "determinism", "SEED": seed})
    return out.getvalue().strip().splitlines()[-1]


def test_same_seed_bit_identical_in_two_processes():
    """A child process and this process (a different process, with other compiled programs cached)."""
    a = _digest(5)
    assert len(a) == 64 and a == _digest_here(5)
    assert _digest_here(6) != a  # the digest does depend on the seed (not a constant)


def test_vector_env_matches_single_env():
    """Bit-identical start; rounding-level agreement after one step; the same episode after 30 steps."""
    n, seed, steps = 2, 21, 30
    kw = dict(domain_randomization=True, max_time=5.0)
    venv = TrackVectorEnv("go_stop", n, autoreset_mode="same_step", **kw)
    obs_v, info_v = venv.reset(seed=seed)
    rng = np.random.default_rng(0)
    actions = rng.uniform(0.0, 14.0, (steps, n, 2)).astype(np.float32)
    vec_obs = [obs_v]
    for k in range(steps):
        o, r, term, trunc, info = venv.step(actions[k])
        assert not (term | trunc).any()
        vec_obs.append(o)
    vec_obs = np.array(vec_obs)

    def single(s, i):
        env = gym.make("trackenv/GoStop-v0", **kw)
        o, info = env.reset(seed=s)
        out = [o]
        for k in range(steps):
            out.append(env.step(actions[k, i])[0])
        return np.array(out), info

    for i in range(n):
        s_obs, info = single(seed + i, i)
        np.testing.assert_array_equal(s_obs[0], vec_obs[0, i])  # bit-identical first observation
        assert info["params"] == {p: float(v[i]) for p, v in info_v["params"].items()}  # and parameters
        scale = np.maximum(np.ptp(s_obs, axis=0), 1e-2)
        step1 = np.max(np.abs(s_obs[1] - vec_obs[1, i]) / scale)
        assert step1 < 1e-5, step1  # float32 rounding of the two compiled programs
        whole = np.max(np.abs(s_obs - vec_obs[:, i]) / scale)
        assert whole < 0.05, whole  # measured up to ~1-3 % after 1.5 s: the rounding grows, see README
        other, _ = single(seed + i + 1, i)  # negative control: the neighbouring seed is another episode
        assert np.max(np.abs(other - vec_obs[:, i]) / scale) > 10 * whole
