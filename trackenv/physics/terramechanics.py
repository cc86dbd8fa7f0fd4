"""Terramechanics laws: shear stress vs shear displacement, pressure-sinkage, compaction resistance.

Pure, elementwise functions of arrays (any shape broadcasts). SI units: stresses in Pa,
displacements and sinkage in m, forces in N.

Shape annotations: the arguments broadcast against each other (``*#s``) and the result has the
broadcast shape ``*s``; terrain and vehicle parameter leaves are scalars or ``(*b)`` arrays.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..params import Terrain

_In = Float[ArrayLike, " *#s"]  # an elementwise argument: broadcasts against the others
_Out = Float[Array, " *s"]  # the broadcast result

EXP_LOG_POWER_MIN = 64  # vehicles in the whole batch: from here exp(a log x) is faster than pow (measured)


def positive_power(x: _In, a: _In, nb: int = 0) -> _Out:
    """max(x, 0)^a for a > 0 [units of x^a], in the faster form for the batch (``nb`` trailing vehicle axes).

    XLA's CPU ``pow`` is not vectorised: on a (2, 14, 256) array it takes about 4.5 ns per element against
    1.3 ns for exp(a log x) (``benchmarks/bench_simulate.py --ops``). From
    :data:`EXP_LOG_POWER_MIN` vehicles in the whole batch, split over the cores or not, exp(a log x) makes the
    batched simulation faster; for one vehicle and small batches ``pow`` does (docs/performance.md: split, 32
    vehicles per core ran 1.15-1.2x faster with exp(a log x), 8 per core 1.15-1.2x slower). The relative error of exp(a log x)
    is about |a log x| units in the last place, ~10⁻⁶ in float32 for the pressures here. The ``where`` on
    both sides keeps the value and the gradient at x = 0 finite (0 and 0).
    """
    if (math.prod(jnp.shape(x)[jnp.ndim(x) - nb:]) if nb else 1) < EXP_LOG_POWER_MIN:
        return jnp.maximum(x, 0.0) ** a
    positive = x > 0.0
    safe = jnp.where(positive, x, 1.0)
    return jnp.where(positive, jnp.exp(a * jnp.log(safe)), 0.0)


def step5(x: _In, x0: _In, h0: _In, x1: _In, h1: _In) -> _Out:
    """ADAMS's quintic STEP5 (3.16): h0 for x <= x0, h1 for x >= x1, C2-smooth in between."""
    s = jnp.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    return h0 + (h1 - h0) * s**3 * (10.0 - 15.0 * s + 6.0 * s * s)


def step5_slope(x: _In, x0: _In, h0: _In, x1: _In, h1: _In) -> _Out:
    """d/dx of :func:`step5` for constant h0, h1: (h1 - h0)/(x1 - x0) 30 s^2 (1 - s)^2, zero outside (x0, x1)."""
    s = jnp.clip((x - x0) / (x1 - x0), 0.0, 1.0)
    return (h1 - h0) / (x1 - x0) * 30.0 * (s * (1.0 - s)) ** 2


def smoothsign(x: _In, a: _In) -> _Out:
    """Smooth sign function STEP5(x, -a, -1, a, 1) (docs/model.md §3)."""
    return step5(x, -a, -1.0, a, 1.0)


def shear_strength(normal_pressure: _In, cohesion: _In, friction_angle: _In) -> _Out:
    """Mohr-Coulomb maximum shear stress c + sigma tan(phi) (2.1) [Pa]."""
    return cohesion + normal_pressure * jnp.tan(friction_angle)


def janosi_shear_stress(
    shear_displacement: _In, normal_pressure: _In, cohesion: _In, friction_angle: _In, shear_modulus: _In
) -> _Out:
    """Janosi-Hanamoto shear stress (2.8)/(3.19): (c + sigma tan phi)(1 - exp(-|j|/K)) [Pa]."""
    tau_max = shear_strength(normal_pressure, cohesion, friction_angle)
    return tau_max * (1.0 - jnp.exp(-jnp.abs(shear_displacement) / shear_modulus))


