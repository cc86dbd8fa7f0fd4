"""The first measured diagnosis: BorealTC runs of a Clearpath Husky A200 (MEASURED data).

    python benchmarks/measured_diagnosis.py                         # the shipped subset, data/measured/borealtc
    python benchmarks/measured_diagnosis.py --dataset DIR --out DIR  # e.g. the whole public dataset

1. **Import** every run (``trackenv import borealtc``): speed-mode field logs (wheel speeds in; currents
   and the IMU's yaw rate measured), and **replay** each with the configs as they are (``replay/<run>/``).
2. **Calibrate on asphalt**, leaving one run out at a time: the Husky's uncertain drive and contact
   parameters (``PARAMETERS``) are fitted to the other asphalt runs (:func:`trackenv.calibrate.calibrate`)
   and the held-out run is predicted by the configs as they are, by the calibrated model and by a
   model-free baseline (:class:`trackenv.calibrate.NaiveBaseline`, fitted on the same runs). A last
   calibration on every asphalt run gives the calibrated vehicle (``husky_calibrated.yaml``; only the
   vehicle's own parameters travel to the other ground, the asphalt's contact parameters stay there).
3. **Diagnose the sandy-loam runs** with the calibrated vehicle (:func:`trackenv.diagnose.diagnose`, its
   folds hold out whole runs), for each seed; each run is cropped to its first ``--crop`` seconds to bound
   the time. The verdict's stability is reported across seeds and across the diagnosis's folds (which
   candidate predicts each held-out run best).

Writes ``report.md``, ``results.json`` and ``asphalt_heldout.png`` to ``--out``. The soil of the sandy
loam is not characterised in the dataset: Table 5.5's sandy loam 1 stands in for it, so a part of any
gap there is unknown soil values, which the diagnosis's ``recalibrate_base`` control is there to absorb.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from trackenv.calibrate import NaiveBaseline, calibrate, evaluate, write_vehicle_config  # noqa: E402
from trackenv.compare import json_clean  # noqa: E402
from trackenv.diagnose.data import load_tests  # noqa: E402
from trackenv.importers.borealtc import import_borealtc  # noqa: E402
from trackenv.replay import replay  # noqa: E402

# The Husky's uncertain parameters on asphalt [SI]: the drive's no-load friction (the dataset's 1.35 A
# no-load current gives 3.27 N m) and viscous loss, the tyre-asphalt friction angle (rad) and shear modulus.
PARAMETERS = {
    "vehicle.stiction_torque": (0.0, 20.0),
    "vehicle.drive_damping": (0.0, 5.0),
    "terrain.friction_angle": (0.35, 0.95),
    "terrain.shear_modulus": (0.001, 0.05),
}
SIGNALS = ("i_left", "i_right", "yaw_rate")


def _mean_nrmse(ev, name: str) -> dict:
    return {s: ev.nrmse[name].get(s) for s in SIGNALS}


def _crop(logs: list[Path], out: Path, seconds: float) -> Path:
    """Copies of ``logs`` holding their first ``seconds`` [s] (meta.json notes the crop)."""
    if out.exists():
        shutil.rmtree(out)
    for src in logs:
        dst = out / src.name
        dst.mkdir(parents=True)
        df = pd.read_csv(src / "log.csv")
        df[df["t"] <= df["t"].iloc[0] + seconds].to_csv(dst / "log.csv", index=False)
        meta = json.loads((src / "meta.json").read_text())
        meta["notes"] = (meta.get("notes", "") + f" Cropped to the first {seconds:g} s of the run.").strip()
        (dst / "meta.json").write_text(json.dumps(meta, indent=2))
    return out


def _figure(rows: list[dict], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 3, figsize=(14, 3.2 * len(rows)), squeeze=False, constrained_layout=True)
    for r, row in enumerate(rows):
        for c, sig in enumerate(SIGNALS):
            ax = axes[r, c]
            t = row["t"]
            ax.plot(t, row["measured"][sig], ".", ms=2, color="k", label="MEASURED")
            ax.plot(t, row["base_pred"][sig], lw=1, label=f"configs (NRMSE {row['base'][sig]:.0%})")
            ax.plot(t, row["cal_pred"][sig], lw=1, label=f"calibrated (NRMSE {row['calibrated'][sig]:.0%})")
            ax.plot(t, row["naive_pred"][sig], lw=1, ls=":", label=f"naive baseline (NRMSE {row['naive'][sig]:.0%})")
            ax.set(title=f"{row['run']} (held out): {sig}", xlabel="time [s]",
                   ylabel="|i| [A]" if sig.startswith("i_") else "yaw rate [rad/s]")
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
    fig.suptitle("BorealTC Husky A200 on asphalt, MEASURED: each run predicted by a calibration on the others", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", default=str(ROOT / "data" / "measured" / "borealtc"))
    ap.add_argument("--out", default=str(ROOT / "out" / "measured"))
    ap.add_argument("--crop", type=float, default=20.0, help="seconds of each sandy-loam run the diagnosis uses")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--max-nfev", type=int, default=6, help="calibration: most residual evaluations per fit")
    ap.add_argument("--sandy-runs", default=None, help="comma-separated SANDY_LOAM run numbers (default: all)")
    ap.add_argument("--asphalt-crop", type=float, default=None,
                    help="seconds of each asphalt run the calibration uses (default: whole runs)")
    ap.add_argument("--report-only", action="store_true", help="rewrite report.md from results.json")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.report_only:
        (out / "report.md").write_text(_report(json.loads((out / "results.json").read_text()), "asphalt_heldout.png"))
        return 0
    out.mkdir(parents=True, exist_ok=True)
    timing = {}
    t0 = time.perf_counter()
    logs = import_borealtc(args.dataset, out / "logs", force=True)
    timing["import_s"] = time.perf_counter() - t0
    asphalt = sorted(p for p in logs if p.name.startswith("ASPHALT"))
    sandy = sorted(p for p in logs if p.name.startswith("SANDY_LOAM"))
    if args.sandy_runs:
        keep = {f"SANDY_LOAM_{r.strip()}" for r in args.sandy_runs.split(",")}
        sandy = [p for p in sandy if p.name in keep]
    print(f"imported {len(asphalt)} asphalt and {len(sandy)} sandy-loam runs in {timing['import_s']:.1f} s")
    t0 = time.perf_counter()
    replays = {}
    for p in logs:  # every run replayed with the configs as they are (speed mode), a figure each
        r = replay(p, out / "replay" / p.name, force=True)
        replays[p.name] = {k: (v or {}).get("nrmse") for k, v in r.metrics["channels"].items()}
    timing["replay_s"] = time.perf_counter() - t0
    print(f"replayed {len(logs)} runs in {timing['replay_s']:.0f} s")
    if args.asphalt_crop:
        crop_dir = _crop(asphalt, out / "asphalt_cropped", args.asphalt_crop)
        asphalt = sorted(crop_dir / p.name for p in asphalt)

    # 2. asphalt: leave one run out
    t0 = time.perf_counter()
    rows = []
    for held in asphalt:
        train = [p for p in asphalt if p != held]
        cal = calibrate(train, PARAMETERS, signals=SIGNALS, max_nfev=args.max_nfev, progress=False)
        base_ev = evaluate([held], {}, signals=SIGNALS)
        cal_ev = evaluate([held], cal.values, signals=SIGNALS)
        naive_ev = NaiveBaseline.fit(train).evaluate([held])
        name = held.name
        (held_test,), _ = load_tests(held)
        rows.append({"run": name, "train": [p.name for p in train], "values": cal.values, "at_bound": cal.at_bound,
                     "base": _mean_nrmse(base_ev, name), "calibrated": _mean_nrmse(cal_ev, name),
                     "naive": _mean_nrmse(naive_ev, name), "rmse_calibrated": cal_ev.rmse[name],
                     "rmse_naive": naive_ev.rmse[name], "t": cal_ev.predictions[name]["t"],
                     "base_pred": base_ev.predictions[name], "cal_pred": cal_ev.predictions[name],
                     "naive_pred": naive_ev.predictions[name], "measured": held_test.measured})
        print(f"held out {name}: NRMSE configs {rows[-1]['base']}, calibrated {rows[-1]['calibrated']}, "
              f"naive {rows[-1]['naive']}")
    final = calibrate(asphalt, PARAMETERS, signals=SIGNALS, max_nfev=args.max_nfev, progress=False)
    vehicle_values = {k: v for k, v in final.values.items() if k.startswith("vehicle.")}
    vehicle_yaml = write_vehicle_config("husky", vehicle_values, out / "husky_calibrated.yaml",
                                        f"calibrated on the MEASURED BorealTC asphalt runs {', '.join(p.name for p in asphalt)}")
    timing["asphalt_s"] = time.perf_counter() - t0
    fig = _figure(rows, out / "asphalt_heldout.png")
    print(f"calibrated vehicle: {vehicle_values} -> {vehicle_yaml} ({timing['asphalt_s']:.0f} s)")

    # 3. sandy loam: diagnosis with the calibrated vehicle
    from trackenv.diagnose import diagnose

    crop = _crop(sandy, out / "sandy_loam_cropped", args.crop)
    diagnoses = []
    for seed in args.seeds:
        t0 = time.perf_counter()
        dg = diagnose(crop, out / f"diagnosis_seed{seed}", vehicle=vehicle_yaml, seed=seed, rounds=1, search_points=8,
                      polish_iters=2, figures=seed == args.seeds[0], progress=False)
        wall = time.perf_counter() - t0
        names = [t.name for t in dg.tests]
        fold_best = {}
        for j, n in enumerate(names):
            losses = {c: float(f.heldout_loss[j]) for c, f in dg.fits.items()}
            fold_best[n] = min(losses, key=losses.get)
        v = dg.verdict
        diagnoses.append({"seed": seed, "wall_s": wall, "effect": v["effect"], "best_candidate": v["best_candidate"],
                          "confidence": v["confidence"], "verdict_line": v["verdict_line"],
                          "heldout_gap_shrink": v["heldout_gap_shrink"], "best_candidate_shrink": v["best_candidate_shrink"],
                          "best_candidate_shrink_ci": v["best_candidate_shrink_ci"], "p_beats_none": v["p_beats_none"],
                          "fold_best": fold_best, "ranking": [r["effect"] for r in dg.report["ranking"]],
                          "report": str(out / f"diagnosis_seed{seed}" / "report.md")})
        timing[f"diagnosis_seed{seed}_s"] = wall
        print(f"seed {seed}: {v['verdict_line']} ({wall:.0f} s); best per held-out run: {fold_best}")
    timing["total_s"] = sum(timing.values())

    results = {"data": "MEASURED (BorealTC, Clearpath Husky A200, MIT licence)", "dataset": args.dataset,
               "parameters": PARAMETERS, "asphalt_heldout": [{k: v for k, v in r.items() if k not in
                                                            ("t", "base_pred", "cal_pred", "naive_pred", "measured")}
                                                           for r in rows],
               "replay_nrmse_configs": replays, "calibrated_vehicle": vehicle_values, "final_calibration": final.values,
               "final_at_bound": final.at_bound, "sandy_loam_crop_s": args.crop, "asphalt_crop_s": args.asphalt_crop,
               "sandy_loam_runs": [p.name for p in sandy], "diagnoses": diagnoses,
               "timing": timing}
    (out / "results.json").write_text(json.dumps(json_clean(results), indent=2))
    (out / "report.md").write_text(_report(results, fig.name))
    print(f"wrote {out / 'report.md'}; total {timing['total_s']:.0f} s")
    return 0


def _summary(heldout: list[dict], seed: int = 0) -> list[str]:
    """Mean held-out NRMSE per model and channel over the runs, with a 95% bootstrap interval (runs resampled),
    and how many runs the calibrated model beats each reference on."""
    rng = np.random.default_rng(seed)
    L = ["| channel | configs | calibrated | naive baseline | calibrated beats configs | calibrated beats naive |",
         "|---|---|---|---|---|---|"]
    n = len(heldout)
    for sig in SIGNALS:
        cols = {m: np.array([r[m][sig] for r in heldout], float) for m in ("base", "calibrated", "naive")}
        cells = []
        for m in ("base", "calibrated", "naive"):
            x = cols[m]
            boot = x[rng.integers(0, n, (2000, n))].mean(axis=1) if n > 1 else x
            lo, hi = np.percentile(boot, [2.5, 97.5])
            cells.append(f"{100 * x.mean():.1f}% ({100 * lo:.1f}-{100 * hi:.1f}%)")
        win_b = int(np.sum(cols["calibrated"] < cols["base"]))
        win_n = int(np.sum(cols["calibrated"] < cols["naive"]))
        L.append(f"| {sig} | " + " | ".join(cells) + f" | {win_b} of {n} | {win_n} of {n} |")
    return L


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.0f}%"


def _report(res: dict, fig: str) -> str:
    L = ["# Measured diagnosis: BorealTC Husky A200 (MEASURED data)", "",
         f"Data: {res['data']}, from `{res['dataset']}`. Speed mode: the wheel speeds drive the model; the motor "
         "currents (magnitudes) and the IMU's yaw rate are compared.", "",
         "## Asphalt: calibrated on the other runs, predicted on the held-out run", "",
         ("Each asphalt run's first " + f"{res['asphalt_crop_s']:g} s." if res.get("asphalt_crop_s") else "Whole runs."),
         "",
         f"![held-out asphalt runs]({fig})", "",
         "| held-out run | channel | configs | calibrated | naive baseline |", "|---|---|---|---|---|"]
    for r in res["asphalt_heldout"]:
        for s in SIGNALS:
            L.append(f"| {r['run']} | {s} | {_pct(r['base'][s])} | {_pct(r['calibrated'][s])} | {_pct(r['naive'][s])} |")
    L += ["", "NRMSE = RMSE / robust span (1st-99th percentile) of the measured channel in that run. Over the "
          "held-out runs: mean NRMSE (95% bootstrap interval over runs):", ""] + _summary(res["asphalt_heldout"])
    L += ["",
          f"Calibrated vehicle (all asphalt runs): {res['calibrated_vehicle']}; the whole fit: {res['final_calibration']}"
          + (f"; at a bound: {', '.join(res['final_at_bound'])}" if res["final_at_bound"] else ""), "",
          f"## Sandy loam: diagnosis with the calibrated vehicle (each run's first {res['sandy_loam_crop_s']:g} s)", ""]
    L += ["| seed | verdict | best candidate | its held-out shrink (95% CI) | p vs none | best per held-out run |",
          "|---|---|---|---|---|---|"]
    for d in res["diagnoses"]:
        ci = d["best_candidate_shrink_ci"]
        ci_s = f" ({_pct(ci[0])} to {_pct(ci[1])})" if ci else ""
        L.append(f"| {d['seed']} | {d['effect']} (confidence {d['confidence']:.2f}) | {d['best_candidate']} | "
                 f"{_pct(d['best_candidate_shrink'])}{ci_s} | {d['p_beats_none']:.3g} | "
                 + ", ".join(f"{k}: {v}" for k, v in d["fold_best"].items()) + " |")
    L += ["", "Timing [s]: " + ", ".join(f"{k} {v:.0f}" for k, v in res["timing"].items()), ""]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
