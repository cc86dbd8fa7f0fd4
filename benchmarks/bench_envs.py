"""Speed of the Gymnasium environments: single env via ``gym.make`` and the batched VectorEnv.

    python benchmarks/bench_envs.py                 # default substep; vector N = 64, 1024, 4096
    python benchmarks/bench_envs.py --quick         # N = 1, 64 only, shorter runs
    python benchmarks/bench_envs.py --substeps 0.0005 0.001 0.002 0.005
    python benchmarks/bench_envs.py --sync-dispatch # jax_cpu_enable_async_dispatch = False (see below)

Prints Markdown tables for the README: steps per second after compilation (the first step, which
compiles, is excluded and reported separately), control_dt = 0.05 s, go-stop on dry sand, a constant
11.8 V action (episodes end and are reset inside the timed loop). The single-env numbers include
everything a user pays per ``env.step``: the jitted physics + task call, the one device-to-host
transfer and building ``info``. Vector numbers are aggregate env-steps per second.

``--sync-dispatch`` sets JAX's ``jax_cpu_enable_async_dispatch`` to False before JAX starts: the CPU
then runs each jitted call on the calling thread instead of handing it to a worker thread, which on
this 2-core machine removes ~100 us of hand-off per step and roughly doubles single-env steps/s at
coarse substeps. It is a process-wide setting (it must be set before the first JAX computation), so
trackenv does not set it; RL scripts driving one env at a time on CPU should.
"""

from __future__ import annotations

import argparse
import platform
import time

import gymnasium as gym
import jax
import numpy as np

import trackenv  # noqa: F401  (registers the environments)
from trackenv.envs.core import ENV_DEFAULT_SUBSTEP as DEFAULT_SUBSTEP
from trackenv.envs.vector import TrackVectorEnv


def _rate(step, per_call: int, seconds: float, rounds: int, first=None) -> tuple[float, float]:
    """(seconds of ``first()`` (default ``step()``: the call that compiles), best calls of ``step`` x ``per_call``
    per second over ``rounds`` timed rounds)."""
    t0 = time.perf_counter()
    (first or step)()
    first = time.perf_counter() - t0
    best = 0.0
    for _ in range(rounds):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds / rounds or n == 0:
            step()
            n += 1
        best = max(best, n * per_call / (time.perf_counter() - t0))
    return first, best


def bench_single(substep: float, seconds: float) -> tuple[float, float]:
    env = gym.make("trackenv/GoStop-v0", substep=substep)
    env.reset(seed=0)
    a = np.array([11.8, 11.8], np.float32)

    def fifty_steps():
        for _ in range(50):
            _, _, term, trunc, _ = env.step(a)
            if term or trunc:
                env.reset()

    return _rate(fifty_steps, 50, seconds, 3, first=lambda: env.step(a))


def bench_vector(n_envs: int, substep: float, seconds: float, batching: str) -> tuple[float, float]:
    venv = TrackVectorEnv("go_stop", n_envs, substep=substep, autoreset_mode="same_step", physics_batching=batching)
    venv.reset(seed=0)
    a = np.full((n_envs, 2), 11.8, np.float32)
    return _rate(lambda: venv.step(a), n_envs, seconds, 2)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="vector N = 1, 64 only; shorter runs")
    ap.add_argument("--substeps", type=float, nargs="*", default=None,
                    help=f"substeps [s] for the single-env table (default: {DEFAULT_SUBSTEP:g} and 0.001, 0.002, 0.005)")
    ap.add_argument("--vector-substep", type=float, default=DEFAULT_SUBSTEP)
    ap.add_argument("--batching", nargs="*", default=["auto"], choices=["auto", "vmap", "native", "loop"])
    ap.add_argument("--seconds", type=float, default=3.0, help="timed seconds per measurement")
    ap.add_argument("--sync-dispatch", action="store_true",
                    help="set jax_cpu_enable_async_dispatch=False before JAX starts (see the module docstring)")
    args = ap.parse_args(argv)
    if args.sync_dispatch:
        jax.config.update("jax_cpu_enable_async_dispatch", False)
    subs = args.substeps or sorted({DEFAULT_SUBSTEP, 0.001, 0.002, 0.005})
    sizes = (1, 64) if args.quick else (64, 1024, 4096)
    secs = args.seconds / (2 if args.quick else 1)
    print(f"machine: {platform.processor() or platform.machine()}, {jax.device_count()} x {jax.devices()[0].device_kind} "
          f"(vector envs split over them from {trackenv.parallel.MIN_ENVS_PER_DEVICE} envs per device), "
          f"jax {jax.__version__}; float32; control_dt 0.05 s; go-stop on dry sand; default substep {DEFAULT_SUBSTEP * 1e3:g} ms; "
          f"{'synchronous' if args.sync_dispatch else 'asynchronous (default)'} CPU dispatch\n")
    print("Single env via gym.make (PassiveEnvChecker + OrderEnforcing wrappers included):\n")
    print("| substep | substeps / step | first step (compile) s | steps/s | x real time |")
    print("|---|---|---|---|---|")
    for sub in subs:
        first, sps = bench_single(sub, secs)
        print(f"| {sub * 1e3:g} ms | {int(np.ceil(0.05 / sub - 1e-9))} | {first:.1f} | {sps:,.0f} | {sps * 0.05:,.0f} |", flush=True)
    print(f"\nVector env (TrackVectorEnv, same-step autoreset, substep {args.vector_substep * 1e3:g} ms):\n")
    print("| N | physics batching | first step (compile) s | env-steps/s (aggregate) | x real time |")
    print("|---|---|---|---|---|")
    for n in sizes:
        for batching in args.batching:
            first, sps = bench_vector(n, args.vector_substep, secs * (2 if n >= 1024 else 1), batching)
            print(f"| {n} | {batching} | {first:.1f} | {sps:,.0f} | {sps * 0.05:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
