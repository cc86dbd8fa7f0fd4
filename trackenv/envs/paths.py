"""Reference paths as dense polylines, built and queried with pure ``jnp`` (jit/vmap-able).

A :class:`Path` is a polyline sampled along its arc length ``s`` (measured from the nominal start of
the maneuver, negative on the straight lead-in), with the heading and curvature of the reference
curve at every vertex. The polylines carry straight extensions before the start and after the end,
so that projecting a vehicle that has overshot the end still gives a meaningful along-track
position (``s`` larger than the path length) and a cross-track error to the extended line.

Conventions (docs/model.md §1): world X/Y, heading psi counter-clockwise from X; curvature kappa > 0
turns left; the cross-track error is positive when the vehicle is to the *left* of the path.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp


class Path(NamedTuple):
    """A polyline reference. All arrays (N,) or (N, 2); SI units."""

    xy: jax.Array  # m, vertices (N, 2)
    heading: jax.Array  # rad, reference heading at each vertex
    curvature: jax.Array  # 1/m, reference curvature at each vertex
    s: jax.Array  # m, arc length from the nominal start (negative on the lead-in)


class Projection(NamedTuple):
    s: jax.Array  # m, along-track position of the closest point
    cross_track: jax.Array  # m, signed distance, > 0 left of the path
    heading: jax.Array  # rad, path heading at the closest point
    curvature: jax.Array  # 1/m, path curvature at the closest point


def wrap_angle(a):
    """Wrap an angle to [-pi, pi)."""
    return (a + jnp.pi) % (2.0 * jnp.pi) - jnp.pi


def from_curvature(lengths, curvatures, ds: float, n: int, s_start: float) -> Path:
    """Path of piecewise-constant curvature starting at the origin along +X.

    ``lengths``/``curvatures`` (K,): consecutive segments beginning at s = 0 (straight beyond them).
    The polyline has ``n`` vertices at s = s_start + k ds (s_start < 0 gives a straight lead-in).
    Positions integrate the exact heading psi(s) = sum_j kappa_j clip(s - S_j, 0, L_j) with the
    midpoint rule (chord error kappa^2 ds^2 / 24, below 1e-4 for kappa <= 2/m, ds = 0.025 m).
    """
    lengths = jnp.asarray(lengths)
    curvatures = jnp.asarray(curvatures)
    dtype = lengths.dtype
    starts = jnp.concatenate([jnp.zeros((1,), dtype), jnp.cumsum(lengths)[:-1]])
    s = s_start + jnp.arange(n, dtype=dtype) * ds

    def psi(sv):
        return (curvatures * jnp.clip(sv[:, None] - starts, 0.0, lengths)).sum(axis=-1)

    def kappa(sv):
        inside = (sv[:, None] >= starts) & (sv[:, None] < starts + lengths)
        return (curvatures * inside).sum(axis=-1)

    heading = psi(s)
    mid = psi(s[:-1] + 0.5 * ds)
    steps = ds * jnp.stack([jnp.cos(mid), jnp.sin(mid)], axis=-1)
    xy0 = jnp.stack([jnp.asarray(s_start, dtype), jnp.asarray(0.0, dtype)])[None]
    xy = jnp.concatenate([xy0, xy0 + jnp.cumsum(steps, axis=0)], axis=0)
    return Path(xy, heading, kappa(s), s)


def from_lateral_profile(x, y, dy, d2y) -> Path:
    """Path y(x) given on an increasing grid ``x`` (N,) with its first and second derivatives."""
    xy = jnp.stack([x, y], axis=-1)
    seg = jnp.sqrt(jnp.diff(x) ** 2 + jnp.diff(y) ** 2)
    s = jnp.concatenate([jnp.zeros((1,), x.dtype), jnp.cumsum(seg)])
    # s = 0 where x = 0 (the nominal start)
    s0 = jnp.interp(jnp.asarray(0.0, x.dtype), x, s)
    heading = jnp.arctan(dy)
    curvature = d2y / (1.0 + dy * dy) ** 1.5
    return Path(xy, heading, curvature, s - s0)


def project(path: Path, p) -> Projection:
    """Closest point of the polyline to ``p`` (2,), with the signed cross-track error (> 0: left)."""
    a = path.xy[:-1]
    seg = path.xy[1:] - a
    seg_len2 = jnp.maximum((seg * seg).sum(-1), 1e-12)
    d = p[None] - a
    t = jnp.clip((d * seg).sum(-1) / seg_len2, 0.0, 1.0)
    closest = a + t[:, None] * seg
    dist2 = ((p[None] - closest) ** 2).sum(-1)
    k = jnp.argmin(dist2)
    tk = t[k]
    segk = seg[k]
    cross = (segk[0] * d[k, 1] - segk[1] * d[k, 0]) / jnp.sqrt(seg_len2[k])
    s = path.s[k] + tk * (path.s[k + 1] - path.s[k])
    dh = wrap_angle(path.heading[k + 1] - path.heading[k])
    heading = path.heading[k] + tk * dh
    curvature = path.curvature[k] + tk * (path.curvature[k + 1] - path.curvature[k])
    return Projection(s, cross, heading, curvature)


def curvature_at(path: Path, s):
    """Reference curvature at arc length ``s`` (linear between vertices, held beyond the ends)."""
    return jnp.interp(s, path.s, path.curvature)
