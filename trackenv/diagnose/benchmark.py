"""The withheld-effect check: ``trackenv diagnose-benchmark --cases N``.

Blind cases come from :mod:`.blind` (a random effect of each MODEL.md §8 kind in a functional form
*different* from the candidate library's, or none; random parameters, maneuvers, rates, noise, ammeter
type and small base-parameter perturbations). Each case folder is diagnosed by :func:`.core.diagnose`
without its label (the answer key is stored outside the case folders and read only afterwards).
Reported: the confusion matrix (true label × verdict), top-1 accuracy, the false-positive rate on
null cases (an effect named where there is none), and the held-out gap shrink of the verdict on the
cases it got right; plus per case the verdict, confidence, shrink, and wall time.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from .candidates import NONE
from .core import diagnose

LABELS = ("slip_sinkage", "lateral_friction_radius", "internal_resistance", "grouser_stiction", "pitch_load_transfer",
          "sensor_artifacts", NONE)


def summarize(rows: list[dict]) -> dict:
    conf = {a: {b: 0 for b in LABELS} for a in LABELS}
    for r in rows:
        conf[r["label"]][r["verdict"]] = conf[r["label"]].get(r["verdict"], 0) + 1
    n = len(rows)
    correct = [r for r in rows if r["verdict"] == r["label"]]
    nulls = [r for r in rows if r["label"] == NONE]
    shrink = [r["shrink"] for r in correct if r["label"] != NONE]
    true_shrink = [r["true_effect_shrink"] for r in rows if r["label"] != NONE and r["true_effect_shrink"] is not None]
    return {
        "cases": n, "top1_accuracy": len(correct) / n if n else None,
        "null_cases": len(nulls),
        "null_false_positive_rate": (sum(r["verdict"] != NONE for r in nulls) / len(nulls)) if nulls else None,
        "effect_cases": n - len(nulls),
        "effect_recall": (sum(r["verdict"] == r["label"] for r in rows if r["label"] != NONE) / (n - len(nulls)))
        if n > len(nulls) else None,
        "median_heldout_shrink_when_right": float(np.median(shrink)) if shrink else None,
        "median_heldout_shrink_of_true_effect": float(np.median(true_shrink)) if true_shrink else None,
        "median_wall_s": float(np.median([r["wall_s"] for r in rows])) if rows else None,
        "confusion": conf,
    }


def confusion_figure(summary: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.array([[summary["confusion"][a][b] for b in LABELS] for a in LABELS])
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    ax.imshow(m, cmap="Blues")
    short = [s.replace("_", "\n") for s in LABELS]
    ax.set_xticks(range(len(LABELS)), short, fontsize=7)
    ax.set_yticks(range(len(LABELS)), short, fontsize=7)
    ax.set_xlabel("verdict")
    ax.set_ylabel("withheld effect (true label)")
    for i in range(len(LABELS)):
        for k in range(len(LABELS)):
            if m[i, k]:
                ax.text(k, i, str(m[i, k]), ha="center", va="center", color="white" if m[i, k] > m.max() / 2 else "k")
    ax.set_title(f"blind benchmark (SYNTHETIC): top-1 {summary['top1_accuracy']:.2f}, "
                 f"null FPR {summary['null_false_positive_rate'] if summary['null_false_positive_rate'] is not None else float('nan'):.2f}",
                 fontsize=9)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def run_benchmark(out_dir: str | Path, n_cases: int, seed: int = 0, null_fraction: float = 0.2,
                  labels: list[str] | None = None, n_tests: int | None = None, progress: bool = True,
                  **diagnose_kwargs) -> dict:
    """Generate ``n_cases`` blind cases in ``out_dir``, diagnose each, score against the withheld labels."""
    from tqdm.auto import tqdm

    from . import blind

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if labels:
        answers = []
        for k, lab in enumerate(labels):
            truth = blind.make_case(out / "cases" / f"case_{k:03d}", np.random.default_rng([seed, k]), label=lab,
                                    n_tests=n_tests)
            answers.append({"case": f"case_{k:03d}", **truth})
        (out / "answers.json").write_text(json.dumps(answers, indent=1) + "\n", encoding="utf-8")
    else:
        answers = blind.make_cases(out, n_cases, seed=seed, null_fraction=null_fraction)
    t_gen = time.perf_counter() - t0
    rows = []
    for a in tqdm(answers, desc="diagnosing blind cases", unit="case", disable=not progress):
        t1 = time.perf_counter()
        d = diagnose(out / "cases" / a["case"], out / "reports" / a["case"], figures=False, progress=False,
                     seed=seed, **diagnose_kwargs)
        v = d.verdict
        rank = {r["effect"]: r for r in d.report["ranking"]}
        rows.append({"case": a["case"], "label": a["label"], "verdict": v["effect"], "confidence": v["confidence"],
                     "best_candidate": v["best_candidate"], "reason": v["reason"],
                     "shrink": v["heldout_gap_shrink"], "gap_before": v["gap_before"],
                     "true_effect_shrink": rank[a["label"]]["heldout_gap_shrink"] if a["label"] in rank else None,
                     "terrain": a["terrain"], "n_tests": len(a["tests"]),
                     "maneuvers": [t["maneuver"] for t in a["tests"]], "wall_s": time.perf_counter() - t1})
    summary = summarize(rows)
    summary["generation_s"] = t_gen
    summary["total_s"] = time.perf_counter() - t0
    result = {"note": "SYNTHETIC blind cases (trackenv.diagnose.blind): alternative effect forms, labels withheld "
                      "from the diagnosis", "seed": seed, "summary": summary, "cases": rows}
    (out / "benchmark.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    confusion_figure(summary, out / "confusion.png")
    L = ["# Blind benchmark of `trackenv diagnose` (SYNTHETIC cases)", "",
         f"{summary['cases']} cases ({summary['null_cases']} null), seed {seed}; effects in forms different from the "
         "candidate library (trackenv/diagnose/blind.py); labels withheld from the diagnosis.", "",
         f"- top-1 accuracy: **{summary['top1_accuracy']:.2f}**",
         f"- null false-positive rate: **{summary['null_false_positive_rate']}**",
         f"- median held-out gap shrink when right: **{summary['median_heldout_shrink_when_right']}**",
         f"- median held-out shrink of the true effect's candidate: {summary['median_heldout_shrink_of_true_effect']}",
         f"- median wall time per case: {summary['median_wall_s']:.0f} s", "", "![confusion](confusion.png)", "",
         "| case | label | verdict | confidence | shrink | tests | reason |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['case']} | {r['label']} | {r['verdict']} | {r['confidence']:.2f} | {100 * r['shrink']:.0f}% | "
                 f"{', '.join(r['maneuvers'])} ({r['terrain']}) | {r['reason']} |")
    (out / "benchmark.md").write_text("\n".join(L) + "\n", encoding="utf-8")
    return result
