"""Speed of the simulator: simulated seconds per wall second, single and batched, with XLA's cost.

    python benchmarks/bench_simulate.py            # full table (a few minutes on 2 cores)
    python benchmarks/bench_simulate.py --quick    # smaller batches

Prints a Markdown table for the README: compile time, wall time of a 10 s maneuver, real-time factor
(simulated s / wall s, aggregated over the batch), XLA's FLOP count per substep and the achieved
GFLOP/s beside the machine's measured peak (a large float32 matmul), and what bounds the step.
Batches are run two ways: ``jax.vmap`` of the single-vehicle program, and the native layout with the
vehicle index on the last axis of every array (MODEL.md §6), which needs no vmap.
"""

from __future__ import annotations

import argparse
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

import trackenv as te
from trackenv.physics.model import initial_state
from trackenv.simulate import DEFAULT_SUBSTEP, _simulate_jit, n_substeps

T_END = 10.0
DT = 0.05


def go_stop_profile(batch: int | None):
    rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [6.0, 11.8, 11.8], [6.1, 0, 0], [T_END, 0, 0]], float)
    t, v = rows[:, 0], rows[:, 1:]
    if batch:  # one slightly different profile per vehicle, vehicles on the last axis
        scale = np.linspace(0.8, 1.2, batch)
        v = v[:, :, None] * scale[None, None, :]
    return te.VoltageProfile.from_arrays(t, v)


def timed(fn, repeat: int):
    out = fn()
    jax.block_until_ready(out)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def peak_gflops(n: int = 2048, repeat: int = 5) -> float:
    a = jnp.ones((n, n), jnp.float32)
    f = jax.jit(lambda x: x @ x)
    t = timed(lambda: f(a), repeat)
    return 2 * n**3 / t / 1e9


def flops_of(compiled) -> float:
    cost = compiled.cost_analysis()
    if isinstance(cost, (list, tuple)):
        cost = cost[0]
    return float(cost.get("flops", float("nan"))) if cost else float("nan")


def substep_flops(params, batch: tuple) -> float:
    """XLA's FLOP count of one integration substep for ``batch`` vehicles (loops are not unrolled
    by the cost model, so the count is taken on the substep itself)."""
    from trackenv.integrate import current_coeffs, etdrk4_substep

    h = DEFAULT_SUBSTEP
    s0 = initial_state(params, batch)
    v3 = jnp.full((3, 2) + batch, 11.8, jnp.float32)
    f = jax.jit(lambda s, v: etdrk4_substep(s, v, params, h, current_coeffs(params, h)))
    return flops_of(f.lower(s0, v3).compile())


def run(batches, repeat: int):
    params = te.load_params("dry_sand")
    substeps = n_substeps(DT, DEFAULT_SUBSTEP)
    n_steps = int(round(T_END / DT))
    rows = []

    # single trajectory
    prof = go_stop_profile(None)
    s0 = initial_state(params)
    t0 = time.perf_counter()
    compiled = _simulate_jit.lower(params, prof, s0, n_steps=n_steps, dt=DT, substeps=substeps).compile()
    compile_s = time.perf_counter() - t0
    wall = timed(lambda: compiled(params, prof, s0), repeat)
    rows.append(("single", 1, compile_s, wall, substep_flops(params, ())))

    vsim = jax.jit(
        jax.vmap(lambda p, s: _simulate_jit.__wrapped__(params, p, s, n_steps, DT, substeps), in_axes=(0, 0)),
    )
    for b in batches:
        # native layout: vehicles on the last axis
        prof_b = go_stop_profile(b)
        s0_b = initial_state(params, (b,))
        t0 = time.perf_counter()
        comp_b = _simulate_jit.lower(params, prof_b, s0_b, n_steps=n_steps, dt=DT, substeps=substeps).compile()
        c_b = time.perf_counter() - t0
        wall_b = timed(lambda: comp_b(params, prof_b, s0_b), max(1, repeat // 2))
        rows.append(("last-axis", b, c_b, wall_b, substep_flops(params, (b,))))
        # jax.vmap of the single-vehicle program
        prof_v = te.VoltageProfile(jnp.broadcast_to(prof.t, (b,) + prof.t.shape),
                                   jnp.moveaxis(prof_b.volts, -1, 0))
        s0_v = jax.tree.map(lambda x: jnp.broadcast_to(x, (b,) + x.shape), s0)
        t0 = time.perf_counter()
        comp_v = vsim.lower(prof_v, s0_v).compile()
        c_v = time.perf_counter() - t0
        wall_v = timed(lambda: comp_v(prof_v, s0_v), max(1, repeat // 2))
        rows.append(("vmap", b, c_v, wall_v, substep_flops(params, (b,))))
    return rows, substeps, n_steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="batches 1, 64 only")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args(argv)
    batches = (1, 64) if args.quick else (1, 64, 256, 1024)
    peak = peak_gflops()
    rows, substeps, n_steps = run(batches, args.repeat)
    n_sub_total = substeps * n_steps
    print(f"machine: {platform.processor() or platform.machine()}, {jax.device_count()} x {jax.devices()[0].device_kind}, "
          f"jax {jax.__version__}; float32; substep {DT / substeps * 1e3:g} ms; maneuver {T_END:g} s go-stop on dry sand")
    print(f"peak (2048^2 float32 matmul): {peak:.1f} GFLOP/s\n")
    print("| layout | vehicles | compile s | wall s (10 s maneuver) | x real time (aggregate) | us / substep / vehicle | FLOP / substep / vehicle | GFLOP/s | % of peak |")
    print("|---|---|---|---|---|---|---|---|---|")
    for layout, b, c, w, fl in rows:
        rt = T_END * b / w
        per = w / n_sub_total / b * 1e6
        fl_sub = fl / b
        gf = fl * n_sub_total / w / 1e9
        print(f"| {layout} | {b} | {c:.1f} | {w * 1e3:.1f} ms | {rt:,.0f} | {per:.2f} | {fl_sub:,.0f} | {gf:.2f} | {100 * gf / peak:.1f} |")
    single = rows[0]
    gf = single[4] * n_sub_total / single[3] / 1e9
    print(
        f"\nWhat bounds the step: a single vehicle does ~{single[4]:,.0f} FLOP per substep in "
        f"{single[3] / n_sub_total * 1e6:.1f} us, i.e. {gf:.2f} GFLOP/s ({100 * gf / peak:.2f}% of peak): it is bound by "
        "per-kernel dispatch inside XLA's loop (about 56 small fused kernels per substep on (2, 14) arrays), "
        "not by arithmetic or memory. Batching amortises that overhead until the per-substep working set "
        "leaves the caches."
    )


if __name__ == "__main__":
    main()
