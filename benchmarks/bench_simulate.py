"""Speed of the simulator: one trajectory, batches, compile time, kernels, FLOP rate, and scipy.

    python benchmarks/bench_simulate.py                  # full table (several minutes on 2 cores)
    python benchmarks/bench_simulate.py --quick          # batches 64, 256 only
    python benchmarks/bench_simulate.py --batches 1024 4096 --batch-t-end 1

Prints Markdown tables for the README, every number from this one process run:

- the compiled substep: fused kernels in the substep loop's body (XLA's optimised HLO), XLA's FLOP
  count and the wall time per substep, for one vehicle and for a batch;
- one 10 s go-stop on dry sand at the default substep (compile time, wall time, x real time), and
  the same model as a plain numpy right-hand side (``numpy_model.py``, checked against the JAX
  derivative) under ``scipy.integrate.solve_ivp`` (LSODA, rtol 1e-6) on the same voltage log;
- batches (vehicles on the last axis, docs/model.md §6) through ``te.simulate``, which splits large
  batches across the host devices (``trackenv.parallel``), and the same batch on one device;
- GFLOP/s beside the machine's measured peak (a 2048^2 float32 matmul);
- one trajectory again in a fresh process with ``TRACKENV_SMALL_LOOP_BYTES=0`` (XLA's small-loop
  emission off, ``trackenv.parallel``), and the speed-up of the default over it (``--one`` prints only
  the one-trajectory line, the form that process runs);
- the two forms of the contact-point sums (``trackenv.physics.sums``: XLA's ``reduce`` and unrolled
  additions) per batch size, each compiled and timed in this process (``--sums`` prints only that table);
- the cost per element of the transcendental functions on the model's element arrays (``--ops`` prints
  only that table): XLA's CPU ``pow`` is not vectorised, and on one vehicle's arrays nothing is.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import trackenv as te
from trackenv import parallel
from trackenv.integrate import current_coeffs, etdrk4_substep
from trackenv.physics import sums
from trackenv.physics.model import initial_state
from trackenv.simulate import DEFAULT_SUBSTEP, n_substeps, simulate_core

sys.path.insert(0, str(Path(__file__).parent))
import numpy_model  # noqa: E402

T_END = 10.0
DT = 0.05
ROWS = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [6.0, 11.8, 11.8], [6.1, 0, 0], [T_END, 0, 0]], float)
# the same compiled core as trackenv.simulate.simulate_batch, jitted here for ahead-of-time lowering (fusion count)
CORE_JIT = jax.jit(simulate_core, static_argnames=("n_steps", "dt", "substeps", "t0", "unroll"))


def go_stop_profile(batch: int | None):
    t, v = ROWS[:, 0], ROWS[:, 1:]
    if batch:  # one slightly different profile per vehicle, vehicles on the last axis
        v = v[:, :, None] * np.linspace(0.8, 1.2, batch)[None, None, :]
    return te.VoltageProfile.from_arrays(t, v)


def timed(fn, repeat: int):
    jax.block_until_ready(fn())
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def peak_gflops(n: int = 2048, repeat: int = 5) -> float:
    a = jnp.ones((n, n), jnp.float32)
    f = jax.jit(lambda x: x @ x)
    return 2 * n**3 / timed(lambda: f(a), repeat) / 1e9


def substep_kernels(params, batch: tuple, n_loop: int):
    """(fusions in the loop body, FLOP per substep, us per substep) of a loop of substeps."""
    h = DEFAULT_SUBSTEP
    s0 = jax.tree.map(lambda x: x + 0.01, initial_state(params, batch))
    v3 = jnp.full((3, 2) + batch, 11.8, params.dtype)
    one = jax.jit(lambda s, v: etdrk4_substep(s, v, params, h, current_coeffs(params, h))).lower(s0, v3).compile()
    cost = one.cost_analysis()
    cost = cost[0] if isinstance(cost, (list, tuple)) else cost
    flops = float(cost.get("flops", np.nan)) if cost else np.nan
    loop = jax.jit(lambda s, v: jax.lax.fori_loop(
        0, n_loop, lambda _, x: etdrk4_substep(x, v, params, h, current_coeffs(params, h)), s))
    comp = loop.lower(s0, v3).compile()
    text = comp.as_text()
    bodies = re.split(r"\n(?=\S)", text)
    counts = [len(re.findall(r"= \S+ fusion\(", b)) for b in bodies]
    wall = timed(lambda: comp(s0, v3), 3)
    return max(counts), flops, wall / n_loop * 1e6


def sum_forms(params, batches, n_steps: int = 20, repeat: int = 7) -> None:
    """Table: us / substep / vehicle with XLA's reduce and with unrolled sums, and the form the policy picks."""
    substeps = n_substeps(DT, DEFAULT_SUBSTEP)
    print("| vehicles | reduce: us / substep / vehicle | unrolled: us / substep / vehicle | unrolled / reduce speed-up "
          "| form used |")
    print("|---|---|---|---|---|")
    keep = sums.UNROLL_MIN, sums.UNROLL_MAX
    try:
        for b in batches:
            prof = go_stop_profile(b)
            s0 = initial_state(params, (b,))
            comps = []
            for lo, hi in ((10**9, 10**9), (1, 10**9)):  # never unrolled, always unrolled
                sums.UNROLL_MIN, sums.UNROLL_MAX = lo, hi
                fresh = jax.jit(lambda *a, **k: simulate_core(*a, **k),  # a new function: JAX traces it anew
                                static_argnames=("n_steps", "dt", "substeps"))
                comps.append(fresh.lower(params, prof, s0, n_steps=n_steps, dt=DT, substeps=substeps).compile())
            best = [np.inf, np.inf]
            for _ in range(repeat):  # interleaved, so that a change of load hits both forms alike
                for k, comp in enumerate(comps):
                    best[k] = min(best[k], timed(lambda: comp(params, prof, s0), 1))
            us = [w / (n_steps * substeps) / b * 1e6 for w in best]
            sums.UNROLL_MIN, sums.UNROLL_MAX = keep
            print(f"| {b} | {us[0]:.2f} | {us[1]:.2f} | {us[0] / us[1]:.2f} | "
                  f"{'unrolled' if sums.unrolled(b) else 'reduce'} |", flush=True)
    finally:
        sums.UNROLL_MIN, sums.UNROLL_MAX = keep


