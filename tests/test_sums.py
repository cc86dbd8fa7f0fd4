"""The two forms of the contact-point sums (trackenv.physics.sums) compute the same sums.

``contact_sum`` picks XLA's ``reduce`` or unrolled slice additions by batch size, for speed only; here
both forms are checked against a float64 numpy sum, for every axis combination the model uses and
for batch sizes on both sides of the policy's bounds, and a simulation of a batch in the unrolled
range against the same vehicles simulated one at a time.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import trackenv as te
from trackenv.physics import sums


@pytest.mark.parametrize("batch", [(), (1,), (8,), (sums.UNROLL_MIN,), (64,), (sums.UNROLL_MAX,), (4, 5)])
@pytest.mark.parametrize("axes", [0, 1, (0, 1)])
def test_both_forms_equal_the_sum(batch, axes, monkeypatch):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(2, 14) + batch).astype(np.float32)
    want = a.astype(np.float64).sum(axis=axes)
    for lo, hi in ((10**9, 10**9), (1, 10**9)):  # reduce always, unrolled always
        monkeypatch.setattr(sums, "UNROLL_MIN", lo)
        monkeypatch.setattr(sums, "UNROLL_MAX", hi)
        got = np.asarray(jax.jit(lambda x: sums.contact_sum(x, axes, len(batch)))(jnp.asarray(a)))
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


def test_policy_bounds():
    assert not sums.unrolled(1) and not sums.unrolled(sums.UNROLL_MIN - 1)
    assert sums.unrolled(sums.UNROLL_MIN) and sums.unrolled(sums.UNROLL_MAX - 1)
    assert not sums.unrolled(sums.UNROLL_MAX) and not sums.unrolled(4096)


def test_unrolled_batch_matches_single_vehicles():
    """A batch in the unrolled range agrees with its vehicles simulated one by one (reduce form) to rounding."""
    batch = sums.UNROLL_MIN
    assert sums.unrolled(batch)
    params = te.load_params("asphalt")
    rows = np.array([[0, 0, 0], [0.3, 11.8, 11.8], [0.8, 11.8, 11.8], [1.0, 16.0, 6.0], [1.5, 16.0, 6.0]])
    scale = np.linspace(0.8, 1.2, batch)
    volts = rows[:, 1:, None] * scale[None, None, :]
    traj = te.simulate(params, te.VoltageProfile.from_arrays(rows[:, 0], volts), 1.5)
    for k in (0, batch - 1):
        one = te.simulate(params, te.VoltageProfile.from_arrays(rows[:, 0], volts[..., k]), 1.5)
        for ch in ("speed_ideal", "yaw_rate", "i_left", "i_right"):
            a, b = np.asarray(traj.channels[ch][:, k]), np.asarray(one.channels[ch])
            assert np.max(np.abs(a - b)) <= 1e-3 * max(np.max(np.abs(b)), 1e-3), (k, ch)


def test_partitioned_trace_chooses_the_form_for_one_devices_share():
    """Traced inside ``Partitioned(n)`` (a program XLA splits over n devices), the form is the one for each
    device's batch / n vehicles: 256 vehicles sum with XLA's reduce, two shares of 128 unrolled."""
    a = jnp.zeros((2, 14, 2 * (sums.UNROLL_MAX - 32)), jnp.float32)  # 256 vehicles: each half in the unrolled range

    def primitives():
        jaxpr = jax.make_jaxpr(lambda x: sums.contact_sum(x, 1, 1))(a)
        return {e.primitive.name for e in jaxpr.jaxpr.eqns}

    assert "reduce_sum" in primitives()
    with sums.Partitioned(2):
        assert "reduce_sum" not in primitives()
        with sums.Partitioned(1):  # nested: the inner one holds
            assert "reduce_sum" in primitives()
    assert "reduce_sum" in primitives()  # restored on leaving
