"""The batched step and the vector env on an accelerator (GPU): one short script, at most a few minutes.

    python benchmarks/bench_accelerator.py                     # B = 4 096 ... 65 536, vector env N = 4 096, 16 384
    python benchmarks/bench_accelerator.py --batches 64 256 --envs 64 --t-end 0.2    # a quick check (any device)

Prints Markdown tables for the README, every number from this one process, on JAX's default device (named
in the first line; on a CPU the same script measures the CPU):

- ``te.simulate`` of the first ``--t-end`` seconds of the 10 s go-stop on dry sand at the verified 0.5 ms
  substep, one voltage scale per vehicle, vehicles on the last axis: compile time, wall time (best of
  ``--repeat``), × real time aggregate and ns per vehicle-substep;
- the native vector env (``physics_batching="auto"``, same-step autoreset, go-stop on dry sand): first step
  (compile) and env-steps/s over ``--steps`` steps of random voltages.

On an accelerator nothing is chunked or split (``trackenv.parallel.chunk_limit``): each batch is one program.
Float32, as everywhere. Run with ``JAX_PLATFORMS=cuda`` (or nothing: JAX picks the accelerator when its
plugin is installed, e.g. ``pip install "jax[cuda12]"``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import trackenv as te  # noqa: E402
from trackenv.envs.vector import TrackVectorEnv  # noqa: E402
from trackenv.simulate import DEFAULT_SUBSTEP  # noqa: E402

ROWS = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [6.0, 11.8, 11.8], [6.1, 0, 0], [10.0, 0, 0]], float)


def bench_simulate(batch: int, t_end: float, repeat: int) -> dict:
    volts = ROWS[:, 1:, None] * np.linspace(0.8, 1.2, batch)[None, None]
    prof = te.VoltageProfile.from_arrays(ROWS[:, 0], volts)
    params = te.load_params("dry_sand")
    t0 = time.perf_counter()
    jax.block_until_ready(te.simulate(params, prof, t_end).channels["x"])
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(te.simulate(params, prof, t_end).channels["x"])
        best = min(best, time.perf_counter() - t0)
    substeps = t_end / DEFAULT_SUBSTEP
    return {"compile_s": first - best, "wall_s": best, "x_real_time": batch * t_end / best,
            "ns_per_vehicle_substep": 1e9 * best / (batch * substeps)}


def bench_vector(n: int, steps: int) -> dict:
    env = TrackVectorEnv("go_stop", n, autoreset_mode="same_step", physics_batching="auto")
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    env.reset(seed=0)
    env.step(np.full((n, 2), 8.0, np.float32))
    first = time.perf_counter() - t0
    actions = [rng.uniform(0.0, 12.0, (n, 2)).astype(np.float32) for _ in range(steps)]
    t0 = time.perf_counter()
    for a in actions:
        env.step(a)
    wall = time.perf_counter() - t0
    return {"first_step_s": first, "env_steps_per_s": n * steps / wall, "x_real_time": n * steps * env.params.control_dt / wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, nargs="*", default=[4096, 16384, 65536])
    ap.add_argument("--envs", type=int, nargs="*", default=[4096, 16384])
    ap.add_argument("--t-end", type=float, default=2.0, help="simulated seconds per batch run")
    ap.add_argument("--steps", type=int, default=20, help="vector env steps timed after the first")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    dev = jax.devices()[0]
    print(f"device: {dev.platform} {getattr(dev, 'device_kind', '')} ({len(jax.devices())} visible), jax {jax.__version__}, "
          f"float32, substep {DEFAULT_SUBSTEP * 1e3:g} ms")
    print("\n| vehicles | compile s | wall s | × real time (aggregate) | ns / vehicle-substep |\n|---|---|---|---|---|")
    for b in a.batches:
        r = bench_simulate(b, a.t_end, a.repeat)
        print(f"| {b} | {r['compile_s']:.1f} | {r['wall_s']:.3f} | {r['x_real_time']:,.0f} | {r['ns_per_vehicle_substep']:.2f} |",
              flush=True)
    print("\n| vector env N | first step (compile) s | env-steps/s | × real time |\n|---|---|---|---|")
    for n in a.envs:
        r = bench_vector(n, a.steps)
        print(f"| {n} | {r['first_step_s']:.1f} | {r['env_steps_per_s']:,.0f} | {r['x_real_time']:,.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
