"""Phases of a test, segmented from the commanded voltages alone (what the driver did, not the response).

Each sample of a log gets one of::

    idle    before the first command (both |V| ≤ 0.5 V)
    ramp    a voltage is changing and the larger |V| grows        (accelerating, entering a turn)
    brake   a voltage is changing and the larger |V| shrinks      (releasing, slowing down)
    cruise  voltages steady, nearly equal (|V_r − V_l| ≤ max(1 V, 0.1 max|V|))
    turn    voltages steady, unequal (a driving turn, or a zero-radius spin with V_l ≈ −V_r)
    coast   both |V| ≤ 0.5 V after the first command (the vehicle stops or coasts)

"Changing" means |dV/dt| > 2 V/s on either side (the thesis's ramps run at 20-80 V/s, its steady
segments at 0). Runs shorter than ``min_duration`` (0.1 s) are merged into the preceding phase, so
that a sampled ramp corner does not make a one-sample phase.
"""

from __future__ import annotations

import numpy as np

PHASES = ("idle", "ramp", "cruise", "turn", "brake", "coast")
ZERO_V = 0.5  # V, below this a side counts as unpowered
SLEW_V_PER_S = 2.0  # V/s, above this a voltage counts as changing


def segment_phases(t: np.ndarray, volts: np.ndarray, min_duration: float = 0.1) -> np.ndarray:
    """Phase label (a ``PHASES`` string) of each sample, from times ``t`` (K,) [s] and voltages (K, 2) [V]."""
    t = np.asarray(t, np.float64)
    v = np.asarray(volts, np.float64)
    k = t.shape[0]
    if k < 2:
        return np.array(["idle"] * k, dtype=object)
    mag = np.max(np.abs(v), axis=1)
    # one-sided slopes: a sample belongs to the change that follows it (the command leads the response)
    dv = np.diff(v, axis=0) / np.maximum(np.diff(t), 1e-12)[:, None]
    slope = np.vstack([dv, dv[-1:]])
    dmag = np.diff(mag) / np.maximum(np.diff(t), 1e-12)
    dmag = np.concatenate([dmag, dmag[-1:]])
    changing = np.max(np.abs(slope), axis=1) > SLEW_V_PER_S
    powered = mag > ZERO_V
    started = np.cumsum(powered | changing) > 0
    diff = np.abs(v[:, 1] - v[:, 0])
    label = np.where(diff <= np.maximum(1.0, 0.1 * mag), "cruise", "turn").astype(object)
    label[changing & (dmag >= 0)] = "ramp"
    label[changing & (dmag < 0)] = "brake"
    label[~powered & ~changing] = "coast"
    label[~started] = "idle"
    return _merge_short(t, label, min_duration)


def _merge_short(t: np.ndarray, label: np.ndarray, min_duration: float) -> np.ndarray:
    out = label.copy()
    starts = np.flatnonzero(np.r_[True, out[1:] != out[:-1]])
    ends = np.r_[starts[1:], len(out)]
    for s, e in zip(starts, ends):
        dur = t[min(e, len(t) - 1)] - t[s]
        if s > 0 and dur < min_duration:
            out[s:e] = out[s - 1]
    return out


def phase_spans(t: np.ndarray, label: np.ndarray) -> list[tuple[str, float, float]]:
    """Contiguous runs ``(phase, t_start, t_end)`` of a label array (for figures and reports)."""
    if len(label) == 0:
        return []
    starts = np.flatnonzero(np.r_[True, label[1:] != label[:-1]])
    ends = np.r_[starts[1:], len(label)]
    return [(str(label[s]), float(t[s]), float(t[min(e, len(t) - 1)])) for s, e in zip(starts, ends)]
