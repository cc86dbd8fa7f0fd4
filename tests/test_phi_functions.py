"""ETDRK4's coefficients (phi-functions of z = -h lambda) against an 80-digit reference.

The integrator evaluates phi_1..phi_3 by a series for |z| < 1 and by their closed forms with e^z - 1
beyond (no ``expm1``), and (1/2) phi_1(z/2) from phi_1(z); these tests pin both branches and the switch
between them, over the whole range of decay rates a substep meets (0 to 1e6 per step).
"""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from trackenv import integrate

getcontext().prec = 80
getcontext().Emin = -999_999_999


def _phi(k: int, z: Decimal) -> Decimal:
    if z == 0:
        return 1 / Decimal(math.factorial(k))
    head = sum((z**j / math.factorial(j) for j in range(k)), Decimal(0))
    return (z.exp() - head) / z**k


def reference(z: float) -> np.ndarray:
    """E, E2, Q, f1, f2, f3 of :class:`trackenv.integrate.Coeffs` at h = 1, from exact decimal arithmetic."""
    zd = Decimal(z)
    p1, p2, p3 = _phi(1, zd), _phi(2, zd), _phi(3, zd)
    vals = [zd.exp(), (zd / 2).exp(), _phi(1, zd / 2) / 2, p1 - 3 * p2 + 4 * p3, p2 - 2 * p3, 4 * p3 - p2]
    return np.array([float(v) for v in vals])


Z = -np.concatenate([[0.0], np.logspace(-8, 6, 141), np.linspace(0.9, 1.1, 21), np.linspace(1.9, 2.1, 21)])


@pytest.mark.parametrize(("dtype", "tol"), [(np.float64, 2e-14), (np.float32, 5e-6)])
def test_etd_coefficients_match_the_exact_phi_functions(dtype, tol):
    """Each coefficient within ``tol`` of the reference at the rounded z: the exponentials relative to
    themselves, the step weights relative to their largest value (h = 1)."""
    with jax.enable_x64(dtype == np.float64):
        rate = jnp.asarray(-Z, dtype)
        got = np.array([np.asarray(c, np.float64) for c in integrate.etd_coeffs(rate, dtype(1.0))]).T
    z = -np.asarray(rate, np.float64)
    ref = np.array([reference(x) for x in z])
    for i, name in enumerate(integrate.Coeffs._fields):
        # below the smallest normal number XLA flushes to zero
        scale = np.maximum(np.abs(ref[:, i]), np.finfo(dtype).tiny) if i < 2 else np.max(np.abs(ref[:, i]))
        err = np.abs(got[:, i] - ref[:, i]) / scale
        worst = int(np.argmax(err))
        assert err[worst] < tol, f"{name} at z = {z[worst]:.3g}: error {err[worst]:.2e} >= {tol:.0e}"


def test_rk4_is_the_zero_rate_limit():
    """At lambda = 0 the ETDRK4 weights are classical RK4's (h/2, h/6, h/6, h/6): the series branch at z = 0."""
    c = integrate.etd_coeffs(jnp.zeros(3, jnp.float32), 0.002)
    rk = integrate.rk4_coeffs(0.002)
    for name, a, b in zip(integrate.Coeffs._fields, c, rk):
        np.testing.assert_allclose(np.asarray(a), b, rtol=1e-6, err_msg=name)
