"""The withheld-effect check: ``trackenv diagnose-benchmark --cases N``.

Blind cases come from :mod:`.blind` (a random effect of each docs/model.md §8 kind in a functional form
*different* from the candidate library's, or none; random parameters, maneuvers, rates, noise, ammeter
type and small base-parameter perturbations). Each case folder is diagnosed by :func:`.core.diagnose`
without its label (the answer key is stored outside the case folders and read only afterwards).
Reported: the confusion matrix (true label × verdict), top-1 accuracy, the false-positive rate on
null cases (an effect named where there is none), and the held-out gap shrink of the verdict on the
cases it got right; plus per case the verdict, confidence, shrink, and wall time; and the detection
power against the effect's size (``power.png``: the fraction of effect cases named correctly per bin
of the answer key's visibility, the largest 0.25 s-averaged difference the effect makes, in noise σ).

Every case's expensive part is cached: ``reports/<case>/evidence.{json,npz}`` holds each candidate's
per-sample held-out and in-sample loss terms and the gap statistics (:func:`.core.save_evidence`).
A case whose cache exists is not re-fitted, and :func:`rescore` re-applies the verdict rule
(:func:`.core.decide`, e.g. with another α) to every case in seconds.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..params import is_integer, is_positive, is_real
from .blind import NEAR_LIMIT
from .candidates import NONE
from .core import check_options, diagnose
from .data import DiagnosisError

LABELS = ("slip_sinkage", "lateral_friction_radius", "internal_resistance", "grouser_stiction", "pitch_load_transfer",
          "sensor_artifacts", NONE)


def rate_upper_bound(k: int, n: int, level: float = 0.95) -> float | None:
    """One-sided Clopper-Pearson upper bound of a rate seen ``k`` times in ``n`` trials: the largest rate
    under which ``k`` or fewer would be seen with probability at least 1 - ``level`` (0/59 → 0.050)."""
    from scipy.stats import beta  # noqa: PLC0415

    if n <= 0:
        return None
    return 1.0 if k >= n else float(beta.ppf(level, k + 1, n - k))


def summarize(rows: list[dict]) -> dict:
    conf = {a: {b: 0 for b in LABELS} for a in LABELS}
    for r in rows:
        conf[r["label"]][r["verdict"]] = conf[r["label"]].get(r["verdict"], 0) + 1
    n = len(rows)
    correct = [r for r in rows if r["verdict"] == r["label"]]
    nulls = [r for r in rows if r["label"] == NONE]
    shrink = [r["shrink"] for r in correct if r["label"] != NONE]
    own = [r["own_shrink"] for r in correct if r["label"] != NONE and r.get("own_shrink") is not None]
    true_shrink = [r["true_effect_shrink"] for r in rows if r["label"] != NONE and r["true_effect_shrink"] is not None]
    flagged = sum(r["verdict"] != NONE for r in nulls)
    return {
        "cases": n, "correct": len(correct), "top1_accuracy": len(correct) / n if n else None,
        "null_cases": len(nulls), "null_flagged": flagged,
        "null_false_positive_rate": flagged / len(nulls) if nulls else None,
        "null_false_positive_rate_upper95": rate_upper_bound(flagged, len(nulls)),
        "effect_cases": n - len(nulls),
        "effect_recall": (sum(r["verdict"] == r["label"] for r in rows if r["label"] != NONE) / (n - len(nulls)))
        if n > len(nulls) else None,
        "median_heldout_shrink_when_right": float(np.median(shrink)) if shrink else None,
        "median_own_shrink_when_right": float(np.median(own)) if own else None,
        "median_heldout_shrink_of_true_effect": float(np.median(true_shrink)) if true_shrink else None,
        "median_wall_s": float(np.median([r["wall_s"] for r in rows])) if rows else None,
        "confusion": conf,
    }


def near_limit_summary(rows: list[dict]) -> dict:
    """The cases drawn near the detection limit: how many, how many named, and how many of them really landed in
    the :data:`.blind.NEAR_LIMIT` window of visibility (the generator keeps the closest of its draws otherwise)."""
    nl = [r for r in rows if r.get("near_limit")]
    win = [r for r in nl if r.get("visibility") is not None and NEAR_LIMIT[0] <= r["visibility"] <= NEAR_LIMIT[1]]
    named = [r for r in nl if r["verdict"] == r["label"]]
    return {"near_limit_cases": len(nl), "near_limit_named": len(named),
            "near_limit_recall": len(named) / len(nl) if nl else None,
            "near_limit_in_window": len(win), "near_limit_in_window_named": sum(r["verdict"] == r["label"] for r in win)}


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


def power_figure(rows: list[dict], path: Path, edges=(0, 1, 2, 3, 4, 8, 16, 1e9)) -> Path:
    """Detection power (effect named correctly) against the effect's visibility [noise σ], with counts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    eff = [r for r in rows if r["label"] != NONE and r.get("visibility") is not None]
    xs, ys, ns, lo, hi = [], [], [], [], []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = [r for r in eff if a <= r["visibility"] < b]
        if not sel:
            continue
        k = sum(r["verdict"] == r["label"] for r in sel)
        n = len(sel)
        from scipy.stats import beta

        xs.append(np.median([r["visibility"] for r in sel]))
        ys.append(k / n)
        ns.append(n)
        lo.append(beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0)
        hi.append(beta.ppf(0.975, k + 1, n - k) if k < n else 1.0)
    fig, ax = plt.subplots(figsize=(6, 4))
    ys_a = np.array(ys)
    ax.errorbar(xs, ys, yerr=[ys_a - np.array(lo), np.array(hi) - ys_a], fmt="o-", capsize=3,
                label="effect named correctly (95% Clopper-Pearson)")
    for x, y, n in zip(xs, ys, ns):
        ax.annotate(f"n={n}", (x, y), textcoords="offset points", xytext=(4, -12), fontsize=7)
    nulls = [r for r in rows if r["label"] == NONE]
    if nulls:
        flagged = sum(r["verdict"] != NONE for r in nulls)
        ax.axhline(flagged / len(nulls), color="tab:red", ls="--", lw=1,
                   label=f"null false-positive rate ({flagged} / {len(nulls)} null cases; 95 % bound "
                         f"{rate_upper_bound(flagged, len(nulls)):.3f})")
    if xs:
        ax.set_xscale("log")
    else:  # a benchmark of null cases only (a false-positive calibration): no power to plot
        ax.text(0.5, 0.5, "no effect cases", transform=ax.transAxes, ha="center", color="0.4")
    ax.set_xlabel("effect size: max 0.25 s-averaged difference it makes [noise σ] (answer key)")
    ax.set_ylabel("fraction")
    ax.set_ylim(-0.05, 1.05)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("detection power vs effect size (SYNTHETIC blind cases)", fontsize=9)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _row(a: dict, v: dict, rank: dict, wall_s: float) -> dict:
    return {"case": a["case"], "label": a["label"], "verdict": v["effect"], "confidence": v["confidence"],
            "best_candidate": v["best_candidate"], "reason": v["reason"], "verdict_line": v.get("verdict_line", ""),
            "shrink": v["heldout_gap_shrink"], "insample_shrink": v.get("insample_gap_shrink"),
            "own_shrink": v.get("heldout_gap_shrink_own"),
            "shrink_ci": v.get("heldout_gap_shrink_ci"), "gap_before": v["gap_before"],
            "gap_p": (v.get("gap_test") or {}).get("p"),
            "true_effect_shrink": rank[a["label"]]["heldout_gap_shrink"] if a["label"] in rank else None,
            "terrain": a["terrain"], "n_tests": len(a["tests"]), "near_limit": a.get("near_limit", False),
            "visibility": a.get("max_visibility"),
            "maneuvers": [t["maneuver"] for t in a["tests"]], "wall_s": wall_s}


