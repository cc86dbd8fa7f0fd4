"""``diagnose_each_terrain``: one diagnosis per terrain of a folder whose tests span several terrains.

:func:`.core.diagnose` fits one effect to all the tests it is given. The thesis's gaps differ by terrain (slip
sinkage on sand, grouser stiction on asphalt: docs/model.md §8), and so may a field campaign's, so one effect
fitted to a mixed folder can be the wrong answer for each terrain (it says so in its flags). This module splits
the tests by their ``meta.json`` terrain, diagnoses each group on its own (``<out>/<terrain>/report.{md,json}``,
unchanged from :func:`.core.diagnose`), and writes a summary (``<out>/report.{md,json}``) with every terrain's
verdict and the combined one:

- ``none`` where no terrain names an effect;
- the effect itself where every terrain that names one names the same;
- ``several`` where the terrains name different effects (``verdict.effects_by_terrain`` lists them).

What it gives up: an effect of the vehicle or of its instruments, common to every terrain, is fitted and tested
on each terrain's tests alone, with less data than a pooled diagnosis has; a terrain with a single test gets the
single-test design (forward chaining, flagged).
"""

from __future__ import annotations

import inspect
import json
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..compare import json_clean as _clean
from .candidates import NONE
from .core import Diagnosis, check_options, diagnose
from .data import load_tests

SEVERAL = "several"
MODE = "each terrain"


@dataclass
class TerrainDiagnoses:
    """The result of :func:`diagnose_each_terrain`: one :class:`.core.Diagnosis` per terrain, and the summary
    (``report``, what the summary's ``report.json`` holds)."""

    by_terrain: dict  # terrain -> Diagnosis, in the order the terrains first appear among the tests
    report: dict
    out_dir: Path | None = None
    files: dict = field(default_factory=dict)

    @property
    def verdict(self) -> dict:
        return self.report["verdict"]


def terrain_groups(folder: str | Path, tests: list[str] | None = None) -> tuple[dict, list[dict]]:
    """``({terrain: [test names]}, excluded)``: the usable tests of ``folder`` grouped by their meta.json terrain,
    in the order they are read, and the tests :func:`.data.load_tests` excluded (with the reason)."""
    data, excluded = load_tests(folder, tests)
    groups: dict[str, list[str]] = {}
    for t in data:
        groups.setdefault(str(t.terrain), []).append(t.name)
    return groups, excluded


def folder_name(terrain: str, taken: set[str]) -> str:
    """A sub-folder name for ``terrain`` (a terrain id, or a YAML path): its file stem with characters other than
    letters, digits, ``.``, ``_`` and ``-`` replaced, made unique among ``taken``."""
    stem = Path(terrain).stem if terrain.endswith((".yaml", ".yml")) else terrain
    base = re.sub(r"[^A-Za-z0-9._-]", "_", stem).strip("._") or "terrain"
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


def combined_verdict(verdicts: dict, n_tests: dict | None = None) -> dict:
    """The summary's verdict from each terrain's (``{terrain: verdict dict of report.json}``): ``none``, the one
    effect every terrain that names one names, or ``several``. Its confidence is the lowest of the confidences of
    the terrains that name an effect (of all the terrains where none does); its flags are the terrains' own,
    each prefixed with its terrain. ``n_tests``: {terrain: number of tests} for :func:`combined_shrink`
    (default one each)."""
    effects = {t: v["effect"] for t, v in verdicts.items()}
    named = sorted({e for e in effects.values() if e not in (NONE, None)})
    naming = [t for t, e in effects.items() if e not in (NONE, None)]
    effect = NONE if not named else named[0] if len(named) == 1 else SEVERAL
    conf = min((verdicts[t]["confidence"] for t in (naming or list(verdicts))), default=0.0)
    parts = [f"{t}: {v['verdict_line']}" for t, v in verdicts.items()]
    if effect == NONE:
        head = f"none on every terrain ({len(verdicts)})"
    elif effect == SEVERAL:
        head = "several effects: " + ", ".join(f"{effects[t]} on {t}" for t in naming)
    else:
        quiet = [t for t in verdicts if t not in naming]
        head = f"{effect} on {', '.join(naming)}" + (f"; none on {', '.join(quiet)}" if quiet else "")
    flags = [f"{t}: {f}" for t, v in verdicts.items() for f in v.get("flags", [])]
    out = {"effect": effect, "confidence": conf, "effects_by_terrain": effects, "flags": flags,
           "verdict_line": head + " | " + " | ".join(parts)}
    return out | combined_shrink(verdicts, n_tests or {t: 1 for t in verdicts})


