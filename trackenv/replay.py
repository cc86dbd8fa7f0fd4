"""Replay: drive the simulator with a field test's voltages and compare with what was measured.

    from trackenv.replay import replay
    res = replay("logs/go_stop_sand_01", "out/replay")      # a docs/model.md §9 field-log folder
    res = replay("go_stop_dry_sand", "out/thesis")          # a thesis test id (configs/field)
    res.metrics["channels"]["i_left"]["nrmse"]

Both write into ``out_dir``:

- ``log.csv`` + ``meta.json``: the *simulated* log in the §9 format, labelled ``"synthetic": true``,
  ``"simulated": true`` (and ``"reconstructed": true`` for thesis tests);
- ``replay.png``: a thesis-style figure (voltages, currents, ideal speed, yaw rate, trajectory),
  simulated vs measured where the log has measurements;
- ``metrics.json``: per-channel RMSE and NRMSE (log) or the thesis-text anchors (thesis test).

**Field-log folder.** The voltages are linear between the log's samples (docs/model.md §1), evaluated at
every RK4 stage. The simulation starts from rest, at the origin with heading 0, at the log's first
sample: if the log's ``t`` does not start at 0 it is shifted (``t_sim = t - t[0]``; the shift is
``t_offset_s`` in ``meta.json``/``metrics.json``), and the figure's time axis is time since the first
sample. The simulation runs on a uniform output grid whose step is the largest multiple of the
integration substep that exceeds neither ``dt`` (0.05 s) nor the log's smallest sample interval (so a
50 Hz log is simulated on its own 20 ms grid); the simulated channels are then evaluated **at the
log's sample times** by linear interpolation on that grid (exact when the times fall on it), and
``log.csv`` is written with the input log's rows and times (its original time base), so it can be
compared with the input row by row. Comparison, per measured channel with samples (missing cells
skipped): ``rmse``, ``nrmse`` = RMSE / (max − min of the measured channel) (``null`` when the
measured channel is constant), ``bias`` (mean of simulated − measured), ``max_abs_error``. When
``meta.json`` says ``current_sensor: "absolute"``, the simulated currents are compared as |i| and
written as |i|. Pose (``x``, ``y``, ``heading``): the simulated pose is moved into the log's frame
by the log's first pose sample (missing values count as 0) before comparing; heading errors are
wrapped to (−π, π]. (These rules are :mod:`trackenv.compare`'s, shared with the diagnosis.)

**Thesis test id.** The voltages are the RECONSTRUCTED profiles of ``configs/field`` (thesis text,
not measured; see its README): there is nothing measured to compare with, so ``metrics.json`` lists
the thesis-text anchors (e.g. the mean current over 1-3 s) next to the simulated values.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from .compare import (
    INPUT_CHANNELS,
    channel_error,
    drive_profile,
    interp_at,
    json_clean,
    log_drive,
    pose_from_log_frame,
    pose_to_log_frame,
    rectify_channels,
    unwrap_measured,
)
from .fieldlog import FieldLog, FieldLogError, read_field_log, write_field_log, write_log_columns
from .outputs import prepare_output_dir
from .simulate import DEFAULT_DT, DEFAULT_SUBSTEP

__all__ = ["replay", "ReplayResult", "resolve_effects", "is_thesis_test", "RECONSTRUCTED_NOTE"]

RECONSTRUCTED_NOTE = ("voltages RECONSTRUCTED from the thesis text (configs/field), not measured; "
                      "simulated with the base model; no field log exists to compare with")
COMPARED = ("i_left", "i_right", "speed_ideal", "yaw_rate", "x", "y", "heading")


@dataclass(frozen=True, eq=False)
class ReplayResult:
    """What :func:`replay` did and wrote.

    ``trajectory`` is on the simulation grid (step ``dt_sim``, time from 0 = the log's first sample);
    ``simulated`` holds the written log's columns (at the log's sample times for a field log, on the
    ``dt`` grid for a thesis test); ``files`` maps ``log``, ``meta``, ``figure``, ``metrics`` to paths.
    """

    source: str
    kind: Literal["field_log", "thesis_test"]
    out_dir: Path
    trajectory: Any
    dt_sim: float
    t_offset: float
    metrics: dict
    simulated: dict
    files: dict
    log: FieldLog | None = None
    params: Any = field(default=None, repr=False)


def resolve_effects(effects) -> tuple:
    """Effect ids (docs/model.md §8) or effect modules -> modules; a bad id raises :class:`ConfigError`."""
    from .effects import resolve_effects as resolve
    from .params import ConfigError

    try:
        return resolve(effects)
    except (ValueError, TypeError) as exc:
        raise ConfigError(str(exc)) from None


def is_thesis_test(source) -> bool:
    """True if ``source`` names a thesis test of configs/field (a bare id, not a path)."""
    from .field_profiles import list_field_tests

    return isinstance(source, str) and "/" not in source and "\\" not in source and source in list_field_tests()


def _grid_step(dt: float, substep: float, min_interval: float) -> float:
    """Largest multiple of ``substep`` that exceeds neither ``dt`` nor ``min_interval`` (at least one substep)."""
    if substep >= dt:
        return dt
    k = max(1, min(math.floor(dt / substep + 1e-6), math.floor(min_interval / substep + 1e-6)))
    return k * substep


def _channel_metrics(signal: str, sim: np.ndarray, meas: np.ndarray) -> dict | None:
    ok = np.isfinite(meas)
    if not ok.any():
        return None
    err = channel_error(signal, sim[ok], meas[ok])
    m = unwrap_measured(meas)[ok] if signal == "heading" else meas[ok]
    rng = float(np.max(m) - np.min(m))
    rmse = float(np.sqrt(np.mean(err**2)))
    return {"rmse": rmse, "nrmse": (rmse / rng) if rng > 0 else None, "range": rng, "bias": float(np.mean(err)),
            "max_abs_error": float(np.max(np.abs(err))), "n": int(ok.sum())}


def _simulated_at(traj, grid: np.ndarray, times: np.ndarray, sensor: str, pose0: tuple[float, float, float]) -> dict:
    """Simulated instrument channels at ``times`` (simulation time base), as the log's instruments report them."""
    at = rectify_channels({k: interp_at(times, grid, traj.channels[k]) for k in COMPARED}, sensor)
    at["x"], at["y"], at["heading"] = pose_to_log_frame(at["x"], at["y"], at["heading"], pose0)
    return at


