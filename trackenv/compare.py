"""Comparison of simulated channels with a field log (docs/model.md §9): what replay and the diagnosis share.

:func:`trackenv.replay.replay` compares one simulation with one log; the diagnosis
(:mod:`trackenv.diagnose`) compares batches of simulations with many logs. Both compare the same way,
and this module is where that way is written down:

- **Sample times.** The simulated channels live on a uniform output grid ``t_k = k · dt`` (time since
  the log's first sample); they are evaluated at the log's sample times by linear interpolation on
  that grid. :func:`grid_weights` gives the interpolation indices and weights once per log,
  :func:`at_samples` applies them (numpy or jax arrays, vehicles on trailing axes; traceable).
  :func:`interp_at` is the same interpolation through ``numpy.interp`` (any increasing grid); replay
  uses it, the diagnosis uses the index/weight form. The two agree to rounding (last bits), which is
  why each caller keeps its own form: their numbers do not change.
- **Rectification.** A log whose ``meta.json`` says ``current_sensor: "absolute"`` reports |i|; the
  simulated currents are compared (and written) as |i| (:func:`rectify`, :func:`rectify_channels`).
- **Pose frame.** The simulation starts at the origin with heading 0; its pose is moved into the
  log's frame by the log's first pose sample ``(x0, y0, heading0)`` (missing values count as 0,
  :meth:`trackenv.fieldlog.FieldLog.first_pose`): :func:`pose_to_log_frame`, inverse
  :func:`pose_from_log_frame`.
- **Errors.** ``sim − meas`` per channel; heading errors wrapped into (−π, π] (:func:`wrap_angle`,
  :func:`channel_error`); a measured heading is unwrapped over its present samples before its range
  is taken (:func:`unwrap_measured`).
- **Drive input.** A log drives the model by its voltages (voltage mode) or by its measured sprocket or
  track speeds (speed mode, :attr:`trackenv.fieldlog.FieldLog.input_mode`). :func:`log_drive` gives
  the drive as ``(kind, values)``, track speeds converted to sprocket speeds ω = V_t / r_s' with the
  belt radius of the simulated vehicle on the simulated terrain; :func:`drive_profile` turns that into
  the :class:`~trackenv.simulate.VoltageProfile` or :class:`~trackenv.simulate.SpeedProfile` that
  :func:`trackenv.simulate.simulate` takes. In speed mode the encoder channel ``speed_ideal`` is the
  input itself and is not compared (:data:`INPUT_CHANNELS`).
- **Records.** :func:`json_clean` makes a nested result JSON-safe (NaN/inf -> ``None``, numpy scalars
  -> Python); :func:`stack_trees` stacks parameter pytrees along a new last (vehicle) axis, the batch
  layout of :func:`trackenv.simulate.simulate_batch` (docs/model.md §6).

Every array function takes numpy arrays (and returns numpy) or jax arrays, traced ones included
(and returns jax), with the same arithmetic either way.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "CURRENTS", "POSE", "SampleWeights", "grid_weights", "at_samples", "interp_at", "rectify",
    "rectify_channels", "pose_to_log_frame", "pose_from_log_frame", "wrap_angle", "channel_error",
    "unwrap_measured", "json_clean", "stack_trees", "log_drive", "drive_profile", "INPUT_CHANNELS",
]

CURRENTS = ("i_left", "i_right")  # the channels an absolute ammeter rectifies
POSE = ("x", "y", "heading")  # the channels moved into the log's frame
INPUT_CHANNELS = {"voltage": (), "speed": ("speed_ideal",)}  # channels that are the drive input, per mode


def _is_jax(x) -> bool:
    return isinstance(x, jax.Array)


class SampleWeights(NamedTuple):
    """Linear interpolation on a uniform grid at K sample times: ``value = x[i0] (1 − w) + x[i0 + 1] w``.

    i0: (K,) int indices into the grid (``0 … n_steps − 1``); w: (K, 1) float64 weights (the trailing
    axis broadcasts over one vehicle axis; :func:`at_samples` reshapes it for more).
    """

    i0: np.ndarray
    w: np.ndarray


def grid_weights(times, dt: float, n_steps: int) -> SampleWeights:
    """Interpolation indices and weights of ``times`` (K,) [s] on the grid ``k · dt``, ``k = 0 … n_steps``.

    Times beyond the grid's last interval extrapolate linearly from it (the callers' grids cover the log).
    """
    x = np.asarray(times) / dt
    i0 = np.clip(np.floor(x).astype(int), 0, n_steps - 1)
    return SampleWeights(i0, (x - i0)[:, None])


def at_samples(x, weights: SampleWeights):
    """Channel ``x`` (T, *b) on the grid at the sample times of ``weights`` -> (K, *b) (numpy or jax)."""
    i0, w = weights
    if w.ndim != x.ndim:
        w = w.reshape(w.shape[:1] + (1,) * (x.ndim - 1))
    if isinstance(x, np.ndarray) and x.dtype == np.float32:  # each factor rounded to float32 as jax rounds it
        return x[i0] * (1.0 - w).astype(np.float32) + x[i0 + 1] * w.astype(np.float32)
    return x[i0] * (1.0 - w) + x[i0 + 1] * w


def interp_at(times, grid, x) -> np.ndarray:
    """Channel ``x`` (T,) on the increasing ``grid`` (T,) at ``times`` (K,), by ``numpy.interp`` (float64)."""
    return np.interp(times, grid, np.asarray(x, np.float64))


def rectify(signal: str, x, sensor: str):
    """``x`` as the log's ammeter reports channel ``signal``: |x| for a current of an ``"absolute"`` sensor."""
    return abs(x) if (sensor == "absolute" and signal in CURRENTS) else x