def check_benchmark_options(*, n_cases: int, labels: list[str] | None = None, null_fraction: float = 0.2,
                            n_tests: int | None = None, t_max: float | None = None,
                            near_limit_fraction: float = 1 / 3) -> None:
    """Raise :class:`.data.DiagnosisError` naming the option if the blind cases of :func:`run_benchmark` cannot be
    drawn: ``n_cases`` >= 1 (unless ``labels`` are given), ``null_fraction`` and ``near_limit_fraction`` in
    [0, 1], ``n_tests`` None or 1 to ``blind.MAX_TESTS``, ``t_max`` None or a positive duration [s]."""
    from .blind import MAX_TESTS

    if not labels and not (is_integer(n_cases) and n_cases >= 1):
        raise DiagnosisError(f"n_cases (the number of blind cases) must be an integer >= 1, got {n_cases!r}")
    for name, value in (("null_fraction", null_fraction), ("near_limit_fraction", near_limit_fraction)):
        if not (is_real(value) and 0.0 <= value <= 1.0):
            raise DiagnosisError(f"{name} must be a fraction in [0, 1], got {value!r}")
    if n_tests is not None and not (is_integer(n_tests) and 1 <= n_tests <= MAX_TESTS):
        raise DiagnosisError(f"n_tests (tests per case) must be an integer from 1 to {MAX_TESTS}, got {n_tests!r}")
    if t_max is not None and not is_positive(t_max):
        raise DiagnosisError(f"t_max (the longest test) must be a positive duration [s], got {t_max!r}")