def _n_steps(t_end: float, dt: float) -> int:
    return max(1, int(math.ceil(t_end / dt - 1e-9)))


def _model_label(effect_names) -> str:
    return "simulated (base model" + (f" + {', '.join(effect_names)})" if effect_names else ")")


def _files(log, meta, figure, metrics) -> dict:
    out = {"log": log, "meta": meta, "figure": figure, "metrics": metrics}
    return {k: v for k, v in out.items() if v is not None}


def _json_dump(path: Path, obj) -> Path:
    path.write_text(json.dumps(json_clean(obj), indent=2, allow_nan=False, ensure_ascii=False) + "\n", encoding="utf-8")
    return path


def replay(
    source: str | Path,
    out_dir: str | Path,
    terrain: str | None = None,
    internal_resistance: str | None = None,
    effects=(),
    substep: float | None = None,
    *,
    dt: float = DEFAULT_DT,
    figure: bool = True,
    progress: Callable[[str], None] | None = None,
    force: bool = False,
) -> ReplayResult:
    """Replay a field log folder or a thesis test id through the simulator; write log, figure, metrics.

    Args:
        source: a docs/model.md §9 field-log folder (a ``Path``, or a string with a path separator or
            naming an existing folder) or a thesis test id of ``configs/field`` (``trackenv replay
            --list``). A bare string that is a thesis test id is the thesis test even if a folder of
            that name exists; write ``./name`` for the folder.
        out_dir: output folder (created); ``log.csv``, ``meta.json``, ``replay.png``, ``metrics.json``.
        terrain: terrain id overriding the log's ``meta.json`` / the test's terrain.
        internal_resistance: ``"constant"`` or ``"viscous"`` (default: the test's; ``constant`` for logs).
        effects: docs/model.md §8 effect ids (``trackenv.effects.EFFECT_IDS``, default parameters) or effect modules.
        substep: integration substep [s] (default ``trackenv.simulate.DEFAULT_SUBSTEP``, 0.5 ms).
        dt: largest output step [s] of the simulation (default 0.05 s); see the module docstring.
        figure: write ``replay.png`` (the slowest output; ``False`` skips it).
        progress: called with a short status string at each stage (the CLI shows them).
        force: write into ``out_dir`` even if it holds a field log that trackenv did not write
            (:func:`trackenv.outputs.prepare_output_dir`; never into the input log's own folder).

    Raises:
        FieldLogError: bad log folder (message names file, column and row).
        ConfigError: unknown terrain, vehicle or effect id.
        OutputFolderError: ``out_dir`` is a file or holds a field log trackenv did not write.
        SimulationDiverged: the simulation went non-finite.
    """
    from .params import ConfigError

    say = progress or (lambda msg: None)
    substep = DEFAULT_SUBSTEP if substep is None else float(substep)
    if not (substep > 0 and math.isfinite(substep)):
        raise ValueError(f"substep must be a positive number of seconds, got {substep}")
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive number of seconds, got {dt}")
    if internal_resistance not in (None, "constant", "viscous"):
        raise ConfigError(f"internal_resistance must be 'constant' or 'viscous', got {internal_resistance!r}")
    effect_modules = resolve_effects(effects)
    effect_names = [e if isinstance(e, str) else type(e).__name__ for e in (effects or ())]
    out = Path(out_dir)
    if is_thesis_test(source):
        prepare_output_dir(out, "replay", force=force)
        return _replay_thesis(str(source), out, terrain, internal_resistance, effect_modules, effect_names, substep,
                              dt, figure, say)
    if isinstance(source, str) and not Path(source).exists() and "/" not in source and "\\" not in source:
        from .field_profiles import list_field_tests

        raise FieldLogError(f"{source}: neither a thesis test id ({', '.join(list_field_tests())}) nor an existing "
                            "field-log folder")
    return _replay_log(Path(source), out, terrain, internal_resistance, effect_modules, effect_names, substep, dt,
                       figure, say, force)


