"""The ``trackenv demo``: every thesis test on the base model, the synthetic field twin replayed, the gaps diagnosed.

    trackenv demo --out out/demo                  # figures, summary.json, report.md
    trackenv demo --out out/demo --no-diagnose    # without the gap diagnoses (the slowest part)

    from trackenv.demo import run_demo, simulate_test
    prof, params, traj = simulate_test("go_stop_dry_sand", None, None, substep=0.0005)
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

import trackenv as te

from .field_profiles import list_field_tests, load_field_profile
from .replay import anchor_metrics

TWIN_DIR = Path(__file__).resolve().parent.parent / "data" / "field" / "thesis"  # the SYNTHETIC field twin

RECONSTRUCTED = ("voltages RECONSTRUCTED from the thesis text (configs/field), not measured; "
                 "simulated with the base model")


def simulate_test(test_id: str, terrain: str | None, internal: str | None, substep: float):
    """Simulate one thesis test (configs/field, reconstructed voltages) on ``terrain`` (default: the test's)
    with ``internal`` resistance (default: the test's); returns (profile, params, trajectory)."""
    prof = load_field_profile(test_id)
    params = te.load_params(terrain or prof.terrain, internal_resistance=internal or prof.internal_resistance)
    vp = te.VoltageProfile.from_arrays(prof.t, prof.volts, source=f"configs/field/{test_id}.yaml")
    t_end = float(np.ceil(prof.t_end / 0.05 - 1e-9) * 0.05)
    traj = te.simulate(params, vp, t_end, substep=substep)
    return prof, params, traj


def summary_row(prof, traj) -> dict:
    """Peaks, final pose and the thesis-text anchors of one simulated thesis test (for summary.json)."""
    ch = {k: np.asarray(v) for k, v in traj.channels.items()}
    out = {
        "test": prof.id, "terrain": prof.terrain, "maneuver": prof.maneuver,
        "peak_speed_ideal_m_s": float(np.max(np.abs(ch["speed_ideal"]))),
        "peak_yaw_rate_rad_s": float(np.max(np.abs(ch["yaw_rate"]))),
        "peak_current_A": float(np.max(np.abs([ch["i_left"], ch["i_right"]]))),
        "final_position_m": [float(ch["x"][-1]), float(ch["y"][-1])],
        "final_heading_deg": float(np.degrees(ch["heading"][-1])),
        "anchors": [],
    }
    for a in anchor_metrics(prof, traj, 0.05):
        if a["simulated"] is not None:
            out["anchors"].append({"signal": a["signal"], "window_s": [a["t0"], a["t1"]],
                                   "thesis_field": a["thesis_field"], "simulated": a["simulated"],
                                   "rel_diff": a["rel_diff"]})
    return out


# the demo's diagnoses search with the blind benchmark's budget (docs/diagnose_benchmark.md): one cross-entropy
# round and 3 polish iterations, about 70 % of the CLI default's simulations (6 965 against 10 055 for the five
# sand tests); ``full_budget`` uses the default
DEMO_BUDGET = {"rounds": 1, "search_points": 8, "polish_iters": 3}


def run_demo(out_dir: str | Path, substep: float, *, diagnose: bool = True, force: bool = False,
             full_budget: bool = False) -> Path:
    """Simulate every thesis test (figure + summary row each), replay the synthetic field twin and, with
    ``diagnose``, diagnose the thesis's gaps on it (with :data:`DEMO_BUDGET`, or the CLI default's search
    budget if ``full_budget``); writes ``report.md`` and ``summary.json`` to ``out_dir`` and returns the
    report's path."""
    from tqdm import tqdm

    from .outputs import prepare_output_dir
    from .plots import maneuver_figure

    out = prepare_output_dir(out_dir, "demo", force=force)
    rows = []
    t0 = time.perf_counter()
    for test in tqdm(list_field_tests(), desc="simulating thesis tests", unit="test"):
        prof, params, traj = simulate_test(test, None, None, substep)
        maneuver_figure(traj, f"{prof.id} ({prof.terrain})", out / f"{test}.png", caption=RECONSTRUCTED)
        rows.append(summary_row(prof, traj))
    (out / "summary.json").write_text(json.dumps({"note": RECONSTRUCTED, "tests": rows}, indent=2))
    lines = ["# trackenv demo: the thesis's field tests on the base model", "",
             f"*{RECONSTRUCTED}.* Wall time {time.perf_counter() - t0:.1f} s.", "",
             "| test | peak speed m/s | peak yaw rate rad/s | peak current A | anchor: thesis field vs simulated |",
             "|---|---|---|---|---|"]
    for r in rows:
        anchors = "; ".join(f"{a['signal']} {a['window_s'][0]:g}-{a['window_s'][1]:g} s: {a['thesis_field']:g} vs "
                            f"{a['simulated']:.3f} ({a['rel_diff']:+.1%})" for a in r["anchors"]) or "-"
        lines.append(f"| [{r['test']}]({r['test']}.png) | {r['peak_speed_ideal_m_s']:.3f} | "
                     f"{r['peak_yaw_rate_rad_s']:.3f} | {r['peak_current_A']:.2f} | {anchors} |")
    lines += twin_replays(out, substep)
    if diagnose:
        lines = gap_diagnoses(out, {} if full_budget else DEMO_BUDGET) + [""] + lines
    (out / "report.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"\nwrote {out / 'report.md'}, {out / 'summary.json'} and the figures")
    return out / "report.md"


SAND_TESTS = ["go_stop_dry_sand", "go_stop_2ms_dry_sand", "j_turn_dry_sand", "lane_change_dry_sand",
              "zero_radius_turn_dry_sand"]


def gap_diagnoses(out: Path, budget: dict = DEMO_BUDGET) -> list[str]:
    """The demo's main job: diagnose the thesis's own gaps on the SYNTHETIC field twin (``budget``: the
    search's ``rounds``, ``search_points`` and ``polish_iters``; ``{}``: the diagnosis's defaults)."""
    from .diagnose import diagnose

    twin = TWIN_DIR
    runs = [
        ("sand", "the sand tests, constant internal resistance (Table 5.4)", SAND_TESTS, "constant",
         "thesis §5.3.4: the base model turns ~11x too fast in the ZRT on sand"),
        ("viscous_go_stop", "the two sand go-stops, viscous internal resistance (Table 5.3) as base",
         ["go_stop_dry_sand", "go_stop_2ms_dry_sand"], "viscous",
         "thesis §5.4.1: the viscous model predicts ~3.1 A at 2 m/s where the field drew 2.23 A"),
    ]
    lines = ["# trackenv demo: the thesis's gaps diagnosed", "",
             "*On the SYNTHETIC field twin (`data/field/thesis`: reconstructed voltages simulated with withheld "
             "unmodelled effects and instrument noise; not measured data). `trackenv diagnose` replays each test "
             "on the base model, places the gap (test x signal x phase), fits every candidate effect on "
             "calibration tests and scores it on held-out tests.*", "",
             "| diagnosis | thesis evidence | where the gap lies (largest cell) | verdict | held-out gap shrink | "
             "report |", "|---|---|---|---|---|---|"]
    for name, what, tests, internal, evidence in runs:
        print(f"diagnosing {what} ...", flush=True)
        d = diagnose(twin, out / "diagnose" / name, tests=tests, internal_resistance=internal, progress=True, **budget)
        v = d.verdict
        c = d.report["gap_cells"][0] if d.report["gap_cells"] else None
        where = (f"{c['test']} / {c['signal']} / {c['phase']} (NRMSE {100 * c['nrmse_before']:.0f}%, bias "
                 f"{c['bias_before']:+.2f})") if c else "-"
        shrink = (f"{100 * v['heldout_gap_shrink']:.0f}% (95% CI {100 * v['heldout_gap_shrink_ci'][0]:.0f}-"
                  f"{100 * v['heldout_gap_shrink_ci'][1]:.0f}%); in-sample {100 * v['insample_gap_shrink']:.0f}%"
                  ) if v["effect"] != "none" else "-"
        lines.append(f"| {what} | {evidence} | {where} | **{v['effect']}** (confidence {v['confidence']:.2f}) | "
                     f"{shrink} | [report](diagnose/{name}/report.md) |")
    return lines


def twin_replays(out: Path, substep: float) -> list[str]:
    """Replay the SYNTHETIC field twin (data/field/thesis) on the base model: where the gap shows."""
    from tqdm import tqdm

    from .replay import replay

    twin = TWIN_DIR
    folders = sorted(p for p in twin.glob("*") if (p / "log.csv").exists())
    if not folders:
        return []
    channels = ("speed_ideal", "yaw_rate", "i_left", "i_right")
    lines = ["", "## The synthetic field twin replayed on the base model", "",
             "*The logs in `data/field/thesis` are SYNTHETIC: reconstructed voltages simulated with unmodelled "
             "effects and instrument noise (the truth is withheld in each folder's truth.json). Replaying them on "
             "the base model shows where the gap lies; naming its cause is the diagnosis's job.*", "",
             "| test | " + " | ".join(f"NRMSE {c}" for c in channels) + " |", "|---|" + "---|" * len(channels)]
    for folder in tqdm(folders, desc="replaying the field twin", unit="test"):
        res = replay(folder, out / "twin" / folder.name, substep=substep)
        m = res.metrics["channels"]
        cells = [f"{m[c]['nrmse']:.2f}" if c in m and m[c].get("nrmse") is not None else "-" for c in channels]
        lines.append(f"| [{folder.name}](twin/{folder.name}/replay.png) | " + " | ".join(cells) + " |")
    return lines
