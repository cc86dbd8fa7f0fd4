"""Seed spread of the domain-randomised drivers: retrain a driver with other seeds and count, per seed, the
held-out cases in which it beats the PI controller.

    python train/seed_spread.py GoStop-v0-asphalt-randomized --seeds 1 2     # train + evaluate seeds 1, 2
    python train/seed_spread.py --table                                      # print train/seeds.md again

Seed 0 is the shipped driver (its record in train/results.json). Each other seed is trained with the
shipped config and ``--randomize`` into ``out/seeds/s<seed>/`` (not shipped: only the counts are kept) and
evaluated on the held-out conditions of ``train/evaluate_drivers.py`` (the four held-out Table 5.5 soils,
16 draws outside the training ranges, each unmodelled effect at its library defaults). The counts go to
``train/seeds.json`` and the table to ``train/seeds.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "train"))
torch.set_num_threads(1)

from evaluate_drivers import HELD_OUT_SOILS, compare_methods, evaluate_section, held_out_cases  # noqa: E402

from trackenv.drivers import ENV_NAME, load_policy  # noqa: E402
from trackenv.drivers.config import RANDOMIZED_SUFFIX  # noqa: E402
from trackenv.drivers.episodes import jsonable  # noqa: E402
from trackenv.drivers.train import train  # noqa: E402

OUT_JSON = ROOT / "train" / "seeds.json"
OUT_MD = ROOT / "train" / "seeds.md"


def parse_name(name: str) -> tuple[str, str]:
    """(task, terrain) of a randomised driver's name, e.g. ``GoStop-v0-asphalt-randomized``."""
    if not name.endswith(RANDOMIZED_SUFFIX):
        raise SystemExit(f"{name}: not a randomised driver (<EnvName>-<terrain>{RANDOMIZED_SUFFIX})")
    stem = name[: -len(RANDOMIZED_SUFFIX)]
    for task, env_name in ENV_NAME.items():
        if stem.startswith(env_name + "-"):
            return task, stem[len(env_name) + 1:]
    raise SystemExit(f"{name}: unknown environment; known: {sorted(ENV_NAME.values())}")


def held_out_record(task, terrain, model) -> dict:
    """The held-out sections of ``evaluate_drivers.py`` for one policy (its soils section on the held-out soils)."""
    return {"soils": evaluate_section("soils", task, terrain, model, soils=HELD_OUT_SOILS),
            "outside": evaluate_section("outside", task, terrain, model),
            "effects": evaluate_section("effects", task, terrain, model)}


def counts(rec) -> dict:
    """Held-out cases, those in which the learned driver beats the PI, and the names of those it loses."""
    cases = held_out_cases(rec)
    lost = [cond for cond, res in cases if not compare_methods(res)["classical"]["beats"]]
    return {"cases": len(cases), "beats_pi": len(cases) - len(lost), "loses": lost}


def run_seed(name: str, seed: int) -> dict:
    task, terrain = parse_name(name)
    out = ROOT / "out" / "seeds" / f"s{seed}"
    t0 = time.time()
    res = train(task, terrain, seed=seed, out_dir=out, randomize=True, tensorboard=False, progress_bar=False,
                command=f"python train/seed_spread.py {name} --seeds {seed}")
    t_train = time.time() - t0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = load_policy(res.model_path, task, terrain, warn=False)
    rec = jsonable(held_out_record(task, terrain, model))
    return {"seed": seed, "train_seconds": round(t_train), "eval_seconds": round(time.time() - t0 - t_train),
            **counts(rec)}


def table(data: dict) -> str:
    rows = ["| driver | seed | held-out cases | beats PI | loses to PI on |", "|---|---|---|---|---|"]
    for name, seeds in data.items():
        for s in sorted(seeds, key=int):
            c = seeds[s]
            rows.append(f"| {name} | {s} | {c['cases']} | {c['beats_pi']} | {', '.join(c['loses']) or '-'} |")
    return "\n".join(rows) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("drivers", nargs="*", help="randomised drivers, e.g. GoStop-v0-asphalt-randomized")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--table", action="store_true", help="only write and print the table")
    a = ap.parse_args(argv)
    data = json.loads(OUT_JSON.read_text()) if OUT_JSON.is_file() else {}
    if not a.table:
        shipped = json.loads((ROOT / "train" / "results.json").read_text())
        for name in a.drivers:
            entry = data.setdefault(name, {})
            entry["0"] = {"seed": 0, "shipped": True, **counts(shipped[name])}
            for seed in a.seeds:
                entry[str(seed)] = run_seed(name, seed)
                OUT_JSON.write_text(json.dumps(data, indent=1) + "\n")
                print(f"{name} seed {seed}: {entry[str(seed)]}", flush=True)
    OUT_JSON.write_text(json.dumps(data, indent=1) + "\n")
    OUT_MD.write_text("# Seed spread of the domain-randomised drivers\n\n"
                      "Written by `python train/seed_spread.py` (module docstring). Seed 0 is the shipped driver; the others\n"
                      "are retrained with the shipped config and evaluated on the same held-out conditions\n"
                      "(train/README.md, \"Seed spread of the randomised drivers\").\n\n"
                      + table(data))
    print(table(data))


if __name__ == "__main__":
    main()