def _replay_log(folder, out, terrain, internal, effect_modules, effect_names, substep, dt, figure,
                say, force=False) -> ReplayResult:
    import trackenv as te

    from .plots import maneuver_figure

    say(f"reading {folder}")
    log = read_field_log(folder)
    if out.resolve() == log.folder.resolve():
        raise FieldLogError(f"{out}: the output folder is the input log's folder; choose another output folder "
                            "(writing there would overwrite the measured log.csv and meta.json)")
    prepare_output_dir(out, "replay", force=force, inputs=(log.folder,))
    params = te.load_params(terrain or log.terrain, vehicle=log.vehicle, internal_resistance=internal or "constant",
                            effects=effect_modules)
    t_log = log.t
    t_offset = float(t_log[0])
    tt = t_log - t_offset
    mode, drive = log_drive(log, params)
    profile = drive_profile(mode, tt, drive, params.dtype, source=str(log.folder / "log.csv"))
    dt_sim = _grid_step(dt, substep, float(np.min(np.diff(tt))))
    n = _n_steps(float(tt[-1]), dt_sim)
    say(f"simulating {n * dt_sim:.2f} s on a {dt_sim * 1e3:g} ms grid (substep {substep * 1e3:g} ms)")
    t0 = time.perf_counter()
    traj = te.simulate(params, profile, n * dt_sim, dt=dt_sim, substep=substep)
    wall = time.perf_counter() - t0
    grid = np.arange(n + 1) * dt_sim

    say("comparing with the log")
    sensor = log.current_sensor
    pose0 = log.first_pose()
    sim = _simulated_at(traj, grid, tt, sensor, pose0)
    measured = log.measured()
    channels, absent = {}, []
    for col in COMPARED:
        if col in INPUT_CHANNELS[mode]:
            absent.append(col)  # the drive input itself (speed mode): not a prediction
        elif col in measured:
            channels[col] = _channel_metrics(col, sim[col], measured[col])
        else:
            absent.append(col)

    say(f"writing log.csv, meta.json, metrics.json to {out}")
    out.mkdir(parents=True, exist_ok=True)
    terrain_id = terrain or log.terrain
    if mode == "voltage":
        cols = {"t": t_log, "v_left": log.volts[:, 0], "v_right": log.volts[:, 1]}
    else:  # the prescribed speeds, and the voltage the drive needs (4.2) as a simulated output
        cols = {"t": t_log, "omega_left": drive[:, 0], "omega_right": drive[:, 1]}
        v_sim = np.asarray(traj.voltage)
        cols.update({"v_left_sim": interp_at(tt, grid, v_sim[:, 0]), "v_right_sim": interp_at(tt, grid, v_sim[:, 1])})
    cols.update({c: sim[c] for c in COMPARED})
    meta = {
        "terrain": terrain_id, "maneuver": log.maneuver, "current_sensor": sensor, "vehicle": log.vehicle,
        "synthetic": True, "simulated": True,
        "source": f"trackenv replay of the field log {log.folder} (simulated with the "
                  f"{'voltages' if mode == 'voltage' else 'measured speeds'} of its log.csv; not measured data)",
        "input_mode": mode, "input_mode_reason": log.input_mode_reason,
        "replay_of": str(log.folder), "replay_of_synthetic": log.synthetic,
        "internal_resistance": internal or "constant", "effects": effect_names,
        "t_offset_s": t_offset, "dt_sim_s": dt_sim, "substep_s": substep,
        "notes": "rows and times are the input log's; the simulation started from rest at its first sample "
                 "(t_offset_s) and its pose was moved into the log's frame at that sample",
    }
    log_path, meta_path = write_log_columns(out, cols, meta)
    meas_plot = {"t": tt}
    if mode == "voltage":
        meas_plot.update({"v_left": log.volts[:, 0], "v_right": log.volts[:, 1]})
    meas_plot.update({k: v for k, v in measured.items() if k not in ("x", "y", "heading")})
    if "x" in measured and "y" in measured:  # measured pose into the simulation's frame, for the figure
        meas_plot["x"], meas_plot["y"], _ = pose_from_log_frame(measured["x"], measured["y"], 0.0, pose0)
    label = "log, synthetic" if log.synthetic else ("field log, MEASURED" if log.meta.get("measured") else "field log")
    caption = (f"replay of {log.folder} ({label}, {len(log)} samples, ammeter {sensor}); simulated with "
               f"{terrain_id}, {internal or 'constant'} internal resistance"
               + ("; driven by the log's measured speeds (speed mode)" if mode == "speed" else "")
               + (f", effects {', '.join(effect_names)}" if effect_names else ", base model")
               + (f"; time since the log's first sample (t = {t_offset:g} s)" if t_offset != 0 else ""))
    fig = None
    if figure:
        say("drawing replay.png")
        fig = maneuver_figure(traj, f"replay of {log.folder.name} ({log.maneuver}, {terrain_id})",
                              out / "replay.png", measured=meas_plot, caption=caption, current_sensor=sensor,
                              measured_label=label, label=_model_label(effect_names), speed_mode=mode == "speed")
    metrics = {
        "source": str(log.folder), "kind": "field_log", "log_is_synthetic": log.synthetic,
        "terrain": terrain_id, "vehicle": log.vehicle, "maneuver": log.maneuver,
        "internal_resistance": internal or "constant", "effects": effect_names, "current_sensor": sensor,
        "input_mode": mode, "log_is_measured": bool(log.meta.get("measured", False)),
        "n_samples": len(log), "t_offset_s": t_offset, "duration_s": float(tt[-1]), "dt_sim_s": dt_sim,
        "substep_s": substep, "wall_time_s": wall,
        "definition": "at the log's sample times; rmse = sqrt(mean((sim - meas)^2)); nrmse = rmse / (max - min of "
                      "measured), null if the measured channel is constant; bias = mean(sim - meas); currents as |i| "
                      "when current_sensor is absolute; heading errors wrapped to (-pi, pi]",
        "channels": channels, "not_in_log": absent,
    }
    met = _json_dump(out / "metrics.json", metrics)
    return ReplayResult(source=str(log.folder), kind="field_log", out_dir=out, trajectory=traj, dt_sim=dt_sim,
                        t_offset=t_offset, metrics=metrics, simulated=cols,
                        files=_files(log_path, meta_path, fig, met), log=log,
                        params=params)