def run_benchmark(out_dir: str | Path, n_cases: int, seed: int = 0, null_fraction: float = 0.2,
                  labels: list[str] | None = None, n_tests: int | None = None, t_max: float | None = None,
                  near_limit_fraction: float = 1 / 3, progress: bool = True, **diagnose_kwargs) -> dict:
    """Generate ``n_cases`` blind cases in ``out_dir`` (kept if already there), diagnose each (cached), score
    against the withheld labels. ``n_tests``/``t_max``: tests per case and their longest duration [s]."""
    from tqdm.auto import tqdm

    from . import blind

    check_benchmark_options(n_cases=n_cases, labels=labels, null_fraction=null_fraction, n_tests=n_tests,
                            t_max=t_max, near_limit_fraction=near_limit_fraction)
    check_options(seed=seed, **{k: v for k, v in diagnose_kwargs.items()
                                if k in ("rounds", "search_points", "polish_iters", "alpha", "substep", "pad_s")})
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if (out / "answers.json").exists():
        answers = json.loads((out / "answers.json").read_text())
    elif labels:
        answers = []
        for k, lab in enumerate(labels):
            near = lab != NONE and near_limit_fraction > 0 and k % max(1, round(1 / near_limit_fraction)) == 1
            truth = blind.make_case(out / "cases" / f"case_{k:03d}", np.random.default_rng([seed, k]), label=lab,
                                    n_tests=n_tests, t_max=t_max, near_limit=near)
            answers.append({"case": f"case_{k:03d}", **truth})
        (out / "answers.json").write_text(json.dumps(answers, indent=1) + "\n", encoding="utf-8")
    else:
        answers = blind.make_cases(out, n_cases, seed=seed, null_fraction=null_fraction, n_tests=n_tests,
                                   t_max=t_max, near_limit_fraction=near_limit_fraction)
    t_gen = time.perf_counter() - t0
    pad = diagnose_kwargs.pop("pad_s", None)
    if pad is None and t_max is not None:
        pad = t_max
    rows = []
    for a in tqdm(answers, desc="diagnosing blind cases", unit="case", disable=not progress):
        rep_dir = out / "reports" / a["case"]
        row_file = rep_dir / "row.json"
        if row_file.exists() and (rep_dir / "evidence.npz").exists():
            rows.append(json.loads(row_file.read_text()))
            continue
        t1 = time.perf_counter()
        d = diagnose(out / "cases" / a["case"], rep_dir, figures=False, progress=False, seed=seed, pad_s=pad,
                     cache=rep_dir, **diagnose_kwargs)
        rank = {r["effect"]: r for r in d.report["ranking"]}
        row = _row(a, d.verdict, rank, time.perf_counter() - t1)
        row_file.write_text(json.dumps(row, indent=1) + "\n")
        rows.append(row)
    return _write(out, rows, seed, {"generation_s": t_gen, "total_s": time.perf_counter() - t0})


