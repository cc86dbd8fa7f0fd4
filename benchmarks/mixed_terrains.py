"""Folders that span two terrains, built from a blind benchmark's cases: one pooled diagnosis against one per terrain.

    trackenv diagnose-benchmark --cases 40 --seed 0 --out out/bench40 ...   # the benchmark of docs/diagnose_benchmark.md
    python benchmarks/mixed_terrains.py --bench out/bench40 --out out/mixed [--pairs case_035+case_029,...]

Each pair joins a deformable-ground case and an asphalt case of the benchmark (SYNTHETIC, their effects withheld)
into one folder of four tests. Where both cases carry the same effect (or none), the right answer is that effect;
where they differ, it is each terrain's own, which one pooled diagnosis cannot give. Both designs run with the
benchmark's budget (1 Latin-hypercube round of 8 points, 1 cross-entropy round, 3 Levenberg-Marquardt iterations,
tests padded to ``--t-max`` s, seed 0): ``trackenv.diagnose.diagnose`` on the four tests, and
``trackenv.diagnose.diagnose_each_terrain``, whose two diagnoses are the benchmark's own two cases' (the script
checks that they give the benchmark's verdicts). Prints a table and writes ``<out>/results.json`` and ``results.md``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from tqdm.auto import tqdm

import trackenv  # noqa: F401  (host devices are set up at import)
from trackenv.diagnose import diagnose, diagnose_each_terrain

# (deformable-ground case, asphalt case) of the 40-case benchmark: five with one effect (or none) on both grounds,
# three with a different effect on each
PAIRS = ["case_035+case_029", "case_017+case_024", "case_026+case_030", "case_016+case_000", "case_009+case_005",
         "case_010+case_012", "case_006+case_013", "case_039+case_008"]
BUDGET = {"rounds": 1, "search_points": 8, "polish_iters": 3, "seed": 0}


def build(bench: Path, pair: str, out: Path) -> tuple[Path, dict]:
    """The pair's folder (each test renamed ``<case>_<test>``) and its answer {terrain: effect}."""
    answers = {a["case"]: a for a in json.loads((bench / "answers.json").read_text())}
    folder = out / "cases" / pair
    if folder.exists():
        shutil.rmtree(folder)
    truth = {}
    for case in pair.split("+"):
        for test in sorted((bench / "cases" / case).iterdir()):
            if test.is_dir():
                shutil.copytree(test, folder / f"{case}_{test.name}")
        a = answers[case]
        row = json.loads((bench / "reports" / case / "row.json").read_text())
        truth[a["terrain"]] = {"effect": row["label"] or "none", "case": case, "benchmark_verdict": row["verdict"]}
    return folder, truth


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bench", type=Path, required=True, help="a trackenv diagnose-benchmark output folder")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--pairs", default=",".join(PAIRS))
    ap.add_argument("--t-max", type=float, default=6.0, help="the benchmark's --t-max (the tests' padding) [s]")
    ap.add_argument("--table", action="store_true", help="only print the table of <out>/results.json again")
    a = ap.parse_args()
    if a.table:
        return table(json.loads((a.out / "results.json").read_text()), a.out)
    rows = []
    for pair in tqdm(a.pairs.split(","), desc="mixed-terrain pairs", unit="pair"):
        folder, truth = build(a.bench, pair, a.out)
        effects = {t["effect"] for t in truth.values()}
        t0 = time.perf_counter()
        pooled = diagnose(folder, a.out / "reports" / pair / "pooled", figures=False, progress=False, pad_s=a.t_max,
                          **BUDGET)
        t1 = time.perf_counter()
        each = diagnose_each_terrain(folder, a.out / "reports" / pair / "each", figures=False, progress=False,
                                     pad_s=a.t_max, **BUDGET)
        t2 = time.perf_counter()
        by = each.verdict["effects_by_terrain"]
        rows.append({
            "pair": pair, "truth": {t: v["effect"] for t, v in truth.items()},
            "pooled": pooled.verdict["effect"], "pooled_line": pooled.verdict["verdict_line"],
            "pooled_right": len(effects) == 1 and pooled.verdict["effect"] == next(iter(effects)),
            "pooled_names_one": pooled.verdict["effect"] in effects,
            "each": by, "each_combined": each.verdict["effect"],
            "each_right": all(by[t] == v["effect"] for t, v in truth.items()),
            "each_as_benchmark": all(by[t] == v["benchmark_verdict"] for t, v in truth.items()),
            "pooled_s": t1 - t0, "each_s": t2 - t1,
        })
        (a.out / "results.json").write_text(json.dumps(rows, indent=1) + "\n")
    table(rows, a.out)


def table(rows: list[dict], out: Path) -> None:
    """Write ``<out>/results.md`` and print it. A verdict is right where it names the pair's one effect (or
    ``none``); where the two cases' effects differ, only one diagnosis per terrain can be right, each terrain
    naming its own. "combined": the per-terrain summary's one verdict (``none``, the effect, or ``several``)."""
    lines = ["| pair | truth | pooled | per terrain | combined | pooled s | per terrain s |",
             "|---|---|---|---|---|---|---|"]
    right_combined = 0
    for r in rows:
        same = len(set(r["truth"].values())) == 1
        ok = r["each_combined"] == next(iter(r["truth"].values())) if same else r["each_right"]
        right_combined += ok
        truth = ", ".join(f"{e} ({t})" for t, e in r["truth"].items())
        each = ", ".join(f"{e} ({t})" for t, e in r["each"].items())
        lines.append(f"| {r['pair']} | {truth} | {r['pooled']}{' ✓' if r['pooled_right'] else ''} | "
                     f"{each}{' ✓' if r['each_right'] else ''} | {r['each_combined']}{' ✓' if ok else ''} | "
                     f"{r['pooled_s']:.0f} | {r['each_s']:.0f} |")
    n = len(rows)
    lines += ["", f"pooled right {sum(r['pooled_right'] for r in rows)} / {n} (names one of the pair's effects: "
              f"{sum(r['pooled_names_one'] for r in rows)}); per terrain, every terrain right "
              f"{sum(r['each_right'] for r in rows)} / {n}, the combined verdict right {right_combined} / {n}; "
              f"per terrain as the benchmark's own two cases {sum(r['each_as_benchmark'] for r in rows)} / {n}"]
    (out / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

if __name__ == "__main__":
    main()