def rectify_channels(channels: dict, sensor: str) -> dict:
    """:func:`rectify` of every channel of ``channels`` (a new dict; the others unchanged)."""
    return {k: rectify(k, v, sensor) for k, v in channels.items()}


def pose_to_log_frame(xs, ys, hs, pose0):
    """Simulated pose (origin, heading 0 at the log's first sample) into the log's frame.

    ``pose0`` = the log's first pose ``(x0, y0, heading0)``: returns ``(x0 + c·xs − s·ys,
    y0 + s·xs + c·ys, heading0 + hs)`` with ``c, s = cos, sin(heading0)``.
    """
    x0, y0, h0 = pose0
    c, s = math.cos(h0), math.sin(h0)
    return x0 + c * xs - s * ys, y0 + s * xs + c * ys, h0 + hs


def pose_from_log_frame(x, y, heading, pose0):
    """Inverse of :func:`pose_to_log_frame`: a pose in the log's frame into the simulation's."""
    x0, y0, h0 = pose0
    c, s = math.cos(h0), math.sin(h0)
    dx, dy = x - x0, y - y0
    return c * dx + s * dy, -s * dx + c * dy, heading - h0


def wrap_angle(a):
    """Angle(s) ``a`` [rad] wrapped into (−π, π] (numpy or jax, traceable)."""
    w = (a + math.pi) % (2 * math.pi) - math.pi
    if _is_jax(w):
        return jnp.where(w == -math.pi, math.pi, w)
    return np.where(w == -math.pi, math.pi, w)


def channel_error(signal: str, sim, meas):
    """``sim − meas`` of channel ``signal``; heading errors wrapped into (−π, π].

    ``sim`` (K, *b) or (K,); ``meas`` (K,) broadcasts over the trailing axes of ``sim``.
    """
    meas = meas.reshape(meas.shape + (1,) * (np.ndim(sim) - np.ndim(meas)))
    e = sim - meas
    return wrap_angle(e) if signal == "heading" else e


def unwrap_measured(x: np.ndarray) -> np.ndarray:
    """A measured angle (K,) unwrapped over its present (finite) samples; missing ones stay NaN (a copy)."""
    x = np.array(x, np.float64, copy=True)
    present = np.isfinite(x)
    x[present] = np.unwrap(x[present])
    return x


def json_clean(x):
    """``x`` made JSON-safe: dicts (keys as ``str``), lists/tuples and numpy arrays as lists, NaN/inf as
    ``None``, numpy floats/ints/bools as Python ``float``/``int``/``bool``; anything else as is."""
    if isinstance(x, dict):
        return {str(k): json_clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def stack_trees(trees, dtype=None):
    """Stack pytrees of one structure along a new last axis (the vehicle axis of a batch, docs/model.md §6).

    Floating leaves (arrays or Python floats) are stacked, cast to ``dtype`` first if given; other leaves
    (ints, bools, strings, static parts) are taken from the first tree.
    """
    cast = (lambda x: x) if dtype is None else (lambda x: jnp.asarray(x, dtype))  # noqa: E731
    return jax.tree.map(lambda *xs: jnp.stack([cast(x) for x in xs], axis=-1)
                        if eqx.is_inexact_array_like(xs[0]) else xs[0], *trees)


def log_drive(log, params) -> tuple[str, np.ndarray]:
    """A field log's drive input: ``("voltage", V (K, 2) [V])`` or ``("speed", omega (K, 2) [rad/s])``.

    Speed-mode logs with ``track_speed_*`` columns [m/s] are converted with the belt radius r_s' of
    ``params``'s vehicle on its terrain (:func:`trackenv.physics.geometry.belt_radius`), the radius the
    model's belt speed V_t = r_s' omega uses; ``omega_*`` columns are taken as they are.
    """
    if log.input_mode == "voltage":
        return "voltage", np.asarray(log.volts, np.float64)
    from .physics.geometry import belt_radius  # noqa: PLC0415

    kind, values = log.speed_input
    values = np.asarray(values, np.float64)
    if kind == "track_speed":
        values = values / float(np.asarray(belt_radius(params.vehicle, params.terrain)))
    return "speed", values


def drive_profile(kind: str, t, values, dtype, source: str = "profile"):
    """The simulator's profile for a drive input: a ``VoltageProfile`` or a ``SpeedProfile`` (validated)."""
    from .simulate import SpeedProfile, VoltageProfile  # noqa: PLC0415

    cls = SpeedProfile if kind == "speed" else VoltageProfile
    return cls.from_arrays(t, values, dtype=dtype, source=source)
