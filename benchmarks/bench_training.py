"""Share of PPO wall time spent stepping the environment (target: at most 30%).

    python benchmarks/bench_training.py [--task go_stop] [--terrain dry_sand] [--timesteps 163840]

Trains with the shipped config (configs/train/ppo.yaml: 256 native environments, 8192 transitions per
update, 10 epochs of 2048-sample minibatches on a [64, 64] MLP, torch on 1 thread) and times
``step_wait``/``reset`` of the SB3 adapter (trackenv.drivers.wrappers.StepTimer) against the wall time of
``model.learn``. Also reports the share for smaller batches of environments. Every shipped driver's
record (train/drivers/*.json) holds the same measurement over its whole training run. "steady steps/s"
leaves out the first 32 768 steps (compilation and warm-up), from the run's learning curve.

``--compare-split``: each batch of environments also runs with the vector env's batched program on one
device (``trackenv.parallel.MIN_ENVS_PER_DEVICE`` raised above it), interleaved with the default (split
over the host devices from ``2 x MIN_ENVS_PER_DEVICE`` environments), in this one process.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
torch.set_num_threads(1)

from trackenv import parallel  # noqa: E402
from trackenv.drivers import load_config, train  # noqa: E402


def _run(a, n, min_envs_per_device):
    import pandas as pd  # noqa: PLC0415

    default = parallel.MIN_ENVS_PER_DEVICE
    parallel.MIN_ENVS_PER_DEVICE = min_envs_per_device
    try:
        cfg = load_config("ppo", a.task, a.terrain)
        cfg["n_envs"] = n
        cfg["n_steps"] = max(8, 8192 // n)
        with tempfile.TemporaryDirectory() as d:
            res = train(a.task, a.terrain, "ppo", config={"default": cfg}, timesteps=a.timesteps, out_dir=d,
                        progress_bar=False, tensorboard=False)
            curve = pd.read_csv(res.info["curve_csv"])
    finally:
        parallel.MIN_ENVS_PER_DEVICE = default
    late = curve[curve.timesteps >= 32768]
    steady = ((late.timesteps.iloc[-1] - late.timesteps.iloc[0]) / (late.wall_s.iloc[-1] - late.wall_s.iloc[0])
              if len(late) > 1 else float("nan"))
    return res.info, steady


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="go_stop")
    ap.add_argument("--terrain", default="dry_sand")
    ap.add_argument("--timesteps", type=int, default=163840)
    ap.add_argument("--n-envs", type=int, nargs="+", default=[256, 64])
    ap.add_argument("--compare-split", action="store_true",
                    help="also run each batch on one device, interleaved with the default (one process)")
    a = ap.parse_args()
    print("| n_envs | vector env | steps | wall s | env s | env share | steps/s | steady steps/s |")
    print("|---|---|---|---|---|---|---|---|")
    for n in a.n_envs:
        layouts = [("default", parallel.MIN_ENVS_PER_DEVICE)]
        if a.compare_split:
            layouts.insert(0, ("one device", n + 1))
        for label, per in layouts:
            r, steady = _run(a, n, per)
            devices = parallel.split_count(n, per)
            print(f"| {n} | {label} ({devices} device{'s' if devices > 1 else ''}) | {r['n_timesteps']} | "
                  f"{r['train_seconds']:.1f} | {r['env_step_seconds']:.1f} | {r['env_step_share']:.0%} | "
                  f"{r['n_timesteps'] / r['train_seconds']:.0f} | {steady:.0f} |", flush=True)


if __name__ == "__main__":
    main()