def rescore(out_dir: str | Path, alpha: float | None = None, write: bool = True, exclude=(), **rule) -> dict:
    """Re-apply the verdict rule to every cached case of a benchmark (no fitting): the new summary; with
    ``write``, ``benchmark.{json,md}`` and the figures are rewritten from it. ``exclude``: candidates left
    out of the cached evidence (:func:`.core.without`)."""
    from .core import ALPHA, analysis_flags, decide, flag_penalty, load_evidence, rested_on, without

    if alpha is not None:
        check_options(alpha=alpha)
    out = Path(out_dir)
    answers = {a["case"]: a for a in json.loads((out / "answers.json").read_text())}
    rows = []
    for row_file in sorted((out / "reports").glob("*/row.json")):
        row = json.loads(row_file.read_text())
        ev = without(load_evidence(row_file.parent), exclude)
        v = decide(ev, alpha=ALPHA if alpha is None else alpha, **rule)
        chosen = rested_on(v)
        # the same flags and confidence penalty as the run's (the candidate list, if any, was the run's)
        confidence = v["confidence"] * flag_penalty(analysis_flags(ev, chosen, restricted=False))
        row.update({"verdict": v["effect"], "confidence": confidence, "reason": v["reason"],
                    "shrink": ev["candidates"][chosen]["heldout_shrink"] if v["effect"] != NONE else 0.0,
                    "own_shrink": v.get("own_shrink"), "visibility": answers[row["case"]].get("max_visibility")})
        rows.append(row)
    if write:
        old = json.loads((out / "benchmark.json").read_text()) if (out / "benchmark.json").exists() else {}
        seed = old.get("seed", 0)
        timing = {k: old.get("summary", {}).get(k) for k in ("generation_s", "total_s") if k in old.get("summary", {})}
        _write(out, rows, seed, timing | {"rescored": True})
    return summarize(rows) | near_limit_summary(rows) | {"rows": rows}