def wong_hump_shear_stress(
    shear_displacement: _In, normal_pressure: _In, cohesion: _In, friction_angle: _In, k_omega: _In, k_r: _In
) -> _Out:
    """Wong's humped shear law (2.11) for compact sand, silt, loam [Pa].

    tau = tau_max K_r {1 + [1/(K_r (1 - 1/e)) - 1] exp(1 - j/K_w)} [1 - exp(-j/K_w)].
    """
    j = jnp.abs(shear_displacement) / k_omega
    tau_max = shear_strength(normal_pressure, cohesion, friction_angle)
    bump = 1.0 + (1.0 / (k_r * (1.0 - jnp.exp(-1.0))) - 1.0) * jnp.exp(1.0 - j)
    return tau_max * k_r * bump * (1.0 - jnp.exp(-j))


def wong_peak_shear_stress(
    shear_displacement: _In, normal_pressure: _In, cohesion: _In, friction_angle: _In, k_omega: _In
) -> _Out:
    """Wong's peaked shear law (2.12) for organic terrain: tau_max (j/K_w) exp(1 - j/K_w) [Pa]."""
    j = jnp.abs(shear_displacement) / k_omega
    return shear_strength(normal_pressure, cohesion, friction_angle) * j * jnp.exp(1.0 - j)


def shear_stress(shear_displacement: _In, normal_pressure: _In, terrain: Terrain) -> _Out:
    """Shear stress magnitude [Pa] from the terrain's shear law (``terrain.shear_law``, static)."""
    c, phi, k = terrain.cohesion, terrain.friction_angle, terrain.shear_modulus
    if terrain.shear_law == "janosi":
        return janosi_shear_stress(shear_displacement, normal_pressure, c, phi, k)
    if terrain.shear_law == "wong_hump":
        return wong_hump_shear_stress(shear_displacement, normal_pressure, c, phi, k, terrain.residual_ratio)
    if terrain.shear_law == "wong_peak":
        return wong_peak_shear_stress(shear_displacement, normal_pressure, c, phi, k)
    raise ValueError(f"unknown shear law {terrain.shear_law!r}")


def shear_stress_slope(shear_displacement: _In, normal_pressure: _In, terrain: Terrain) -> _Out:
    """d tau / d|j| [Pa/m] of :func:`shear_stress` (closed forms of 2.8/3.19, 2.11, 2.12)."""
    c, phi, k = terrain.cohesion, terrain.friction_angle, terrain.shear_modulus
    tau_max = shear_strength(normal_pressure, c, phi)
    x = jnp.abs(shear_displacement) / k
    if terrain.shear_law == "janosi":
        return tau_max * jnp.exp(-x) / k
    if terrain.shear_law == "wong_hump":
        k_r = terrain.residual_ratio
        a = 1.0 / (k_r * (1.0 - jnp.exp(-1.0))) - 1.0
        e1 = jnp.exp(1.0 - x)
        return tau_max * k_r * (-a * e1 * (1.0 - jnp.exp(-x)) + (1.0 + a * e1) * jnp.exp(-x)) / k
    if terrain.shear_law == "wong_peak":
        return tau_max * jnp.exp(1.0 - x) * (1.0 - x) / k
    raise ValueError(f"unknown shear law {terrain.shear_law!r}")


def bekker_modulus(k_c: _In, k_phi: _In, width: _In) -> _Out:
    """Bekker's combined modulus k = k_c/b + k_phi (2.4) [N/m^(n+2)]."""
    return k_c / width + k_phi


def bekker_sinkage(normal_pressure: _In, k: _In, n: _In) -> _Out:
    """Sinkage z = (p/k)^(1/n) from Bekker's p = k z^n (2.4) [m]."""
    return positive_power(normal_pressure / k, 1.0 / n)


def compaction_resistance(normal_force: _In, area: _In, contact_length: _In, k: _In, n: _In, nb: int = 0) -> _Out:
    """Bekker compaction resistance of one track (or one patch of length L), discretised (3.40) [N].

    R_c = sum_i A_i / ((n+1) L k^(1/n)) (F_n,i / A_i)^((n+1)/n). Elementwise: returns the per-element
    contributions, and callers sum over the element axis. ``nb``: the trailing vehicle axes of
    ``normal_force``, which choose the form of the power (:func:`positive_power`).
    """
    pressure = normal_force / area
    return area / ((n + 1.0) * contact_length * k ** (1.0 / n)) * positive_power(pressure, (n + 1.0) / n, nb)
