"""``sensor_artifacts``: what the field instruments add to the truth (docs/model.md §7, §8; thesis §4.3.2, §5.3.3).

Instrument hook only (the dynamics are untouched):

- **encoder averaging** (thesis p. 5019: "the encoder averages pulses over a period of time"): the
  ideal speed is the causal moving average over a window W [s],
  ``speed_ideal_m(t) = (1/W) ∫_{t-W}^{t} speed_ideal(τ) dτ``, with the samples interpreted as piecewise
  linear (integrated exactly) and the signal held at its first value before the log starts;
  W = 0 leaves it unchanged;
- **ammeter offset, ripple and rectification** (§5.3: the ammeter reports |i|; a Hall-effect sensor's
  zero offset c [A] differs per channel): ``i_m = |i + c + A sin(2π f t)|`` (A [A], f [Hz]) when
  ``rectify`` (static) is True, else ``i + c + A sin(2π f t)``;
- **gyro bias and scale factor** (IEEE Std 952-1997): ``yaw_rate_m = (1 + ε) yaw_rate + β`` [rad/s].

Defaults: W = 0.1 s (a typical encoder-velocity window at the logs' 10-20 Hz rate; the thesis does
not give it), no offsets (c = 0), no ripple (A = 0, f = 50 Hz), β = 0, ε = 0, rectify = True (the field
ammeter).
Channels are (T, *b) with times t (T,).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import Effect


def _cumulative_integral(t, s):
    """F_k = ∫_{t_0}^{t_k} s dτ (trapezoid = exact for piecewise-linear s), shape of s."""
    dt = (t[1:] - t[:-1]).reshape((-1,) + (1,) * (s.ndim - 1))
    seg = 0.5 * (s[1:] + s[:-1]) * dt
    return jnp.concatenate([jnp.zeros_like(s[:1]), jnp.cumsum(seg, axis=0)], axis=0)


def _integral_at(tau, t, s, F):
    """∫_{t_0}^{tau} s for each tau (T,), s piecewise linear on t, held at s_0 before t_0 and at s_-1 after."""
    ex = (-1,) + (1,) * (s.ndim - 1)
    k = jnp.clip(jnp.searchsorted(t, tau, side="right") - 1, 0, t.shape[0] - 2)
    t0, t1 = t[k], t[k + 1]
    d = jnp.clip(tau - t0, 0.0, t1 - t0)
    h = t1 - t0
    sk, sk1 = s[k], s[k + 1]
    inside = F[k] + sk * d.reshape(ex) + 0.5 * (sk1 - sk) * (d * d / h).reshape(ex)
    before = s[0] * (tau - t[0]).reshape(ex)
    after = F[-1] + s[-1] * jnp.maximum(tau - t[-1], 0.0).reshape(ex)
    out = jnp.where((tau < t[0]).reshape(ex), before, inside)
    return jnp.where((tau > t[-1]).reshape(ex), after, out)


def moving_average(t, s, window):
    """Causal moving average of ``s`` (T, *b) over ``window`` [s] (exact for piecewise-linear s).

    ``window`` is a scalar or has the trailing batch shape of ``s`` (one window per vehicle).
    """
    if t.shape[0] < 2:
        return s
    window = jnp.asarray(window)
    if window.ndim > 0:  # one window per vehicle on the last axis
        return jax.vmap(lambda s_, w_: moving_average(t, s_, w_), in_axes=(-1, -1), out_axes=-1)(s, window)
    F = _cumulative_integral(t, s)
    w = jnp.maximum(window, 1e-9)
    avg = (F - _integral_at(t - w, t, s, F)) / w
    return jnp.where(window > 1e-9, avg, s)


class SensorArtifacts(Effect):
    """Encoder averaging window, ammeter offsets, ripple + rectification, gyro bias and scale (instrument transforms)."""

    id: ClassVar[str] = "sensor_artifacts"
    bounds: ClassVar[dict] = {
        "window": (0.0, 2.0),
        "ripple_amplitude": (0.0, 5.0),
        "ripple_frequency": (0.0, 1000.0),
        "gyro_bias": (-0.5, 0.5),
        "gyro_scale": (-0.5, 0.5),
        "current_offset_left": (-5.0, 5.0),
        "current_offset_right": (-5.0, 5.0),
    }

    window: jax.Array  # s, encoder averaging window
    ripple_amplitude: jax.Array  # A
    ripple_frequency: jax.Array  # Hz
    gyro_bias: jax.Array  # rad/s
    gyro_scale: jax.Array  # -, scale-factor error ε
    current_offset_left: jax.Array  # A, zero offset of the left ammeter
    current_offset_right: jax.Array  # A
    rectify: bool = eqx.field(static=True, default=True)

    @classmethod
    def default(cls, dtype=jnp.float32):
        f = lambda v: jnp.asarray(v, dtype)  # noqa: E731
        return cls(window=f(0.1), ripple_amplitude=f(0.0), ripple_frequency=f(50.0), gyro_bias=f(0.0),
                   gyro_scale=f(0.0), current_offset_left=f(0.0), current_offset_right=f(0.0))

    def instruments(self, channels, t, params):
        out = dict(channels)
        t = jnp.asarray(t)
        if "speed_ideal" in out:
            out["speed_ideal"] = moving_average(t, out["speed_ideal"], self.window)
        for key, offset in (("i_left", self.current_offset_left), ("i_right", self.current_offset_right)):
            if key in out:
                i = out[key]
                tt = t.reshape(t.shape + (1,) * (i.ndim - 1))
                i = i + offset + self.ripple_amplitude * jnp.sin(2.0 * jnp.pi * self.ripple_frequency * tt)
                out[key] = jnp.abs(i) if self.rectify else i
        if "yaw_rate" in out:
            out["yaw_rate"] = (1.0 + self.gyro_scale) * out["yaw_rate"] + self.gyro_bias
        return out
