"""Wall time of a 6-test gap diagnosis (``trackenv.diagnose``) on the synthetic field twin.

    python benchmarks/bench_diagnose.py [--substep 0.001] [--tests a,b,...]

Runs the diagnosis unchanged (its own fit substep unless ``--substep`` is given) on six tests of
``data/field/thesis`` (the four go-stops and J-turns and both lane changes), without figures, and
prints the wall time, the verdict, and the host devices it had.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import trackenv  # noqa: F401  (host devices are set up at import)
from trackenv import parallel
from trackenv.diagnose import diagnose

ROOT = Path(__file__).resolve().parent.parent
TESTS = ["go_stop_dry_sand", "go_stop_asphalt", "j_turn_dry_sand", "j_turn_asphalt",
         "lane_change_dry_sand", "lane_change_asphalt"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", default=",".join(TESTS))
    ap.add_argument("--substep", type=float, default=None)
    a = ap.parse_args()
    kw = {} if a.substep is None else {"substep": a.substep}
    t0 = time.perf_counter()
    d = diagnose(ROOT / "data/field/thesis", None, tests=a.tests.split(","), figures=False, progress=False, **kw)
    wall = time.perf_counter() - t0
    verdict = getattr(d, "verdict", None) or (d.get("verdict") if isinstance(d, dict) else None)
    print(f"{len(a.tests.split(','))}-test diagnosis: {wall:.1f} s wall on {len(parallel.cpu_devices())} host device(s); "
          f"verdict: {verdict if not isinstance(verdict, dict) else verdict.get('effect')}")


if __name__ == "__main__":
    main()
