"""The gradient polish's secant evaluations: what surrounds the simulation runs in numpy on the host, with the
numbers jax gives operation by operation."""

from __future__ import annotations

import traceback

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.diagnose import candidate_set
from trackenv.diagnose.batch import BatchSimulator
from trackenv.diagnose.data import load_tests
from trackenv.diagnose.fit import full_fold, make_folds
from trackenv.diagnose.polish import SECANT_STEP, _Problem
from trackenv.fieldlog import write_log_columns

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"


def _case(folder):
    """Two short tests of the base model with white noise (SYNTHETIC)."""
    rng = np.random.default_rng(7)
    params = te.load_params("dry_sand")
    specs = {"go": [[0, 0, 0], [0.2, 11.8, 11.8], [1.5, 11.8, 11.8], [1.6, 0, 0], [2.5, 0, 0]],
             "turn": [[0, 0, 0], [0.2, 10, 14], [1.5, 10, 14], [1.6, 0, 0], [2.5, 0, 0]]}
    for name, rows in specs.items():
        traj = te.simulate(params, te.VoltageProfile.from_breakpoints(rows), 2.5, dt=0.02)
        cols = {"t": np.asarray(traj.t, float), "v_left": np.asarray(traj.voltage[:, 0], float),
                "v_right": np.asarray(traj.voltage[:, 1], float)}
        for k, s in {"i_left": 0.08, "i_right": 0.08, "speed_ideal": 0.008, "yaw_rate": 0.015}.items():
            cols[k] = np.asarray(traj.channels[k], float) + rng.normal(0, s, len(cols["t"]))
        write_log_columns(folder / name, cols, {"terrain": "dry_sand", "maneuver": name, "current_sensor": "signed",
                                                "synthetic": True, "notes": "SYNTHETIC test case: base model + noise"})
    return folder


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    tests, _ = load_tests(_case(tmp_path_factory.mktemp("polish") / "case"))
    return BatchSimulator(tests)


def _compiles(fn):
    """``fn()`` and the XLA programs compiled while it ran outside the simulation (:mod:`trackenv.simulate`)."""
    seen = []

    def listen(event, duration, **kw):
        if event == COMPILE_EVENT and not any(f.filename.endswith("simulate.py") for f in traceback.extract_stack()):
            seen.append(kw.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        out = fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    return out, seen


@pytest.mark.parametrize("name, windows", [("recalibrate_base", [None, None]), ("pitch_load_transfer", [0.1, 0.0]),
                                           ("sensor_artifacts", [None, None])])
def test_a_secant_evaluation_runs_on_the_host_with_the_numbers_of_jax(sim, name, windows):
    """``_Problem``'s secant evaluation indexes, tiles and transposes, and does its float32 +, −, ×, ÷ and |x|, in
    numpy on the host. Its residuals, Jacobian and predictions equal, bit for bit, those of the same evaluation
    with every operation in jax (``host=False``, the path forward mode traces, and what the secant evaluation
    did before), with an encoder window and for a candidate that only transforms instruments (standing on the
    control's fitted values). Eagerly, each jax operation compiles a small program for every shape it meets:
    the first evaluation at a new shape compiled 47 programs outside the simulation for ``recalibrate_base``
    and 79 for ``pitch_load_transfer`` with a window; now 12 and 6, and none that only moves data (the
    instruments model of ``sensor_artifacts``, the effect's own code, still runs in jax)."""
    cands = {c.name: c for c in candidate_set()}
    cand = cands[name]
    fold_defs = [full_fold(sim.tests), *make_folds(sim.tests)][:2]
    below = None
    if name == "sensor_artifacts":
        recal = cands["recalibrate_base"]
        cand = cand.standing_on(recal)
        below = [{k: v * (1.0 + 0.02 * f) for k, v in recal.anchor.items()} for f in range(len(fold_defs))]
    prob = _Problem(sim, cand, fold_defs, windows[:len(fold_defs)], below)
    u = np.clip(np.stack([cand.anchor_unit() for _ in fold_defs]) + 0.05, 0.01, 0.99)
    if below is not None:
        u = u[:, :cand.n_params]
    z = (np.log(u) - np.log1p(-u)).astype(np.float32)
    (r, J, pred), programs = _compiles(lambda: prob(z))
    moves = {"jit(dynamic_slice)", "jit(gather)", "jit(concatenate)", "jit(transpose)", "jit(reshape)", "jit(squeeze)",
             "jit(_multi_slice)", "jit(tile)", "jit(_moveaxis)"}
    if not cand.instrument_only:  # sensor_artifacts' own instrument model runs in jax, operation by operation
        assert len(programs) <= 12 and not moves & set(programs), programs
    # the evaluation as it was, every operation in jax
    F, p = z.shape
    shifts = np.concatenate([np.zeros((1, p)), SECANT_STEP * np.eye(p), -SECANT_STEP * np.eye(p)])
    Z = (jnp.asarray(z)[None] + jnp.asarray(shifts, jnp.float32)[:, None]).reshape(((2 * p + 1) * F, p))
    R_ops, pred_ops = prob._residual(Z, host=False)
    R_ops = R_ops.reshape((2 * p + 1, F) + R_ops.shape[1:])
    J_ops = jnp.moveaxis((R_ops[1: p + 1] - R_ops[p + 1:]) / (2.0 * SECANT_STEP), 0, -1)
    np.testing.assert_array_equal(r, np.asarray(R_ops[0], np.float64))
    np.testing.assert_array_equal(J, np.asarray(J_ops, np.float64))
    assert pred.keys() == pred_ops.keys()
    for k in pred:
        np.testing.assert_array_equal(pred[k], np.asarray(pred_ops[k])[:F])
    assert np.isfinite(r).all() and np.abs(J).max() > 0
    # a second evaluation at other points of the same shape compiles nothing
    _, again = _compiles(lambda: prob(z + np.float32(0.3)))
    assert again == []