def elementwise_ops(shapes=((2, 14), (2, 14, 256)), n_loop: int = 2000, repeat: int = 5) -> None:
    """Table: ns per element of the transcendental functions the substep uses, on the model's element
    arrays (one vehicle, 256 vehicles), each in a jitted loop of ``n_loop`` dependent evaluations."""
    ops = {
        "identity (loop overhead)": lambda v: v,
        "exp": jnp.exp,
        "log": jnp.log,
        "exp(a log x)": lambda v: jnp.exp(1.9 * jnp.log(v)),
        "x ** a (pow)": lambda v: v ** 1.9,
        "expm1": jnp.expm1,
        "tanh": jnp.tanh,
        "sin": jnp.sin,
    }
    print("| function | " + " | ".join(f"ns / element, {s}" for s in shapes) + " |")
    print("|---|" + "---|" * len(shapes))
    rng = np.random.default_rng(0)
    rows = {name: [] for name in ops}
    for shape in shapes:
        x = jnp.asarray(rng.uniform(0.1, 2.0, shape).astype(np.float32))
        for name, f in ops.items():
            loop = jax.jit(lambda x, f=f: jax.lax.fori_loop(0, n_loop, lambda _, c: c + 1e-6 * f(1e-3 * c + x), x))
            w = timed(lambda: loop(x), repeat)
            rows[name].append(w / n_loop / x.size * 1e9)
    for name, vals in rows.items():
        print(f"| {name} | " + " | ".join(f"{v:.2f}" for v in vals) + " |")


def scipy_seconds(params, t_end: float) -> float:
    rhs = numpy_model.make_rhs(params, ROWS[:, 0], ROWS[:, 1:])
    from scipy.integrate import solve_ivp
    t0 = time.perf_counter()
    sol = solve_ivp(rhs, (0.0, t_end), np.zeros(66), method="LSODA", rtol=1e-6, atol=1e-9,
                    t_eval=np.arange(0.0, t_end + 1e-9, DT))
    wall = time.perf_counter() - t0
    if sol.status != 0:
        raise RuntimeError(f"LSODA failed: {sol.message}")
    return wall


