"""Stability sweep behind ``trackenv.simulate.MAX_SUBSTEP``: the largest substep that stays bounded.

    python benchmarks/stability.py

Simulates the thesis maneuvers (go-stop, J-turn, lane change, zero-radius turns on both terrains)
and a full ±24 V reversal at growing substeps, float32, and prints for each whether the run
diverged (non-finite or beyond ``integrate.physical_bounds``) and the peak |current| and |omega|.
The guard runs in a private copy of the simulation loop so that substeps above the limit can be
tried.
"""

from __future__ import annotations

import numpy as np

import trackenv as te
from trackenv.check_maneuvers import check_maneuvers
from trackenv.physics.model import initial_state
from trackenv.simulate import MAX_SUBSTEP, n_substeps, simulate_batch

MANEUVERS = {
    **check_maneuvers(),
    "reversal_24V_asphalt": ("asphalt", [[0, 0, 0], [0.1, 24, 24], [1.0, 24, 24], [1.1, -24, -24], [2.0, -24, -24],
                                         [2.1, 24, -24], [3, 24, -24]], 3.0),
}
DT = 0.05


def main():
    print(f"MAX_SUBSTEP = {MAX_SUBSTEP * 1e3:g} ms\n")
    print("| substep ms | " + " | ".join(MANEUVERS) + " |")
    print("|---" * (len(MANEUVERS) + 1) + "|")
    for h in (0.002, 0.005, 0.0075, 0.01, 0.0125, 0.0167, 0.025, 0.05):
        cells = []
        for terrain, rows, t_end in MANEUVERS.values():
            p = te.load_params(terrain)
            prof = te.VoltageProfile.from_breakpoints(rows)
            tr = simulate_batch(p, prof, int(round(t_end / DT)), DT, n_substeps(DT, h), initial_state(p))
            i = np.nanmax(np.abs(np.asarray(tr.state.current)))
            cells.append(("**diverged** " if bool(tr.diverged) else "") + f"{i:.3g} A")
        print(f"| {h * 1e3:g} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