def _write(out: Path, rows: list[dict], seed: int, timing: dict) -> dict:
    summary = summarize(rows)
    summary.update(timing)
    summary.update(near_limit_summary(rows))
    nl_named, nl, win_named, win = (summary[k] for k in ("near_limit_named", "near_limit_cases",
                                                         "near_limit_in_window_named", "near_limit_in_window"))
    by_label = {}
    for r in rows:
        d = by_label.setdefault(r["label"], [0, 0])
        d[0] += r["verdict"] == r["label"]
        d[1] += 1
    summary["by_label"] = {k: f"{a}/{b}" for k, (a, b) in by_label.items()}
    result = {"note": "SYNTHETIC blind cases (trackenv.diagnose.blind): alternative effect forms, labels withheld "
                      "from the diagnosis", "seed": seed, "summary": summary, "cases": rows}
    (out / "benchmark.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    confusion_figure(summary, out / "confusion.png")
    power_figure(rows, out / "power.png")
    med = summary["median_heldout_shrink_when_right"]
    own_med = summary.get("median_own_shrink_when_right")
    true_med = summary["median_heldout_shrink_of_true_effect"]
    L = ["# Blind benchmark of `trackenv diagnose` (SYNTHETIC cases)", "",
         f"{summary['cases']} cases ({summary['null_cases']} null, {summary['near_limit_cases']} near the detection "
         f"limit), seed {seed}; effects in forms different from the candidate library (trackenv/diagnose/blind.py); "
         "labels withheld from the diagnosis.", "",
         f"- top-1 accuracy: **{summary['top1_accuracy']:.2f}** ({summary['correct']} / {summary['cases']})",
         f"- null cases flagged: **{summary['null_flagged']} / {summary['null_cases']}**"
         + ("" if not summary["null_cases"] else
            f" (the false-positive rate is below {summary['null_false_positive_rate_upper95']:.3f}: one-sided 95 %, "
            "Clopper-Pearson)"),
         f"- median held-out gap shrink when right: **{'–' if med is None else f'{med:.2f}'}** (from the base model; "
         f"the effect's own part, beyond recalibrating the base: {'–' if own_med is None else f'{own_med:.2f}'})",
         f"- median held-out gap shrink of the true label's candidate, every effect case: "
         f"{'–' if true_med is None else f'{true_med:.2f}'}",
         f"- near-limit effect cases named correctly: {nl_named} / {nl}; of them {win} landed in the "
         f"{NEAR_LIMIT[0]:g}-{NEAR_LIMIT[1]:g} σ window (the others keep the closest of their draws), "
         f"named {win_named} / {win}",
         f"- by label (correct/cases): {', '.join(f'{k} {v}' for k, v in summary['by_label'].items())}",
         f"- median wall time per case: {summary['median_wall_s']:.0f} s", "",
         "![confusion](confusion.png) ![power](power.png)", "",
         "| case | label | verdict | confidence | held-out shrink | own part | in-sample shrink | size [σ] | tests | reason |",
         "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        vis = "–" if r.get("visibility") is None else f"{r['visibility']:.1f}" + (" (near limit)" if r.get("near_limit") else "")
        ins = "–" if r.get("insample_shrink") is None else f"{100 * r['insample_shrink']:.0f}%"
        own = "–" if r.get("own_shrink") is None or r["verdict"] == NONE else f"{100 * r['own_shrink']:.0f}%"
        L.append(f"| {r['case']} | {r['label']} | {r['verdict']} | {r['confidence']:.2f} | {100 * r['shrink']:.0f}% | "
                 f"{own} | {ins} | {vis} | {', '.join(r['maneuvers'])} ({r['terrain']}) | {r['reason']} |")
    (out / "benchmark.md").write_text("\n".join(L) + "\n", encoding="utf-8")
    return result


def refresh_gap_tests(out_dir: str | Path, pad_s: float | None = None, internal_resistance: str = "constant") -> int:
    """Recompute the gap test (:func:`.core.gap_cells`) of every cached case from its logs and one simulation
    of the base model (seconds per case; the fits are not touched). Returns the number of cases updated."""
    from .batch import BatchSimulator
    from .candidates import candidate_set
    from .core import ALPHA, gap_cells
    from .data import load_tests

    out = Path(out_dir)
    none = [c for c in candidate_set(internal_resistance) if c.name == NONE][0]
    k = 0
    for ev_file in sorted((out / "reports").glob("*/evidence.json")):
        data, _ = load_tests(out / "cases" / ev_file.parent.name)
        pred, _ = BatchSimulator(data, internal_resistance, pad_s=pad_s).run(none, {})
        pred = [{s: v[:, 0] for s, v in p.items()} for p in pred]
        ev = json.loads(ev_file.read_text())
        cells = gap_cells(data, pred)
        ev["gap_cells"] = cells
        ev["gap_cells_tested"] = len(cells)
        ev["gap_p"] = min(1.0, min(c["p"] for c in cells) * len(cells)) if cells else 1.0
        ev["gap_z_max"] = max((c["z"] for c in cells), default=0.0)
        ev["gap_alpha"] = ALPHA
        ev_file.write_text(json.dumps(ev, indent=1) + "\n")
        k += 1
    return k