def combined_shrink(verdicts: dict, n_tests: dict) -> dict:
    """The gap shrink over all the tests with each terrain's named effect in its model (the base model where a
    terrain names none), held out and in sample. The gap (noise units, :func:`.metrics.overall_gap`) is the root
    of a mean over tests, so the terrains' squared gaps combine weighted by their test counts. The intervals are
    the terrain's own where there is one terrain, and None otherwise: the terrains' bootstraps are not joined, and
    one terrain's interval need not contain the combined figure."""
    w = {t: n_tests[t] / sum(n_tests.values()) for t in verdicts}
    named = [t for t, v in verdicts.items() if v["effect"] not in (NONE, None)]

    def shrink(before_key: str, after_of) -> float:
        before = sum(w[t] * verdicts[t][before_key] ** 2 for t in verdicts)
        after = sum(w[t] * (after_of(t) if t in named else verdicts[t][before_key]) ** 2 for t in verdicts)
        return float(1.0 - np.sqrt(after / before)) if before > 0 else 0.0

    held = shrink("gap_before_heldout", lambda t: verdicts[t]["gap_after"])
    ins = shrink("gap_before", lambda t: verdicts[t]["gap_before"] * (1.0 - verdicts[t]["insample_gap_shrink"]))
    one = verdicts[named[0]] if named and len(verdicts) == 1 else None
    return {"heldout_gap_shrink": held if named else 0.0, "insample_gap_shrink": ins if named else 0.0,
            "heldout_gap_shrink_ci": None if one is None else one["heldout_gap_shrink_ci"],
            "insample_gap_shrink_ci": None if one is None else one["insample_gap_shrink_ci"],
            "shrink_over": "all tests, each terrain's named effect in its model (the base model where it names none)"}


def _summary_md(report: dict) -> str:
    v = report["verdict"]
    lines = [
        "# Gap diagnosis, each terrain on its own", "",
        f"Folder: `{report['folder']}`. {report['data_label']}", "",
        f"**Verdict: {v['effect']}** (lowest confidence among the terrains it rests on: {v['confidence']:.2f})."
        + ("" if v["effect"] == NONE else
           f" Over all {sum(len(e['tests']) for e in report['terrains'].values())} tests, with each terrain's named "
           f"effect in its model: held-out gap shrink {100 * v['heldout_gap_shrink']:.0f}%, in-sample "
           f"{100 * v['insample_gap_shrink']:.0f}%."), "",
        "The tests were split by the terrain their meta.json names and each group was diagnosed on its own, with "
        "the same options; an effect common to every terrain (of the vehicle or its instruments) is therefore "
        "fitted on each terrain's tests alone, with less data than one pooled diagnosis has.", "",
        "| terrain | tests | verdict | report |", "|---|---|---|---|",
    ]
    for t, e in report["terrains"].items():
        md = e["folder"] + "/report.md"
        line = e["verdict"]["verdict_line"].replace("|", "\\|")
        lines.append(f"| {t} | {', '.join(e['tests'])} | {line} | [{md}]({md}) |")
    if report["excluded"]:
        lines += ["", "Excluded tests:", ""] + [f"- {x['test']}: {x['reason']}" for x in report["excluded"]]
    lines += ["", f"Wall time {report['timing']['wall_s']:.0f} s."]
    return "\n".join(lines) + "\n"


def _read_summary(after: str | Path) -> tuple[Path, dict] | None:
    """``(path of its report.json, its content)`` if ``after`` is a summary written by :func:`diagnose_each_terrain`,
    else None (a single diagnosis's report, or a file that :func:`.candidates.named_fits_from_report` will reject)."""
    path = Path(after)
    report = path / "report.json" if path.is_dir() else path
    try:
        rep = json.loads(report.read_text())
    except (OSError, ValueError):
        return None
    return (report, rep) if isinstance(rep, dict) and rep.get("mode") == MODE else None


