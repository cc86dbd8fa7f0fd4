"""Short open-loop voltage programmes of the thesis maneuvers for the numerical checks.

The convergence test (tests/test_convergence.py) and the stability sweep (benchmarks/stability.py)
drive the simulator with these breakpoint tables, each on dry sand and on asphalt: idealised versions of
the reconstructed thesis inputs (configs/field), a 0.3 s ramp to the cruise voltage and short ramps between the levels, so that
each maneuver's speed, turn and stop phases are present in a few seconds of simulated time::

    from trackenv.check_maneuvers import check_maneuvers
    terrain, rows, t_end = check_maneuvers()["go_stop_sand"]
    traj = te.simulate(te.load_params(terrain), te.VoltageProfile.from_breakpoints(rows), t_end)

Each entry: the terrain id (configs/terrain), the breakpoints ``[t [s], V_left [V], V_right [V]]``
(linear between them, held after the last) and the end time ``t_end`` [s].
"""

from __future__ import annotations

from typing import NamedTuple


class CheckManeuver(NamedTuple):
    """One voltage programme: terrain id, breakpoints [t, V_left, V_right] (s, V, V) and end time [s]."""

    terrain: str
    rows: list[list[float]]
    t_end: float


def check_maneuvers() -> dict[str, CheckManeuver]:
    """The maneuver programmes by id (fresh lists on every call, so callers may modify them)."""
    spin = [[0, 0, 0], [0.3, 12, -12], [2.0, 12, -12], [2.1, 0, 0]]  # +-12 V clockwise spin, 1.7 s
    go_stop = [[0, 0, 0], [0.3, 11.8, 11.8], [3.0, 11.8, 11.8], [3.1, 0, 0]]
    j_turn = [[0, 0, 0], [0.3, 11.8, 11.8], [1.5, 11.8, 11.8], [1.7, 16, 6], [2.6, 16, 6], [2.7, 0, 0]]
    lane_change = [[0, 0, 0], [0.3, 11.8, 11.8], [1.0, 11.8, 11.8], [1.1, 9, 14.6], [1.6, 9, 14.6], [1.7, 14.6, 9],
                   [2.2, 14.6, 9], [2.3, 11.8, 11.8], [2.8, 11.8, 11.8], [2.9, 0, 0]]
    table = {"go_stop": (go_stop, 4.5), "j_turn": (j_turn, 4.0), "lane_change": (lane_change, 4.0),
             "zero_radius_turn": (spin, 2.3)}
    return {f"{name}_{short}": CheckManeuver(terrain, [list(r) for r in rows], t_end)
            for name, (rows, t_end) in table.items() for short, terrain in (("sand", "dry_sand"), ("asphalt", "asphalt"))}


def is_spin(maneuver: CheckManeuver) -> bool:
    """True for a spin in place (equal and opposite voltages at every breakpoint)."""
    return all(vl == -vr for _, vl, vr in maneuver.rows)
