"""Share of PPO wall time spent stepping the environment (target: at most 30%).

    python benchmarks/bench_training.py [--task go_stop] [--terrain dry_sand] [--timesteps 163840]

Trains with the shipped config (configs/train/ppo.yaml: 256 native environments, 8192 transitions per
update, 10 epochs of 2048-sample minibatches on a [64, 64] MLP, torch on 1 thread) and times
``step_wait``/``reset`` of the SB3 adapter (trackenv.drivers.wrappers.StepTimer) against the wall time of
``model.learn``. Also reports the share for smaller batches of environments. Every shipped driver's
record (train/drivers/*.json) holds the same measurement over its whole training run.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
torch.set_num_threads(1)

from trackenv.drivers import load_config, train  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--task", default="go_stop")
    ap.add_argument("--terrain", default="dry_sand")
    ap.add_argument("--timesteps", type=int, default=163840)
    ap.add_argument("--n-envs", type=int, nargs="+", default=[256, 64])
    a = ap.parse_args()
    print("| n_envs | steps | wall s | env s | env share | steps/s |")
    print("|---|---|---|---|---|---|")
    for n in a.n_envs:
        cfg = load_config("ppo", a.task, a.terrain)
        cfg["n_envs"] = n
        cfg["n_steps"] = max(8, 8192 // n)
        with tempfile.TemporaryDirectory() as d:
            r = train(a.task, a.terrain, "ppo", config={"default": cfg}, timesteps=a.timesteps, out_dir=d,
                      progress_bar=False, tensorboard=False).info
        print(f"| {n} | {r['n_timesteps']} | {r['train_seconds']:.1f} | {r['env_step_seconds']:.1f} | "
              f"{r['env_step_share']:.0%} | {r['n_timesteps'] / r['train_seconds']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
