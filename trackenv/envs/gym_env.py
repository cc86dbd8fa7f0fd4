"""Gymnasium wrapper of the functional core: ``gym.make("trackenv/GoStop-v0", terrain="asphalt")``.

One environment is one vehicle. Each ``step`` makes exactly one call of a jitted function
(physics + task + observation + reward + packing) and one device-to-host transfer of a single
float32 vector, which is then split into the observation, the reward, the flags and ``info``.
That function is the row program of :mod:`.rows` run on one row: the program every sub-environment of
:class:`~trackenv.envs.vector.TrackVectorEnv` runs (default ``physics_batching="loop"``), so a vector
env's sub-environment i reset with seed s + i plays bit for bit the episode this env plays after
``reset(seed=s + i)`` with the same actions.
The jitted functions are cached by structure and take the parameters as an argument (flattened to
two vectors, see :mod:`.flat`), so every environment with the same structure (task, substeps, effects, randomised
parameter names) shares one compiled
program, and nothing recompiles after the first step (dtypes and weak types are pinned).

Options (keyword arguments of ``gym.make``):

- ``terrain``: any ``configs/terrain`` id (``dry_sand``, ``asphalt``, ``sandy_loam_1`` ...) or a YAML path;
- ``effects``: ids of docs/model.md §8 (resolved through ``trackenv.effects``) or effect modules;
- ``control_dt``: control step [s], default 0.05; ``substep``: largest integration substep [s],
  default ``trackenv.envs.core.ENV_DEFAULT_SUBSTEP`` (the verified substep of ``simulate``, README),
  at most ``control_dt`` and ``trackenv.simulate.MAX_SUBSTEP`` (else ``ValueError``);
- ``domain_randomization``: ``False`` (default), ``True`` (default ranges), a dict of ranges or a ground
  mixture ``{"grounds": [terrain ids]}``, see :mod:`trackenv.envs.randomization`;
- ``normalize_action``: ``False`` (default, actions in volts) or ``True`` (actions in [-1, 1] times
  the 24 V limit);
- ``render_mode``: ``None`` or ``"rgb_array"``;
- ``vehicle``, ``internal_resistance``: as :func:`trackenv.load_params`;
- task options (targets as numbers or ``(low, high)`` ranges sampled per episode, tolerances,
  ``max_time``, ``reward={...}``): see the task classes in :mod:`trackenv.envs.tasks`.

Actions: ``Box(-24, 24, (2,), float32)``, the voltages [V_left, V_right]. Out-of-range actions are
clipped to the space (as Gymnasium users expect); NaN/inf or a wrong shape raises ``ValueError``.
For Stable-Baselines3 (which prefers [-1, 1]) either pass ``normalize_action=True`` or wrap with
``gymnasium.wrappers.RescaleAction(env, -1.0, 1.0)``.

``info`` (reset and every step): ``success``, ``off_course``, ``diverged``, ``timeout`` (bools),
``is_success`` (= success, for SB3's logger), ``time`` [s], ``completion`` [0, 1],
``tracking_rmse`` (the task's primary error, SI), ``energy`` [J drawn from the supply so far],
``episode_return``, ``params`` (the domain-randomised values of this episode) and ``state``, the
full physical state (``pose`` (3,), ``vel`` (3,), ``omega`` (2,), ``current`` (2,), ``jz``/``jx``
(2, N) and effect states), float32 numpy arrays in SI units.

The episode ends with ``terminated`` on success or when the vehicle leaves the course, and with
``truncated`` at ``max_time`` or when the simulation diverges (``info["diverged"]``). A ``step`` after
the episode has ended (terminated or truncated) without a ``reset`` raises Gymnasium's
``gymnasium.error.ResetNeeded``, the error its ``OrderEnforcing`` wrapper raises for a step before the first
reset (the vector env resets finished sub-environments itself).

Keyword arguments are checked before anything is built: a mistyped one (``terain=``) raises ``TypeError``
listing every accepted keyword (the environment's and the task's) and the closest match.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from . import core, rows
from .core import ENV_DEFAULT_SUBSTEP
from .flat import codecs


class Layout:
    """Positions of the fields in the packed host vector (see :func:`trackenv.envs.core.pack`)."""

    def __init__(self, params: core.EnvParams, state: core.EnvState, *, with_physics=True, final_obs=False):
        self.n_obs = len(params.obs_names)
        i = self.n_obs
        self.reward = i
        i += 1
        self.info = {k: i + j for j, k in enumerate(core.INFO_KEYS)}
        i += len(core.INFO_KEYS)
        self.terminated, self.truncated = i, i + 1
        i += 2
        self.dr_paths = params.dr_paths
        self.dr = slice(i, i + len(params.dr_paths))
        i += len(params.dr_paths)
        self.final_obs = None
        self.final_info = None
        if final_obs:
            self.final_obs = slice(i, i + self.n_obs)
            i += self.n_obs
            self.final_info = {k: i + j for j, k in enumerate(core.INFO_KEYS)}
            i += len(core.INFO_KEYS)
        self.physics = []
        if with_physics:
            for path, shape in core.physics_layout(state):
                n = int(np.prod(shape, dtype=np.int64))
                self.physics.append((".".join(path), slice(i, i + n), shape))
                i += n
        self.size = i

    def info_dict(self, host: np.ndarray) -> dict[str, Any]:
        info: dict[str, Any] = {}
        for k, j in self.info.items():
            info[k] = bool(host[j] > 0.5) if k in core.BOOL_INFO else float(host[j])
        info["is_success"] = info["success"]
        dr = host[self.dr]
        info["params"] = {p: float(dr[n]) for n, p in enumerate(self.dr_paths)}
        if self.physics:
            info["state"] = {name: host[sl].reshape(shape) for name, sl, shape in self.physics}
        return info


class TrackEnv(gym.Env):
    """One PackBot on one task; see the module docstring and the task classes for the details."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, task: str = "go_stop", *, terrain: str = "dry_sand", effects=(), control_dt: float = 0.05,
                 substep: float = ENV_DEFAULT_SUBSTEP, render_mode: str | None = None, domain_randomization=False,
                 normalize_action: bool = False, vehicle: str = "packbot", internal_resistance: str = "constant",
                 params: core.EnvParams | None = None, **task_kwargs):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if params is None:
            check_keywords(task, task_kwargs)
            params = core.make_params(task, terrain=terrain, vehicle=vehicle, internal_resistance=internal_resistance,
                                      effects=effects, control_dt=control_dt, substep=substep,
                                      domain_randomization=domain_randomization, normalize_action=normalize_action,
                                      **task_kwargs)
        elif task_kwargs:
            raise TypeError(f"pass task options to make_params, not together with params= (got {sorted(task_kwargs)})")
        self.params = params
        self.task_name = params.task.name
        self.terrain = terrain
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / params.control_dt))}
        vlim = params.voltage_limit
        if params.normalize_action:
            self.action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
        else:
            self.action_space = spaces.Box(-vlim, vlim, (2,), np.float32)
        self.observation_space = spaces.Box(np.asarray(params.obs_low), np.asarray(params.obs_high), dtype=np.float32)
        self.obs_names = params.obs_names
        self._scodec, self._pcodec = codecs(params)
        self._reset_fn, self._step_fn = rows.jitted(self._scodec, self._pcodec)  # run on one row
        self._pf, self._pi = (jnp.asarray(v) for v in self._pcodec.ravel_host(params))
        self._one = jnp.asarray(1, jnp.int32)  # the row count
        self._disabled = jnp.asarray(rows.mode_index("disabled"))  # no autoreset: reset() starts episodes
        self._sf = self._si = None  # (1, n_float), (1, n_int): the state as the one row of a batch
        self._ended = None  # "terminated"/"truncated" once the episode has ended, until reset()
        self._layout = Layout(params, self._scodec.unravel_host(np.zeros(self._scodec.n_float, np.float32),
                                                                np.zeros(self._scodec.n_int, np.int32)),
                              final_obs=True)
        self._trail: list[tuple[float, float]] = []
        self._drawing = None
        self._last_info: dict | None = None
        self._renderer = None

    # -- gymnasium API ---------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset options are not supported, got keys {sorted(options)}")
        episode_seed = self.np_random.integers(0, 2**32 - 1, size=1, dtype=np.uint32)
        sf, si = (np.zeros((1, n), dt) for n, dt in ((self._scodec.n_float, np.float32), (self._scodec.n_int, np.int32)))
        self._sf, self._si, packed = self._reset_fn(sf, si, episode_seed, np.ones(1, bool), self._one, self._pf, self._pi)
        self._ended = None
        host = np.array(packed)[0]
        obs, info = host[: self._layout.n_obs], self._layout.info_dict(host)
        if self.render_mode is not None:
            self._trail = [(0.0, 0.0)]
            self._drawing = None
            self._last_info = info
        return obs, info

    def step(self, action):
        if self._sf is None:
            raise RuntimeError("call reset() before step()")
        if self._ended is not None:
            raise ResetNeeded(f"{self.task_name}: step() after the episode ended ({self._ended}=True at t = "
                              f"{self._ended_time:g} s); call reset() first (Gymnasium: stepping a finished "
                              "episode is undefined)")
        a = self.check_action(action)
        self._sf, self._si, packed = self._step_fn(self._sf, self._si, a[None], self._disabled, self._one,
                                                   self._pf, self._pi)
        host = np.array(packed)[0]  # the one device-to-host transfer (a writable copy)
        lay = self._layout
        obs = host[: lay.n_obs]
        info = lay.info_dict(host)
        if self.render_mode is not None:
            pose = info["state"]["pose"]
            self._trail.append((float(pose[0]), float(pose[1])))
            self._last_info = info
        terminated, truncated = bool(host[lay.terminated] > 0.5), bool(host[lay.truncated] > 0.5)
        if terminated or truncated:
            self._ended = "terminated" if terminated else "truncated"
            self._ended_time = info["time"]
        return obs, float(host[lay.reward]), terminated, truncated, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        if self._sf is None:
            raise RuntimeError("call reset() before render()")
        from . import render as _render  # noqa: PLC0415  (matplotlib only when rendering)

        if self._renderer is None:
            self._renderer = _render.Renderer()
        if self._drawing is None:
            self._drawing = self.params.task.drawing(self.state.task)
        return self._renderer.frame(self._drawing, self._trail, self._last_info, self.params, self.task_name)

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # -- helpers ---------------------------------------------------------------------------------

    def check_action(self, action) -> np.ndarray:
        """The action as float32 (2,); ValueError for a wrong shape or a non-finite value."""
        try:
            a = np.asarray(action, dtype=np.float32)
        except (TypeError, ValueError):
            raise ValueError(f"action must be two numbers [V_left, V_right], got {action!r}") from None
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,) [V_left, V_right], got shape {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action must be finite, got {a.tolist()} (NaN/inf voltages are rejected; "
                             "out-of-range finite values are clipped)")
        return a

    @property
    def state(self) -> core.EnvState | None:
        """The current :class:`~trackenv.envs.core.EnvState` as numpy arrays (a copy, for inspection)."""
        if self._sf is None:
            return None
        return self._scodec.unravel_host(np.asarray(self._sf)[0], np.asarray(self._si)[0])


ENV_KEYWORDS = ("terrain", "effects", "control_dt", "substep", "render_mode", "domain_randomization",
                "normalize_action", "vehicle", "internal_resistance", "params")


def check_keywords(task: str, task_kwargs: dict) -> None:
    """``TypeError`` for a keyword neither the environment nor the task accepts, listing all accepted ones."""
    import difflib

    from .tasks import TASKS  # noqa: PLC0415

    if task not in TASKS:
        return  # make_params reports the unknown task
    options = TASKS[task].default_params()
    accepted = sorted(set(ENV_KEYWORDS) | set(options))
    unknown = sorted(set(task_kwargs) - set(options))
    if unknown:
        close = difflib.get_close_matches(unknown[0], accepted, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise TypeError(f"{task}: unknown option(s) {unknown}{hint}; accepted: {', '.join(accepted)}")


def _task_env(task_cls) -> type[TrackEnv]:
    """The ``gymnasium.Env`` class of one task (``<TaskClass>Env``, the entry point of its env id)."""

    class _Env(TrackEnv):
        def __init__(self, **kwargs):
            if "task" in kwargs:
                raise TypeError("the task is fixed by the environment id")
            super().__init__(task_cls.name, **kwargs)

    _Env.__doc__ = (f"``gym.make('{task_cls.env_id}')``: TrackEnv with the {task_cls.__name__} task.\n\n"
                    + (task_cls.__doc__ or "") + "\n\nCommon options, observation tail, info: see "
                    "``trackenv.envs.gym_env`` and ``trackenv.envs.core``.")
    _Env.__name__ = _Env.__qualname__ = f"{task_cls.__name__}Env"
    _Env.__module__ = __name__
    return _Env


def _define_task_envs() -> dict[str, type[TrackEnv]]:
    from .tasks import TASK_CLASSES  # noqa: PLC0415

    classes = {c.__name__: c for c in map(_task_env, TASK_CLASSES)}
    globals().update(classes)  # GoStopEnv, JTurnEnv, ... (the registered entry points)
    return classes


TASK_ENVS = _define_task_envs()  # env class name -> class, one per task of trackenv.envs.tasks.TASK_CLASSES
