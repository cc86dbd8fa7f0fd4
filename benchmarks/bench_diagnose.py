"""Wall time of a 6-test gap diagnosis (``trackenv.diagnose``) on the synthetic field twin.

    python benchmarks/bench_diagnose.py [--substep 0.001] [--tests a,b,...] [--compare-bucket-fill 0.75] [--each-terrain]

Runs the diagnosis unchanged (its own fit substep unless ``--substep`` is given) on six tests of
``data/field/thesis`` (the four go-stops and J-turns and both lane changes), without figures, and
prints the wall time, the verdict, the host devices it had, and how much of the wall time XLA spent
compiling (JAX's ``/jax/core/compile/backend_compile_duration`` events, :mod:`jax.monitoring`): in all,
and for the simulation programs (``trackenv.simulate._simulate_in_parts``, the jitted ``simulate_core``).
No compilation cache is used unless ``JAX_COMPILATION_CACHE_DIR`` is set. With ``--compare-bucket-fill F`` it then
runs the same diagnosis again in the same process with ``trackenv.diagnose.batch.BUCKET_FILL = F`` (the
rule that decides which tests share a padded batch) and prints both times and the ratio. The default
rule runs first, so that any warm-up the second run gets favours the alternative. With ``--each-terrain`` the
same tests are diagnosed one terrain at a time (``trackenv.diagnose.diagnose_each_terrain``): it prints the wall
time, the combined verdict and each terrain's.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import jax

import trackenv  # noqa: F401  (host devices are set up at import)
from trackenv import parallel
from trackenv.diagnose import batch, diagnose
from trackenv.diagnose.data import load_tests

ROOT = Path(__file__).resolve().parent.parent
COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
COMPILES: list[tuple[str, float]] = []  # (function name, seconds) of every XLA compilation


def _on_duration(event: str, duration: float, **kw) -> None:
    if event == COMPILE_EVENT:
        COMPILES.append((str(kw.get("fun_name", "")), duration))


def compile_summary(since: int = 0) -> str:
    """The XLA compilations recorded after the first ``since``: count and seconds, in all and of the simulation core."""
    done = COMPILES[since:]
    sim = [d for name, d in done if name == "jit(_simulate_in_parts)"]
    return (f"compiling {sum(d for _, d in done):.1f} s ({len(done)} programs; {sum(sim):.1f} s of it for "
            f"{len(sim)} simulation programs)")


TESTS = ["go_stop_dry_sand", "go_stop_asphalt", "j_turn_dry_sand", "j_turn_asphalt",
         "lane_change_dry_sand", "lane_change_asphalt"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", default=",".join(TESTS))
    ap.add_argument("--substep", type=float, default=None)
    ap.add_argument("--compare-bucket-fill", type=float, default=None,
                    help="also run with this BUCKET_FILL, in the same process, and print the ratio")
    ap.add_argument("--each-terrain", action="store_true", help="one diagnosis per terrain, then the combined verdict")
    a = ap.parse_args()
    kw = {} if a.substep is None else {"substep": a.substep}
    tests = a.tests.split(",")
    if a.each_terrain:
        from trackenv.diagnose import diagnose_each_terrain

        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        t0 = time.perf_counter()
        r = diagnose_each_terrain(ROOT / "data/field/thesis", None, tests=tests, figures=False, progress=False, **kw)
        wall = time.perf_counter() - t0
        print(f"{len(tests)}-test diagnosis, each terrain on its own: {wall:.1f} s wall on {len(parallel.cpu_devices())} "
              f"host device(s); verdict: {r.verdict['effect']} (over all tests: held-out gap shrink "
              f"{100 * r.verdict['heldout_gap_shrink']:.0f}%, in-sample {100 * r.verdict['insample_gap_shrink']:.0f}%); "
              f"{compile_summary()}", flush=True)
        for terrain, d in r.by_terrain.items():
            print(f"  {terrain} ({d.report['timing']['wall_s']:.1f} s): {d.verdict['verdict_line']}")
        return
    fills = [batch.BUCKET_FILL] + ([] if a.compare_bucket_fill is None else [a.compare_bucket_fill])
    data, _ = load_tests(ROOT / "data/field/thesis", tests)  # read once, for the bucket counts only
    walls = []
    jax.monitoring.register_event_duration_secs_listener(_on_duration)
    for fill in fills:
        batch.BUCKET_FILL = fill
        n_buckets = len(batch.make_buckets(data))
        since = len(COMPILES)
        t0 = time.perf_counter()
        d = diagnose(ROOT / "data/field/thesis", None, tests=tests, figures=False, progress=False, **kw)
        walls.append(time.perf_counter() - t0)
        print(f"{len(tests)}-test diagnosis (BUCKET_FILL {fill:g}: {n_buckets} buckets): {walls[-1]:.1f} s wall on "
              f"{len(parallel.cpu_devices())} host device(s); verdict: {d.verdict.get('effect')}; "
              f"{compile_summary(since)}", flush=True)
    if len(walls) == 2:
        print(f"BUCKET_FILL {fills[1]:g} / {fills[0]:g} wall time: {walls[1] / walls[0]:.2f}")


if __name__ == "__main__":
    main()