def summary_of(after: str | Path) -> Path | None:
    """The path of ``after``'s ``report.json`` if it is a summary written by :func:`diagnose_each_terrain`, else None."""
    found = _read_summary(after)
    return None if found is None else found[0]


def _after_by_terrain(after: str | Path | None, terrains) -> dict:
    """{terrain: the ``after`` report of its diagnosis}: a summary of this module gives each terrain its own
    terrain's report (None where that terrain named no effect or was not in it); a single diagnosis's report
    applies to every terrain. The summary is read once."""
    found = None if after is None else _read_summary(after)
    if found is None:
        return dict.fromkeys(terrains, after)
    path, rep = found
    out = {}
    for terrain in terrains:
        entry = rep.get("terrains", {}).get(terrain)
        named = entry is not None and entry.get("verdict", {}).get("effect") not in (NONE, None)
        out[terrain] = path.parent / entry["report"] if named else None
    return out


def diagnose_each_terrain(folder: str | Path, out_dir: str | Path | None = None, *, tests: list[str] | None = None,
                          figures: bool = True, progress: bool = True, after: str | Path | None = None,
                          **options) -> TerrainDiagnoses:
    """Diagnose each terrain's tests in ``folder`` on its own (:func:`.core.diagnose` per terrain) and combine the
    verdicts (module docstring).

    Args:
        folder, tests, figures, progress: as for :func:`.core.diagnose`.
        out_dir: the summary's ``report.md``/``report.json`` go here, each terrain's diagnosis to
            ``<out_dir>/<terrain>/`` (``None``: nothing written).
        after: an earlier diagnosis's report: a summary written by this function gives each terrain the fit its
            own terrain named (terrains that named none start from the base model); a single diagnosis's report
            applies to every terrain.
        **options: every other option of :func:`.core.diagnose` (``cache`` gets a sub-folder per terrain).

    Raises:
        DiagnosisError: nothing usable in ``folder``, or a bad option (checked before any fit starts).
    """
    t_start = time.perf_counter()
    checked = inspect.signature(check_options).parameters
    check_options(**{k: v for k, v in options.items() if k in checked})
    groups, excluded = terrain_groups(folder, tests)
    afters = _after_by_terrain(after, groups)
    taken: set[str] = set()
    subs = {terrain: folder_name(terrain, taken) for terrain in groups}
    cache = options.pop("cache", None)
    by_terrain: dict[str, Diagnosis] = {}
    for terrain, names in groups.items():
        sub = subs[terrain]
        if progress:
            print(f"diagnosing {terrain}: {', '.join(names)}", file=sys.stderr, flush=True)
        by_terrain[terrain] = diagnose(folder, None if out_dir is None else Path(out_dir) / sub, tests=names,
                                       figures=figures, progress=progress, after=afters[terrain],
                                       cache=None if cache is None else Path(cache) / sub, **options)
    verdict = combined_verdict({t: d.verdict for t, d in by_terrain.items()}, {t: len(g) for t, g in groups.items()})
    first = next(iter(by_terrain.values()))
    report = {
        "tool": "trackenv diagnose", "mode": MODE, "folder": str(folder),
        "data_label": "; ".join(dict.fromkeys(d.report["data_label"] for d in by_terrain.values())),
        "base_model": {k: v for k, v in first.report["base_model"].items() if k != "after"},
        "verdict": verdict,
        "terrains": {t: {"folder": subs[t], "tests": groups[t], "report": f"{subs[t]}/report.json",
                         "verdict": d.verdict} for t, d in by_terrain.items()},
        "excluded": excluded,
        "timing": {"wall_s": time.perf_counter() - t_start,
                   "by_terrain_s": {t: d.report["timing"]["wall_s"] for t, d in by_terrain.items()}},
    }
    res = TerrainDiagnoses(by_terrain, report)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        res.out_dir = out
        (out / "report.json").write_text(json.dumps(_clean(report), indent=1, allow_nan=False) + "\n")
        (out / "report.md").write_text(_summary_md(report))
        res.files = {"report.json": out / "report.json", "report.md": out / "report.md"}
    return res
