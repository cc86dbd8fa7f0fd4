"""``report.md`` (for people, with figures) and the figures of a diagnosis.

Figures: ``heatmap.png`` (systematic gap per test/phase × signal, before and after), ``ranking.png``
(held-out gap per candidate), ``overlay_<test>.png`` (measured vs base model vs the chosen candidate's
held-out prediction, phases shaded).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .phases import phase_spans
from .sensitivity import summary_lines

SIGNAL_LABEL = {"i_left": "i_left [A]", "i_right": "i_right [A]", "speed_ideal": "speed_ideal [m/s]",
                "yaw_rate": "yaw_rate [rad/s]", "x": "x [m]", "y": "y [m]", "heading": "heading [rad]"}
PHASE_COLOR = {"idle": "#ffffff", "ramp": "#fde0c5", "cruise": "#e0f0e0", "turn": "#dfe6fb", "brake": "#f9d5d5",
               "coast": "#eeeeee"}


def after_text(after: list) -> str:
    """The sentence of report.md that names the fits an earlier diagnosis added to the base model ("" if none)."""
    if not after:
        return ""
    fits = "; ".join(f"`{a['fit']}` (" + ", ".join(f"{k} = {v:.4g}" for k, v in a["params"].items()) + f", from {a['report']})"
                     for a in after)
    return f"The base model carries the fits earlier diagnoses named: {fits}. "


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def heatmap(report: dict, path: Path) -> Path:
    plt = _plt()
    cells = report["cells"]
    rows = list(dict.fromkeys((c["test"], c["phase"]) for c in cells))
    sigs = list(dict.fromkeys(c["signal"] for c in cells))
    before = np.full((len(rows), len(sigs)), np.nan)
    after = np.full_like(before, np.nan)
    for c in cells:
        i, k = rows.index((c["test"], c["phase"])), sigs.index(c["signal"])
        before[i, k] = c["gap_before"]
        after[i, k] = c.get("gap_after", np.nan)
    vmax = max(np.nanmax(before) if np.isfinite(before).any() else 0.1, 0.05)
    fig, axes = plt.subplots(1, 2, figsize=(3 + 1.4 * len(sigs) * 2, 1.2 + 0.28 * len(rows)), sharey=True)
    after_name = report["verdict"]["after_model"]
    for ax, m, title in ((axes[0], before, "base model"), (axes[1], after, f"with {after_name} (held out)")):
        im = ax.imshow(m, aspect="auto", cmap="magma_r", vmin=0, vmax=vmax)
        ax.set_xticks(range(len(sigs)), sigs, rotation=30, ha="right", fontsize=8)
        ax.set_title(title, fontsize=9)
        for i in range(m.shape[0]):
            for k in range(m.shape[1]):
                if np.isfinite(m[i, k]) and m[i, k] >= 0.005:
                    ax.text(k, i, f"{100 * m[i, k]:.0f}", ha="center", va="center", fontsize=6,
                            color="white" if m[i, k] > 0.6 * vmax else "black")
    axes[0].set_yticks(range(len(rows)), [f"{t} · {p}" for t, p in rows], fontsize=7)
    fig.colorbar(im, ax=axes, label="systematic gap (NRMSE − noise) [fraction of range]", shrink=0.8)
    fig.suptitle(f"where the gap lies — {report['data_label'][:90]}", fontsize=8)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def ranking_figure(report: dict, path: Path) -> Path:
    plt = _plt()
    r = report["ranking"]
    fig, ax = plt.subplots(figsize=(6.5, 0.5 + 0.35 * len(r)))
    names = [x["effect"] for x in r][::-1]
    gaps = [x["heldout_gap"] for x in r][::-1]
    colors = ["tab:red" if n == report["verdict"]["effect"] else "tab:gray" for n in names]
    ax.barh(names, gaps, color=colors)
    ax.axvline(report["verdict"]["gap_before"], color="k", lw=0.8, ls="--", label="base model")
    ax.set_xlabel("held-out systematic gap [noise units] (lower is better)")
    ax.legend(fontsize=8)
    ax.set_title(f"verdict: {report['verdict']['effect']} (confidence {report['verdict']['confidence']:.2f})",
                 fontsize=9)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def overlay(diag, j: int, path: Path) -> Path:
    plt = _plt()
    test = diag.tests[j]
    base = diag.fits["none"].full_pred[j]
    after_name = diag.report["verdict"]["after_model"]
    after = diag.fits[after_name].heldout_pred[j]
    sigs = [s for s in ("i_left", "i_right", "speed_ideal", "yaw_rate", "heading") if s in test.measured]
    fig, axes = plt.subplots(len(sigs) + 1, 1, figsize=(8, 1.7 * (len(sigs) + 1)), sharex=True)
    ax = axes[0]
    if test.drive_kind == "speed":  # the prescribed speeds, on the back-emf voltage scale the phases use
        ax.plot(test.t, test.drive_values[:, 0], label="omega_left (input)")
        ax.plot(test.t, test.drive_values[:, 1], label="omega_right (input)")
        ax.set_ylabel("ω [rad/s]")
    else:
        ax.plot(test.t, test.volts[:, 0], label="v_left")
        ax.plot(test.t, test.volts[:, 1], label="v_right")
        ax.set_ylabel("V [V]")
    ax.legend(fontsize=7, ncol=2)
    for ax, sig in zip(axes[1:], sigs):
        ax.plot(test.t, test.measured[sig], color="0.55", lw=0.8,
                label="MEASURED (log)" if test.log.meta.get("measured") is True else "measured (log)")
        ax.plot(test.t, base[sig], color="tab:blue", lw=1.2, label="base model")
        if after_name != "none":
            ax.plot(test.t, after[sig], color="tab:red", lw=1.2, label=f"+ {after_name} (held out)")
        ax.set_ylabel(SIGNAL_LABEL.get(sig, sig), fontsize=8)
    for ax in axes:
        for ph, a, b in phase_spans(test.t, test.phase):
            ax.axvspan(a, b, color=PHASE_COLOR.get(ph, "#ffffff"), alpha=0.5, lw=0)
    axes[1].legend(fontsize=7, loc="best")
    axes[-1].set_xlabel("time since the log's first sample [s]")
    label = "SYNTHETIC log" if test.log.synthetic else "field log"
    axes[0].set_title(f"{test.name} ({test.terrain}, {label}); phases shaded: ramp/cruise/turn/brake/coast",
                      fontsize=9)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path


def _pct(x):
    return "–" if x is None else f"{100 * x:.1f}%"


def write_report(diag, out: Path, figures: bool = True) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    rep = diag.report
    files = {}
    if figures:
        files["heatmap"] = heatmap(rep, out / "heatmap.png")
        files["ranking"] = ranking_figure(rep, out / "ranking.png")
        for j, t in enumerate(diag.tests):
            files[f"overlay_{t.name}"] = overlay(diag, j, out / f"overlay_{t.name}.png")
    v = rep["verdict"]
    L = [f"# Sim-to-real gap diagnosis: `{rep['folder']}`", "",
         f"**Data:** {rep['data_label']}.", "",
         f"Base model: {rep['base_model']['internal_resistance']} internal resistance; fits at a "
         f"{1e3 * rep['base_model']['substep_s']:g} ms substep; vehicle: {rep['base_model'].get('vehicle', 'the logs')}; "
         f"drive input: {', '.join(rep['base_model'].get('input_modes', ['voltage']))} mode. "
         f"{after_text(rep['base_model'].get('after') or [])}"
         f"Wall time {rep['timing']['wall_s']:.0f} s.", "",
         "## Verdict", ""]
    L += [f"**{v['verdict_line']}**", "",
          f"Base-model gap {v['gap_before']:.2f} noise units (held-out samples: {v['gap_before_heldout']:.2f}); "
          f"after `{v['after_model']}` (held out): {v['gap_after']:.2f}. Gap test p = {v['gap_test']['p']:.2g} "
          f"({v['gap_test']['cells']} test x signal cells). Rule: {rep['method']['rule']}"]
    for line in summary_lines(rep.get("rounding_check", [])):
        L += ["", line]
    L += ["", "## Where the gap lies", ""]
    if rep["gap_cells"]:
        L += ["| test | signal | phase | t [s] | NRMSE | systematic gap | bias | lag [s] | share |", "|---|---|---|---|---|---|---|---|---|"]  # noqa: E501
        for c in rep["gap_cells"]:
            lag = "–" if c["lag_before_s"] is None else f"{c['lag_before_s']:+.2f}"
            L.append(f"| {c['test']} | {c['signal']} | {c['phase']} | {c['t_start']:.1f}-{c['t_end']:.1f} | "
                     f"{_pct(c['nrmse_before'])} | {_pct(c['gap_before'])} | {c['bias_before']:+.3g} | {lag} | "
                     f"{100 * c['share_of_gap']:.0f}% |")
    else:
        L.append("No cell carries a gap that stands out from the noise.")
    if figures:
        L += ["", "![heat map](heatmap.png)"]
    L += ["", "## Which effect: candidates ranked by held-out score", "",
          "| candidate | fitted params | held-out NRMSE | held-out gap [noise units] | shrink | score | converged |",
          "|---|---|---|---|---|---|---|"]
    for r in rep["ranking"]:
        ps = ", ".join(f"{k}={val:.3g}" for k, val in r["params"].items()) or "–"
        L.append(f"| `{r['effect']}` | {ps} | {_pct(r['heldout_nrmse'])} | {r['heldout_gap']:.2f} | "
                 f"{100 * r['heldout_gap_shrink']:.0f}% | {r['score']:.4g} | {'yes' if r['converged'] else 'NO'} |")
    for na in rep["not_applicable"]:
        L.append(f"| `{na['effect']}` | not fitted: {na['why']} | | | | | |")
    if figures:
        L += ["", "![ranking](ranking.png)"]
    L += ["", "## How far: per test, held out", ""]
    if figures:
        for t in diag.tests:
            L.append(f"- `{t.name}`: ![overlay](overlay_{t.name}.png)")
    L += ["", "## Tests", "", "| test | terrain | maneuver | ammeter | duration [s] | samples | notes |", "|---|---|---|---|---|---|---|"]
    for t in rep["tests"]:
        L.append(f"| {t['test']} | {t['terrain']} | {t['maneuver']} | {t['current_sensor']} | {t['duration_s']:.1f} | "
                 f"{t['n_samples']} | {'; '.join(t['notes']) or '–'} |")
    for e in rep["excluded"]:
        L.append(f"| {e['test']} | EXCLUDED | | | | | {e['reason']} |")
    m = rep["method"]
    folds = "; ".join(f"{f['kind']}: {f['heldout']}" for f in m["folds"])
    L += ["", "## Method", "", f"- folds (held out): {folds}",
          f"- loss: {m['loss']}", f"- score: {m['score']}", f"- gap: {m['gap']}", f"- search: {m['search']}",
          f"- thresholds: {m['thresholds']}", "", "Machine-readable: `report.json`."]
    (out / "report.md").write_text("\n".join(L) + "\n", encoding="utf-8")
    files["report_md"] = out / "report.md"
    files["report_json"] = out / "report.json"
    return {k: str(v) for k, v in files.items()}