def one_trajectory(params, repeat: int) -> float:
    """Compile and time one 10 s go-stop at the default substep; print its line; return the wall time [s]."""
    substeps = n_substeps(DT, DEFAULT_SUBSTEP)
    n_steps = int(round(T_END / DT))
    prof = go_stop_profile(None)
    s0 = initial_state(params)
    t0 = time.perf_counter()
    comp = CORE_JIT.lower(params, prof, s0, n_steps=n_steps, dt=DT, substeps=substeps).compile()
    compile_s = time.perf_counter() - t0
    wall = timed(lambda: comp(params, prof, s0), repeat)
    loops = "substep loop as one kernel" if parallel.substep_loop_is_one_kernel(comp) else "substep loop as separate kernels"
    print(f"one trajectory (10 s go-stop, dry sand; {loops}): compile {compile_s:.1f} s, wall {wall * 1e3:.1f} ms, "
          f"{T_END / wall:.0f}x real time, {wall / (n_steps * substeps) * 1e6:.2f} us / substep", flush=True)
    return wall


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="batches 64, 256 only")
    ap.add_argument("--batches", type=int, nargs="*", default=None)
    ap.add_argument("--batch-t-end", type=float, default=2.0, help="simulated seconds per batch run (first part of the go-stop)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-scipy", action="store_true")
    ap.add_argument("--sums", action="store_true", help="only the table of the two forms of the contact-point sums")
    ap.add_argument("--sum-batches", type=int, nargs="*", default=[1, 8, 16, 64, 128, 256, 1024])
    ap.add_argument("--one", action="store_true", help="only the one-trajectory line (no scipy, no tables)")
    ap.add_argument("--ops", action="store_true", help="only the table of elementwise function costs")
    args = ap.parse_args(argv)
    if args.one:
        one_trajectory(te.load_params("dry_sand"), args.repeat)
        return
    batches = args.batches if args.batches is not None else ((64, 256) if args.quick else (64, 256, 1024, 4096))
    params = te.load_params("dry_sand")
    substeps = n_substeps(DT, DEFAULT_SUBSTEP)
    if args.sums:
        sum_forms(params, args.sum_batches)
        return
    if args.ops:
        elementwise_ops()
        return
    print(f"machine: {platform.processor() or platform.machine()}, {len(parallel.cpu_devices())} host devices "
          f"(cores: {parallel._cores()}), jax {jax.__version__}; float32; substep {DT / substeps * 1e3:g} ms")
    peak = peak_gflops()
    print(f"peak (2048^2 float32 matmul, one core): {peak:.1f} GFLOP/s\n")

    # the compiled substep
    print("| substep loop | fused kernels in the loop body | FLOP / substep / vehicle | us / substep | us / substep / vehicle | GFLOP/s | % of peak |")  # noqa: E501
    print("|---|---|---|---|---|---|---|")
    for batch, n_loop in (((), 2000), ((256,), 50)):
        nf, fl, us = substep_kernels(params, batch, n_loop)
        b = batch[0] if batch else 1
        gf = fl / us / 1e3
        print(f"| {b} vehicle{'s' if b > 1 else ''} | {nf} | {fl / b:,.0f} | {us:.2f} | {us / b:.3f} | {gf:.2f} | {100 * gf / peak:.1f} |")

    # one trajectory, and scipy on the same log
    print()
    wall = one_trajectory(params, args.repeat)
    off = subprocess.run([sys.executable, __file__, "--one", "--repeat", str(args.repeat)], capture_output=True,
                         text=True, check=True, env={**os.environ, "TRACKENV_SMALL_LOOP_BYTES": "0"}).stdout
    wall_off = float(re.search(r"wall ([0-9.]+) ms", off).group(1)) / 1e3
    print(f"the same without small loops as one kernel (TRACKENV_SMALL_LOOP_BYTES=0, a fresh process): wall "
          f"{wall_off * 1e3:.1f} ms, {T_END / wall_off:.0f}x real time; the default is {wall_off / wall:.2f}x faster")
    if not args.no_scipy:
        err = numpy_model.check(params)
        sp = scipy_seconds(params, T_END)
        print(f"numpy RHS (max relative deviation from the JAX derivative {err:.1e}) under scipy solve_ivp LSODA "
              f"(rtol 1e-6, atol 1e-9): {sp:.2f} s, {T_END / sp:.1f}x real time; trackenv is {sp / wall:.1f}x faster")

    # batches
    print(f"\n| vehicles | split over devices | compile s | wall s ({args.batch_t_end:g} s simulated) | x real time (aggregate) "
          f"| us / substep / vehicle | one device: x real time | split / one device |")
    print("|---|---|---|---|---|---|---|---|")
    for b in batches:
        prof_b = go_stop_profile(b)
        run = lambda: te.simulate(params, prof_b, args.batch_t_end, dt=DT, on_divergence="flag").channels  # noqa: E731
        t0 = time.perf_counter()
        jax.block_until_ready(run())
        first = time.perf_counter() - t0
        rep = 1 if b >= 1024 else args.repeat
        w = timed(run, rep)
        split = parallel.split_count(b)
        per = w / (args.batch_t_end / DT * substeps) / b * 1e6
        if split > 1:
            keep = parallel.MIN_PER_DEVICE
            parallel.MIN_PER_DEVICE = 10**12
            try:
                w1 = timed(run, rep)
            finally:
                parallel.MIN_PER_DEVICE = keep
            one = f"{args.batch_t_end * b / w1:,.0f} | {w1 / w:.2f}"
        else:
            one = "(same) | 1"
        print(f"| {b} | {split} | {first - w:.1f} | {w:.2f} | {args.batch_t_end * b / w:,.0f} | {per:.3f} | {one} |", flush=True)
    print("\n(compile s of a batch: first call minus a timed call.)\n")
    sum_forms(params, args.sum_batches)


if __name__ == "__main__":
    main()
