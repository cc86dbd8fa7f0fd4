"""The substep mean of the lateral shear decay rate against adaptive quadrature.

ETDRK4 takes j_x's decay rate |V_t|/max(z-tilde*, Delta Z) (3.32) as |V_t| times the mean of
1/max(z-tilde*, Delta Z) over the substep (``trackenv.physics.contact.mean_inverse_z_tilde``), with v and r
linear in time. Reference: ``scipy.integrate.quad_vec`` of the instantaneous 1/max(z-tilde*, Delta Z) that
``contact.kinematics`` computes from (3.29)-(3.31) along the same linear path, told where each element's
lateral velocity and each leading edge's change sign (float64). The draws are larger than a 0.5 ms substep's
changes at a steering reversal, so that z-bar sweeps past elements, leaves the track and r changes sign
within a substep.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad_vec

import trackenv as te
from trackenv.physics import contact
from trackenv.physics.geometry import patch_edges

U, OMEGA = 0.8, (9.0, 9.0)  # m/s, rad/s: driving forward, both leading edges at the front


def _case(vehicle_id, v0, v1, r0, r1):
    with jax.enable_x64(True):
        params = te.load_params("asphalt", vehicle=vehicle_id, dtype=jnp.float64)
        veh, ter = params.vehicle, params.terrain
        omega = jnp.asarray(OMEGA, jnp.float64)

        def kin(v, r):
            return contact.kinematics(veh, ter, jnp.stack([jnp.float64(U), v, r]), omega, 0)

        inverse = jax.jit(lambda s: 1.0 / jnp.maximum(kin(v0 + (v1 - v0) * s, r0 + (r1 - r0) * s).z_tilde,
                                                      contact.MIN_Z_STAR))
        start = kin(jnp.float64(v0), jnp.float64(r0))
        mean = np.asarray(contact.mean_inverse_z_tilde(veh, start, jnp.array([U, v1, r1]), jnp.array([U, v0, r0]), 0))
        x = np.asarray(start.x).ravel()
        ahead = np.atleast_1d(np.asarray(patch_edges(veh, 0)[0], np.float64)).ravel()
        positions = np.concatenate([x, ahead])  # every element and every patch's front (leading) edge
        dv = (v1 - v0) + (r1 - r0) * positions
        with np.errstate(divide="ignore", invalid="ignore"):
            cuts = -(v0 + r0 * positions) / dv
        points = sorted({float(s) for s in cuts[np.isfinite(cuts)] if 0.0 < s < 1.0})
        ref, _ = quad_vec(lambda s: np.asarray(inverse(s)), 0.0, 1.0, points=points or None, epsabs=1e-9,
                          epsrel=1e-10, limit=2000)
        frozen = np.asarray(1.0 / jnp.maximum(start.z_tilde, contact.MIN_Z_STAR))  # the rate at the substep's start
    return mean, ref, frozen, points


def _draws(n, seed):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        v0, r0 = rng.normal(0.0, 0.05), rng.normal(0.0, 0.5)
        yield v0, v0 + rng.normal(0.0, 0.01), r0, r0 + rng.normal(0.0, 0.1)


@pytest.mark.parametrize("vehicle_id", ["packbot", "husky"])
def test_mean_inverse_z_tilde_matches_adaptive_quadrature(vehicle_id):
    worst, swept = 0.0, 0
    for v0, v1, r0, r1 in _draws(12, seed=3):
        mean, ref, frozen, points = _case(vehicle_id, v0, v1, r0, r1)
        worst = max(worst, float(np.max(np.abs(mean - ref) / ref)))
        swept += bool(points) and float(np.max(np.abs(frozen - ref) / ref)) > 0.5
    assert worst < 0.02, f"{vehicle_id}: largest relative error of the substep mean {worst:.3g}"
    # the draws exercise what the mean is for: substeps in which z-bar passes elements, where the rate at
    # the substep's start is off by more than half
    assert swept >= 3, f"{vehicle_id}: only {swept} of 12 draws sweep z-bar past an element"


def test_mean_of_a_steady_turn_is_the_instantaneous_rate():
    """With v and r constant (a steady turn), z-tilde* does not move and the mean is the instantaneous value."""
    mean, ref, frozen, points = _case("packbot", 0.02, 0.02, 0.4, 0.4)
    assert not points
    np.testing.assert_allclose(mean, frozen, rtol=1e-12)
    np.testing.assert_allclose(ref, frozen, rtol=1e-9)