def anchor_metrics(prof, traj, dt: float) -> list[dict]:
    """A thesis test's text anchors (configs/field) beside the simulated values, for trajectories sampled every ``dt``.

    An anchor without a simulated value says why in ``missing``: ``"output_step"`` (no output sample in its window
    at this ``dt``; a smaller ``dt`` gives one) or ``"base_model"`` (not comparable from the base model alone), and
    in ``note``."""
    t = np.arange(np.asarray(traj.t).shape[0]) * dt
    ch = {k: np.asarray(v, np.float64) for k, v in traj.channels.items()}
    rows = []
    for a in prof.anchors:
        row = {k: a.get(k) for k in ("signal", "stat", "t0", "t1", "value", "unit", "source")}
        row["thesis_field"] = row.pop("value")
        sim = None
        if a["stat"] == "mean" and a["t0"] is not None and a["t1"] is not None:
            m = (t >= a["t0"] - 1e-9) & (t <= a["t1"] + 1e-9)
            if not m.any():  # an output step longer than the window: no mean to compare, not a NaN
                row.update(simulated=None, rel_diff=None, missing="output_step",
                           note=f"no simulated sample in {a['t0']:g}-{a['t1']:g} s at the output step dt = {dt:g} s; "
                                "replay with a smaller dt")
                rows.append(row)
                continue
            if a["signal"] == "current":
                sim = float(np.mean(0.5 * (np.abs(ch["i_left"][m]) + np.abs(ch["i_right"][m]))))
            elif a["signal"] in ch:
                sim = float(np.mean(ch[a["signal"]][m]))
        row["simulated"] = sim
        row["rel_diff"] = (sim - a["value"]) / a["value"] if sim is not None and a["value"] else None
        if sim is None:
            row.update(missing="base_model", note="not comparable from a base-model simulation alone (see configs/field)")
        rows.append(row)
    return rows


