"""How much of a fit's prediction float rounding alone decides: the rounding check of a diagnosis.

The model's stop can bifurcate: after a turning stop at zero volts the vehicle may rock in yaw as the
contact elements' stored lateral shear displacements spring back, and at the fits' substep whether a
given sample sees that can depend on float rounding alone (docs/diagnose_benchmark.md, "Post-stop
samples: the model's own bifurcation"). Such samples make a loss jump between parameter sets a rounding
apart, and a report that leans on them claims more than its fit can support.

:func:`rounding_check` simulates one fitted parameter set twice, changing nothing but the order of the
floating-point additions: alone in its batch, and as ``COPIES`` copies (the batch size selects the form
of the contact-point sums, :mod:`trackenv.physics.sums`, and whether the batch is split over the cores).
It reports the share of compared samples that move by more than one noise σ of their log, and where.
"""

from __future__ import annotations

import time

import numpy as np

from ..compare import channel_error
from .batch import BatchSimulator
from .candidates import NONE, ON, RECALIBRATE
from .data import TestData
from .fit import CandidateFit

COPIES = 16  # copies of the parameter set in the second batch: the unrolled-sum form (trackenv.physics.sums)


def _values(fit: CandidateFit, fits: dict) -> tuple:
    """(candidate, {name: (1,)} physical values, encoder windows) of ``fit``'s full-data point; a fit without
    parameters (``none``) is checked as the control at its anchor, which reproduces the base model."""
    cand = fit.candidate
    if cand.n_params == 0:
        if RECALIBRATE not in fits:
            return None, {}, ()
        cand = fits[RECALIBRATE].candidate
        return cand, {k: np.array([v], np.float64) for k, v in cand.anchor.items()}, ()
    vals = cand.physical(fit.full.unit[None])  # {name: (1,)}: one point of the unit cube
    if cand.on is not None:  # the values this fit stands on, as it recorded them: the control's full fit, one
        # of its fold fits (where that fitted all the data better, :mod:`.fit`) or the base (``@base``)
        vals |= {ON + s.name: np.array([fit.full.params[f"{cand.on.name}.{s.name}"]], np.float64)
                 for s in cand.on.specs}
    window = fit.full.params.get("encoder_window")
    return cand, vals, (() if window is None else (float(window),))


def rounding_check(sim: BatchSimulator, data: list[TestData], name: str, fits: dict, copies: int = COPIES,
                   threshold: float = 1.0) -> dict:
    """The rounding check of fit ``fits[name]`` (module docstring).

    Returns ``{"fit", "copies", "threshold", "moved_fraction", "max_sigma", "cells", "seconds"}``: the share of
    compared samples (finite, in the fit mask) whose prediction moves by more than ``threshold`` noise σ, the
    largest move in σ, and per test × signal with any such sample its count, largest move and first time [s]
    since the log's first sample. ``moved_fraction`` is None when nothing could be checked.
    """
    t0 = time.perf_counter()
    cand, vals, windows = _values(fits[name], fits)
    out = {"fit": name, "copies": copies, "threshold": threshold, "moved_fraction": None, "max_sigma": None,
           "cells": []}
    if cand is None:
        return out
    alone, div1 = sim.run(cand, vals, windows=windows)
    many, divk = sim.run(cand, {k: np.repeat(v, copies) for k, v in vals.items()}, windows=windows)
    if div1.any() or divk.any():
        out["note"] = "a simulation diverged"
        return out
    n = moved = 0
    top = 0.0
    for j, t in enumerate(data):
        for sig in t.measured:
            ok = np.isfinite(t.measured[sig]) & t.fit_mask
            if not t.noise[sig] > 0:  # a constant channel: no noise scale to judge by
                continue
            d = np.abs(channel_error(sig, alone[j][sig][:, 0], many[j][sig][:, 0])) / t.noise[sig]
            d = np.where(ok, d, 0.0)
            n += int(ok.sum())
            big = d > threshold
            top = max(top, float(d.max(initial=0.0)))
            if big.any():
                moved += int(big.sum())
                out["cells"].append({"test": t.name, "signal": sig, "samples": int(big.sum()),
                                     "max_sigma": float(d.max()), "first_t": float(t.t[np.argmax(big)] - t.t[0])})
    out["cells"].sort(key=lambda c: -c["max_sigma"])
    out["moved_fraction"] = moved / max(n, 1)
    out["max_sigma"] = top
    out["seconds"] = time.perf_counter() - t0
    return out


def rounding_checks(sim: BatchSimulator, data: list[TestData], chosen: str, fits: dict) -> list[dict]:
    """:func:`rounding_check` of the fit the verdict names (or the best one) and of what it is compared
    against: the control and the base model (each once)."""
    names = list(dict.fromkeys(n for n in (chosen, RECALIBRATE, NONE) if n in fits))
    return [rounding_check(sim, data, n, fits) for n in names]


def summary_lines(checks: list[dict]) -> list[str]:
    """Sentences for report.md: one per checked fit with samples that moved, else one for all the fits
    checked; and one per check that could not run."""
    lines = [_moved_line(c) for c in checks if c.get("cells")]
    ran = [c for c in checks if c.get("moved_fraction") is not None]
    if ran and not lines:
        fits = ", ".join("`" + c["fit"] + "`" for c in ran)
        lines.append(f"Rounding check: the fits {fits} give the same predictions, to "
                     f"{max(c['max_sigma'] for c in ran):.2g} noise σ at most, when their parameters are simulated "
                     f"as {ran[0]['copies']} copies instead of alone (only the order of the float additions changes).")
    return lines + [f"Rounding check of `{c['fit']}`: not run ({c['note']})." for c in checks if c.get("note")]


def _moved_line(check: dict) -> str:
    c = check["cells"][0]
    return (f"Rounding check: the `{check['fit']}` fit's parameters, simulated as {check['copies']} copies instead "
            f"of alone (only the order of the float additions changes), move {100 * check['moved_fraction']:.1f}% "
            f"of the compared samples by more than one noise σ; the largest, {c['max_sigma']:.0f} σ, in "
            f"{c['test']} / {c['signal']} from t = {c['first_t']:.1f} s. Those samples follow float rounding, not "
            f"the parameters, so the fits' losses there are not smooth (docs/diagnose_benchmark.md, "
            f"\"Post-stop samples\").")
