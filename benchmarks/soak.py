"""Soak test of the vector environment: many steps with autoreset, domain randomisation and an effect on.

    python benchmarks/soak.py                       # 10^6 env-steps (README "Reliability")
    python benchmarks/soak.py --steps 100000 --json out/soak.json

N environments (default 64) of ``ZeroRadiusTurn-v0`` on dry sand with ``domain_randomization=True`` and
the ``slip_sinkage`` effect, same-step autoreset, short episodes (``max_time``) so that every
environment resets many times, and seeded random voltage actions in [-24, 24] V. It measures:

- **memory**: resident set size (RSS) after a warm-up (the first 10 % of the steps) and at the end;
  growth = (end - warm-up) / warm-up;
- **compilations** after the first step, counted by a JAX compile-event listener (as in
  tests/envs/test_compilation.py);
- **NaN**: every observation and reward finite; diverged episodes (``info["diverged"]``) counted;
- throughput (env-steps per second) and the number of episodes finished.

``run_soak`` returns the numbers as a dict (tests/test_soak.py runs a shorter soak in CI).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
from pathlib import Path

import jax
import numpy as np

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


def rss_bytes() -> int:
    """Resident set size of this process [bytes] (psutil, else /proc/self/statm)."""
    try:
        import psutil

        return int(psutil.Process(os.getpid()).memory_info().rss)
    except ImportError:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run_soak(steps: int = 1_000_000, num_envs: int = 64, *, task: str = "zero_radius_turn", terrain: str = "dry_sand",
             effect: str = "slip_sinkage", max_time: float = 1.0, seed: int = 0, warmup_fraction: float = 0.1,
             progress: bool = False) -> dict:
    """Step ``num_envs`` environments ``steps // num_envs`` times; return memory, compilation and NaN counts."""
    from trackenv.envs.vector import TrackVectorEnv

    compiles: list[str] = []

    def listener(event, duration, **kwargs):
        if event == COMPILE_EVENT:
            compiles.append(event)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        venv = TrackVectorEnv(task, num_envs, autoreset_mode="same_step", terrain=terrain, effects=[effect],
                              domain_randomization=True, max_time=max_time)
        rng = np.random.default_rng(seed)
        n_iter = max(2, steps // num_envs)
        warm = max(1, int(warmup_fraction * n_iter))
        obs, _ = venv.reset(seed=seed)
        actions = rng.uniform(-24.0, 24.0, (n_iter, num_envs, 2)).astype(np.float32) if n_iter * num_envs <= 4e6 \
            else None
        t0 = time.perf_counter()
        venv.step(np.zeros((num_envs, 2), np.float32))
        first_step_s = time.perf_counter() - t0
        compiles_first = len(compiles)
        nonfinite = 0
        diverged = 0
        episodes = 0
        masses = []
        rss_warm = rss_samples = None
        rss_samples = []
        t_warm = None
        for k in range(n_iter):
            a = actions[k] if actions is not None else rng.uniform(-24.0, 24.0, (num_envs, 2)).astype(np.float32)
            obs, rew, term, trunc, info = venv.step(a)
            if not (np.isfinite(obs).all() and np.isfinite(rew).all()):
                nonfinite += 1
            done = term | trunc
            if done.any():
                episodes += int(done.sum())
                fi = info.get("final_info", {})
                if "diverged" in fi:
                    diverged += int(np.asarray(fi["diverged"])[done].sum())
            if k == warm:
                gc.collect()
                rss_warm = rss_bytes()
                t_warm = time.perf_counter()
                if "params" in info:
                    masses.append(np.asarray(info["params"]["vehicle.mass"]).copy())
            if k > warm and k % max(1, (n_iter - warm) // 20) == 0:
                rss_samples.append(rss_bytes())
            if progress and k % max(1, n_iter // 20) == 0:
                print(f"  {k * num_envs:>9,d} steps  RSS {rss_bytes() / 2**20:7.1f} MiB  compiles {len(compiles)}",
                      file=sys.stderr, flush=True)
        wall = time.perf_counter() - t0
        gc.collect()
        rss_end = rss_bytes()
        venv.close()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    after_warm = n_iter - warm
    return {
        "steps": n_iter * num_envs, "num_envs": num_envs, "task": task, "terrain": terrain, "effect": effect,
        "domain_randomization": True, "max_time_s": max_time, "autoreset_mode": "same_step",
        "first_step_s": first_step_s, "wall_s": wall,
        "steps_per_s_after_warmup": after_warm * num_envs / max(time.perf_counter() - t_warm, 1e-9) if t_warm else None,
        "episodes_finished": episodes, "diverged_episodes": diverged, "nonfinite_steps": nonfinite,
        "compilations_first_step": compiles_first, "compilations_after_first_step": len(compiles) - compiles_first,
        "rss_warmup_mib": rss_warm / 2**20, "rss_end_mib": rss_end / 2**20,
        "rss_max_after_warmup_mib": max(rss_samples + [rss_end]) / 2**20,
        "rss_growth": (rss_end - rss_warm) / rss_warm,
        "randomised_mass_spread_kg": float(np.ptp(masses[0])) if masses else None,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--num-envs", type=int, default=64)
    ap.add_argument("--max-time", type=float, default=1.0, help="episode length [s] (short: many autoresets)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write the result here")
    args = ap.parse_args(argv)
    res = run_soak(args.steps, args.num_envs, max_time=args.max_time, seed=args.seed, progress=True)
    text = json.dumps(res, indent=2)
    print(text)
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(text + "\n")
    ok = res["rss_growth"] < 0.01 and res["compilations_after_first_step"] == 0 and res["nonfinite_steps"] == 0
    print("PASS" if ok else "FAIL", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