def _replay_thesis(test_id, out, terrain, internal, effect_modules, effect_names, substep, dt, figure,
                   say) -> ReplayResult:
    import trackenv as te

    from .field_profiles import FIELD_DIR, load_field_profile
    from .plots import maneuver_figure

    say(f"loading thesis test {test_id}")
    prof = load_field_profile(test_id)
    terrain_id = terrain or prof.terrain
    ir = internal or prof.internal_resistance
    params = te.load_params(terrain_id, internal_resistance=ir, effects=effect_modules)
    profile = te.VoltageProfile.from_arrays(prof.t, prof.volts, source=str(FIELD_DIR / f"{test_id}.yaml"))
    n = _n_steps(prof.t_end, dt)
    say(f"simulating {n * dt:.2f} s (substep {substep * 1e3:g} ms)")
    t0 = time.perf_counter()
    traj = te.simulate(params, profile, n * dt, dt=dt, substep=substep)
    wall = time.perf_counter() - t0

    say(f"writing log.csv, meta.json, metrics.json to {out}")
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "terrain": terrain_id, "maneuver": prof.maneuver, "vehicle": "packbot",
        "synthetic": True, "simulated": True, "reconstructed": True,
        "source": f"trackenv replay of thesis test {test_id}: motor voltages RECONSTRUCTED from the thesis text "
                  f"(configs/field/{test_id}.yaml), not measured; every other column is simulated",
        "thesis_test": test_id, "thesis_source": prof.source, "internal_resistance": ir, "effects": effect_names,
        "substep_s": substep,
        "notes": "currents as the thesis's field ammeter reports them (|i|); " + RECONSTRUCTED_NOTE,
    }
    written = write_field_log(out, traj, meta, current_sensor="absolute", profile=profile)
    title = f"{test_id} ({terrain_id}) — RECONSTRUCTED voltages"
    caption = (f"{RECONSTRUCTED_NOTE}. Source: configs/field/{test_id}.yaml ({prof.source}). "
               f"{ir} internal resistance" + (f", effects {', '.join(effect_names)}" if effect_names else "") + ".")
    fig = None
    if figure:
        say("drawing replay.png")
        fig = maneuver_figure(traj, title, out / "replay.png", caption=caption, current_sensor="signed",
                              label=_model_label(effect_names))
    metrics = {
        "source": test_id, "kind": "thesis_test", "reconstructed": True, "note": RECONSTRUCTED_NOTE,
        "terrain": terrain_id, "maneuver": prof.maneuver, "internal_resistance": ir, "effects": effect_names,
        "duration_s": n * dt, "dt_s": dt, "substep_s": substep, "wall_time_s": wall,
        "channels": {}, "anchors": anchor_metrics(prof, traj, dt),
    }
    met = _json_dump(out / "metrics.json", metrics)
    cols = {c: written.data[c].to_numpy(np.float64) for c in written.data.columns}
    return ReplayResult(source=test_id, kind="thesis_test", out_dir=out, trajectory=traj, dt_sim=dt, t_offset=0.0,
                        metrics=metrics, simulated=cols,
                        files=_files(out / "log.csv", out / "meta.json", fig, met),
                        params=params)
