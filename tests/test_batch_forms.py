"""Forms the simulator chooses for speed by batch shape compute the same model.

- ``terramechanics.positive_power``: XLA's ``pow`` for small batches, exp(a log x) from
  ``EXP_LOG_POWER_MIN`` vehicles; both against float64 numpy, with a finite gradient at x = 0.
- ``simulate.shared_leaves_as_scalars``: a batch's parameter leaves that hold one value for every vehicle
  become scalars; the simulation equals the one with the per-vehicle arrays to rounding, and leaves that
  differ between vehicles, or are traced, stay as they are. The leaves the diagnosis's control scales stay
  arrays when asked (``keep``), so that its batches on asphalt (zero cohesion) and sand share a program,
  with the scalar form's numbers to the last bit.
- ``sums.divide_by_parameter``: the division by J_eff, kept a division in the compiled program, so that a
  per-vehicle J_eff does not make XLA copy the per-track chain into every contact point's fusion.
"""

import re

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.compare import stack_trees
from trackenv.physics import terramechanics as tm
from trackenv.physics.sums import divide_by_parameter
from trackenv.simulate import _simulate_jit, shared_leaves_as_scalars, simulate_batch


@pytest.mark.parametrize("batch", [(), (8,), (tm.EXP_LOG_POWER_MIN,), (4 * tm.EXP_LOG_POWER_MIN,)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_positive_power_matches_numpy_in_both_forms(batch, dtype):
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 2e5, size=(2, 14) + batch)  # Pa: element pressures
    x.flat[0], x.flat[1] = 0.0, -3.0  # an unloaded element, and a negative input (max(x, 0) = 0)
    a = 1.0 + 1.0 / 1.1  # (n + 1)/n of dry sand
    want = np.maximum(x, 0.0) ** a
    with jax.enable_x64(dtype == np.float64):
        got = np.asarray(jax.jit(lambda v: tm.positive_power(v, a, len(batch)))(jnp.asarray(x, dtype)))
    assert got.dtype == dtype
    rtol = 3e-6 if dtype == np.float32 else 1e-13
    np.testing.assert_allclose(got, want, rtol=rtol, atol=0.0)


@pytest.mark.parametrize("batch", [(), (4 * tm.EXP_LOG_POWER_MIN,)])
def test_positive_power_gradient_is_finite_at_zero(batch):
    x = jnp.zeros((2, 14) + batch, jnp.float32).at[0, 0].set(2.0)
    g = jax.grad(lambda v: tm.positive_power(v, 1.9, len(batch)).sum())(x)
    assert bool(jnp.all(jnp.isfinite(g)))
    assert float(g[0, 0].reshape(-1)[0]) == pytest.approx(1.9 * 2.0**0.9, rel=1e-5)


def _batch(n: int):
    """A stacked batch on dry sand where only the cohesion differs between vehicles, and its voltages."""
    base = te.load_params("dry_sand")
    trees = [te.replace(base, **{"terrain.cohesion": float(base.terrain.cohesion) * (1.0 + 0.05 * k)}) for k in range(n)]
    params = stack_trees(trees)
    rows = np.array([[0, 0, 0], [0.2, 11.8, 11.8], [0.8, 16.0, 6.0], [1.2, 0.0, 0.0]])
    volts = np.repeat(rows[:, 1:, None], n, axis=2)
    return params, te.VoltageProfile.from_arrays(rows[:, 0], volts)


def test_shared_leaves_become_scalars_and_differing_ones_stay():
    params, _ = _batch(6)
    out = shared_leaves_as_scalars(params, (6,))
    assert out.terrain.cohesion.shape == (6,)  # differs between the vehicles
    assert out.vehicle.drive_inertia.shape == () and out.vehicle.track_gauge.shape == ()
    assert float(out.vehicle.mass) == float(params.vehicle.mass[0])
    assert out.vehicle.mass.dtype == params.vehicle.mass.dtype
    shapes = jax.eval_shape(lambda p: shared_leaves_as_scalars(p, (6,)), params)  # traced: nothing collapses
    assert shapes.vehicle.mass.shape == (6,)


def test_simulation_with_shared_leaves_as_scalars_equals_the_per_vehicle_arrays():
    params, prof = _batch(6)
    initial = te.initial_state(params, (6,))
    got = simulate_batch(params, prof, 24, 0.05, 100, initial)
    want = _simulate_jit(params, prof, initial, n_steps=24, dt=0.05, substeps=100, t0=0.0, unroll=1)
    for ch in ("speed_ideal", "yaw_rate", "i_left", "i_right", "x", "heading"):
        a, b = np.asarray(got.channels[ch]), np.asarray(want.channels[ch])
        assert np.max(np.abs(a - b)) <= 1e-4 * max(np.max(np.abs(b)), 1e-3), ch
    assert not np.array_equal(np.asarray(got.channels["speed_ideal"][-1, 0]),
                              np.asarray(got.channels["speed_ideal"][-1, 5]))  # the cohesion still differs


@pytest.mark.parametrize("den_shape", [(), (5,)])
def test_divide_by_parameter_is_the_division_with_its_gradient(den_shape):
    rng = np.random.default_rng(3)
    num = jnp.asarray(rng.normal(size=(2, 5)), jnp.float32)
    den = jnp.asarray(rng.uniform(0.5, 2.0, size=den_shape), jnp.float32)
    np.testing.assert_allclose(np.asarray(divide_by_parameter(num, den)), np.asarray(num) / np.asarray(den), rtol=1e-7)
    g_num, g_den = jax.grad(lambda n, d: divide_by_parameter(n, d).sum(), argnums=(0, 1))(num, den)
    np.testing.assert_allclose(np.asarray(g_num), np.broadcast_to(1.0 / np.asarray(den), (2, 5)), rtol=1e-6)
    want_den = (-np.asarray(num) / np.asarray(den) ** 2).sum(axis=0 if den_shape else None)
    np.testing.assert_allclose(np.asarray(g_den), want_den, rtol=1e-5)
    assert not np.isfinite(np.asarray(divide_by_parameter(num.at[0, 0].set(jnp.inf), den)))[0, 0]


def _fused_instructions(params, n: int) -> int:
    """Instructions inside the fused kernels of the compiled simulation of ``n`` vehicles."""
    rows = np.array([[0, 0, 0], [0.2, 11.8, 11.8], [1.0, 11.8, 11.8]])
    prof = te.VoltageProfile.from_arrays(rows[:, 0], np.repeat(rows[:, 1:, None], n, axis=2))
    text = _simulate_jit.lower(params, prof, te.initial_state(params, (n,)), n_steps=2, dt=0.05, substeps=100,
                               t0=0.0, unroll=1).compile().as_text()
    blocks = re.split(r"\n(?=\S)", text)
    return sum(b.count("\n") for b in blocks if b.startswith("%fused_computation"))


def test_a_per_vehicle_drive_inertia_compiles_to_the_same_kernels_as_a_shared_one():
    # With J_eff / broadcast(J) rewritten to a multiplication, XLA copied the per-track chain into the
    # element-level fusions: 48 % more fused instructions at 16 vehicles and 2.6x the time per substep.
    n = 16
    shared = te.load_params("dry_sand")
    per_vehicle = eqx.tree_at(lambda p: p.vehicle.drive_inertia, shared,
                              shared.vehicle.drive_inertia * jnp.linspace(0.9, 1.1, n, dtype=jnp.float32))
    ratio = _fused_instructions(per_vehicle, n) / _fused_instructions(shared, n)
    assert ratio < 1.1, ratio


def _control_batch(terrain: str, n: int = 4):
    """The control's batch on ``terrain``: cohesion, friction angle and shear modulus scaled per vehicle, as
    :meth:`trackenv.diagnose.candidates.Candidate.apply` scales them, and voltages for a short drive. Unlike
    :func:`_batch` (cohesion only), the friction angle and shear modulus differ between vehicles, as in the
    control's fits: kept or not, they are arrays, and only asphalt's zero cohesion changes form. (A kept leaf
    whose values are equal and non-zero can round differently from its scalar form, by an ulp.)"""
    base = te.load_params(terrain)
    f = [1.0 + 0.05 * k for k in range(n)]
    trees = [te.replace(base, **{"terrain.cohesion": float(base.terrain.cohesion) * f[k],
                                 "terrain.friction_angle": float(base.terrain.friction_angle) * f[k],
                                 "terrain.shear_modulus": float(base.terrain.shear_modulus) * f[k]})
             for k in range(n)]
    rows = np.array([[0, 0, 0], [0.1, 12.0, 8.0], [0.5, 12.0, 8.0], [0.6, 0.0, 0.0]])
    return stack_trees(trees), te.VoltageProfile.from_arrays(rows[:, 0], np.repeat(rows[:, 1:, None], n, axis=2))


def test_the_diagnosis_keeps_its_scaled_leaves_arrays_so_terrains_share_a_program():
    """Asphalt's cohesion is zero whatever the control's factor: equal across the batch, it became a scalar,
    where sand's stayed an array, and each terrain compiled its own program. Kept as arrays, one program serves
    both, and asphalt's numbers are the scalar form's to the last bit."""
    from trackenv.diagnose.candidates import RECALIBRATE_LEAVES
    from trackenv.simulate import simulate_on_cores

    asphalt, prof = _control_batch("asphalt")
    sand, _ = _control_batch("dry_sand")
    assert float(asphalt.terrain.cohesion[0]) == 0.0
    assert shared_leaves_as_scalars(asphalt, (4,)).terrain.cohesion.shape == ()
    assert shared_leaves_as_scalars(asphalt, (4,), RECALIBRATE_LEAVES).terrain.cohesion.shape == (4,)
    assert shared_leaves_as_scalars(asphalt, (4,), RECALIBRATE_LEAVES).vehicle.mass.shape == ()  # not kept

    def run(params, keep):
        traj = simulate_on_cores(params, prof, 16, 0.05, 100, keep_arrays=keep)
        return {k: np.asarray(v) for k, v in traj.channels.items()}

    kept = run(asphalt, RECALIBRATE_LEAVES)
    before = _simulate_jit._cache_size()
    run(sand, RECALIBRATE_LEAVES)
    assert _simulate_jit._cache_size() == before  # sand reuses asphalt's program
    scalar = run(asphalt, frozenset())
    for ch in ("speed_ideal", "yaw_rate", "i_left", "i_right", "x", "heading"):
        np.testing.assert_array_equal(kept[ch], scalar[ch], err_msg=ch)


def test_the_control_scales_exactly_the_leaves_it_keeps_as_arrays():
    """``RECALIBRATE_LEAVES`` names what ``Candidate.apply`` scales for the control: every leaf that a factor
    other than 1 changes, and no other (a vehicle without internal resistance of its own included, whose
    stiction torque the control then scales)."""
    from trackenv.diagnose.candidates import RECALIBRATE_LEAVES, candidate_set

    control = {c.name: c for c in candidate_set()}["recalibrate_base"]
    constant = te.load_params("dry_sand", internal_resistance="constant")
    viscous = te.load_params("dry_sand", internal_resistance="viscous")
    without = te.replace(constant, **{"internal.constant": 0.0, "internal.viscous": 0.0})
    base = stack_trees([constant, viscous, without])
    factors = {"internal_resistance_factor": 1.3, "cohesion_factor": 0.7, "friction_angle_factor": 1.1,
               "shear_modulus_factor": 1.2}
    scaled = control.apply(base, {k: np.full(3, v) for k, v in factors.items()}, {})

    def leaves(tree):
        return {jax.tree_util.keystr(k, simple=True, separator="."): np.asarray(v)
                for k, v in jax.tree_util.tree_flatten_with_path(tree)[0]}

    before, after = leaves(base), leaves(scaled)
    changed = {k for k in before if not np.array_equal(before[k], after[k])}
    assert changed == RECALIBRATE_LEAVES
    assert {"terrain.cohesion", "vehicle.stiction_torque"} <= changed
