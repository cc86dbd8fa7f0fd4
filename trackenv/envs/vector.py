"""Native batched environments: a ``gymnasium.vector.VectorEnv`` and a Stable-Baselines3 ``VecEnv``.

:class:`TrackVectorEnv` steps N environments in **one** jitted call (per host device; per chunk of a
large batch) of the functional core with Gymnasium's autoreset built in, followed by **one**
device-to-host transfer of an (N, K) float32 array::

    venv = gym.make_vec("trackenv/GoStop-v0", num_envs=1024, autoreset_mode="same_step")
    obs, info = venv.reset(seed=0)                   # env i starts as gym.make(...).reset(seed=0 + i)
    obs, rew, term, trunc, info = venv.step(actions) # actions (N, 2) volts

``autoreset_mode`` (``gymnasium.vector.AutoresetMode``, or its value as a string):

- ``"next_step"`` (default, Gymnasium's default): the step after an episode ends resets that
  environment; its action is ignored and it returns reward 0 and no flags;
- ``"same_step"``: an ending environment is reset in the same step; the returned observation is the
  new episode's first, ``info["final_obs"]`` (object array, ``None`` elsewhere) holds the final
  observation and ``info["final_info"]`` the final metrics, each with the ``_key`` masks;
- ``"disabled"``: no autoreset; reset ended environments with ``reset(options={"reset_mask": mask})``.

``physics_batching`` (how the N environments are computed):

- ``"loop"`` (default): every environment is stepped by the single env's compiled program, one row
  after another inside the jitted call (:mod:`.rows`); from 16 environments per host device the rows
  are split over the devices, each running that same program (:func:`trackenv.parallel.run_split`).
  Sub-environment i reset with seed s plays **bit for bit** the episode of
  ``gym.make(...).reset(seed=s + i)`` driven by the same actions (observations, rewards, flags,
  ``info`` and physical state), for every N. A step costs about N single-env steps;
- ``"vmap"`` (plain ``jax.vmap`` of the integrator), ``"native"`` (the vmapped step hands the physics
  to the integrator with the batch on the *last* axis of every array, docs/model.md §6, through
  ``jax.custom_batching.custom_vmap``) or ``"auto"`` (vmap below 256 environments, native from 256,
  split over the host devices from ``parallel.MIN_ENVS_PER_DEVICE`` = 128 per device, traced with the
  contact sums' form for one device's share, :class:`trackenv.physics.sums.Partitioned`; above
  ``parallel.MAX_PER_DEVICE`` = 320 environments per device it steps equal chunks one after the other,
  :func:`trackenv.parallel.chunk_size`): one batched program, 1.3-2.9x the throughput of
  ``"loop"`` from 64 environments (docs/performance.md), but XLA compiles its float32 arithmetic
  differently for each batch shape, so a sub-environment only agrees with the single env to rounding
  (~1e-7 after one step, growing to ~1-3 % of a channel's range within 1.5 s; README Reliability).
  The training configs use ``"auto"``.

``info`` holds one array per metric (``success``, ``off_course``, ``diverged``, ``timeout``,
``time``, ``completion``, ``tracking_rmse``, ``energy``, ``episode_return``) with ``_key`` masks,
and ``params`` (the randomised parameter values) when domain randomisation is on. The physical state
is not in ``info`` by default (the batched programs do not transfer it then, it would be most of the
transfer; the row loop always packs it, one body for every use); pass ``info_state=True`` to get
``info["state"]`` (arrays with a leading N axis), or read :attr:`TrackVectorEnv.state` (device
arrays) whenever needed.

:class:`SB3VecEnv` adapts it for Stable-Baselines3 (``PPO("MlpPolicy", SB3VecEnv(...))``): SB3's
same-step autoreset, ``dones = terminated | truncated``, ``infos[i]["terminal_observation"]`` and
``infos[i]["TimeLimit.truncated"]`` on the step an episode ends, plus ``is_success`` and the episode
metrics there; observations are numpy float32 (N, n_obs), rewards numpy float32 (N,).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import parallel
from ..parallel import run_split, shard
from ..params import is_integer
from ..physics import sums
from . import core, rows
from .core import ENV_DEFAULT_SUBSTEP
from .flat import FlatCodec, codecs
from .gym_env import Layout

NATIVE_FROM = 256  # physics_batching="auto": batch-last layout from this many environments (docs/model.md §6)
PHYSICS_BATCHING = ("loop", "vmap", "native", "auto")

_MODES = {AutoresetMode.NEXT_STEP: "next_step", AutoresetMode.SAME_STEP: "same_step", AutoresetMode.DISABLED: "disabled"}


def _mode(mode) -> AutoresetMode:
    if isinstance(mode, AutoresetMode):
        return mode
    for m, name in _MODES.items():
        if mode in (name, m.value):
            return m
    raise ValueError(f"autoreset_mode must be one of {list(_MODES.values())} or a gymnasium AutoresetMode, got {mode!r}")


_FNS: dict = {}


def jitted(scodec: FlatCodec, pcodec: FlatCodec):
    """Jitted batched (reset, masked reset, step) on flat (N, n) state arrays; cached by structure."""
    key = (scodec, pcodec)
    if key in _FNS:
        return _FNS[key]

    def one_reset(seed, params, with_physics, final):
        state, out = core.reset(jax.random.PRNGKey(seed), params)
        sf, si = scodec.ravel(state)
        return sf, si, core.pack(state, out, params, with_physics=with_physics, final=out if final else None)

    def vreset(seeds, pf, pi, with_physics, final, parts):
        params = pcodec.unravel(pf, pi)
        with sums.Partitioned(parts):  # trace-time: the contact sums' form for one device's share
            return jax.vmap(lambda s: one_reset(s, params, with_physics, final))(seeds)

    def vreset_masked(sf, si, seeds, mask, pf, pi, with_physics, final, parts):
        nf, ni, packed = vreset(seeds, pf, pi, with_physics, final, parts)
        return jnp.where(mask[:, None], nf, sf), jnp.where(mask[:, None], ni, si), packed

    def vstep(sf, si, actions, pf, pi, mode, with_physics, final, parts):
        params = pcodec.unravel(pf, pi)

        def one(f, i, a):
            state, out, fin = core.step_autoreset(scodec.unravel(f, i), a, params, mode)
            f, i = scodec.ravel(state)
            return f, i, core.pack(state, out, params, with_physics=with_physics, final=fin if final else None)

        with sums.Partitioned(parts):
            return jax.vmap(one)(sf, si, actions)

    fns = (jax.jit(vreset, static_argnames=("with_physics", "final", "parts")),
           jax.jit(vreset_masked, static_argnames=("with_physics", "final", "parts")),
           jax.jit(vstep, static_argnames=("mode", "with_physics", "final", "parts")))
    _FNS[key] = fns
    return fns


def _pad_rows(x: np.ndarray, size: int) -> np.ndarray:
    """``x`` (n, ...) with ``size - n`` copies of its last row appended."""
    pad = size - x.shape[0]
    return x if pad == 0 else np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])


class TrackVectorEnv(VectorEnv):
    """N PackBots on one task, stepped by one jitted call per step (see the module docstring)."""

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, task: str = "go_stop", num_envs: int = 8, *, autoreset_mode="next_step", info_state: bool = False,
                 terrain: str = "dry_sand", effects=(), control_dt: float = 0.05, substep: float = ENV_DEFAULT_SUBSTEP,
                 render_mode: str | None = None, domain_randomization=False, normalize_action: bool = False,
                 vehicle: str = "packbot", internal_resistance: str = "constant", physics_batching: str = "loop",
                 params: core.EnvParams | None = None, **task_kwargs):
        if not (is_integer(num_envs) and num_envs >= 1):
            raise ValueError(f"num_envs must be a positive integer, got {num_envs!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if physics_batching not in PHYSICS_BATCHING:
            raise ValueError(f"physics_batching must be one of {PHYSICS_BATCHING}, got {physics_batching!r}")
        if physics_batching == "auto":  # measured on a 2-core CPU: native wins from a few hundred envs
            physics_batching = "native" if num_envs >= NATIVE_FROM else "vmap"
        self.physics_batching = physics_batching
        self._loop = physics_batching == "loop"
        if params is None:  # the loop runs the single env's program: its parameters (physics unbatched)
            params = core.make_params(task, terrain=terrain, vehicle=vehicle, internal_resistance=internal_resistance,
                                      effects=effects, control_dt=control_dt, substep=substep,
                                      domain_randomization=domain_randomization, normalize_action=normalize_action,
                                      physics_batching="vmap" if self._loop else physics_batching, **task_kwargs)
        self.params = params
        self.task_name = params.task.name
        self.num_envs = int(num_envs)
        self.autoreset_mode = _mode(autoreset_mode)
        self._mode = _MODES[self.autoreset_mode]
        self.render_mode = render_mode
        self.info_state = bool(info_state) or render_mode is not None
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode, "render_fps": int(round(1.0 / params.control_dt))}
        vlim = params.voltage_limit
        self.single_action_space = (spaces.Box(-1.0, 1.0, (2,), np.float32) if params.normalize_action
                                    else spaces.Box(-vlim, vlim, (2,), np.float32))
        self.single_observation_space = spaces.Box(np.asarray(params.obs_low), np.asarray(params.obs_high), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.obs_names = params.obs_names
        self._final = self._mode == "same_step"
        self._scodec, self._pcodec = codecs(params)
        self._pf, self._pi = (jnp.asarray(v) for v in self._pcodec.ravel_host(params))
        if self._loop:
            self._reset_rows, self._step_rows = rows.jitted(self._scodec, self._pcodec)
            self._row_devices = parallel.split_count(self.num_envs, parallel.MIN_ROWS_PER_DEVICE)
            self._rows_shared = (np.int32(self.num_envs // self._row_devices), self._pf, self._pi)  # rows per call
            self._mode_index = rows.mode_index(self._mode)
        else:
            self._vreset, self._vreset_masked, self._vstep = jitted(self._scodec, self._pcodec)
            self._split_from = parallel.MIN_ENVS_PER_DEVICE  # read once: the split and the traced sums agree
            self._chunk = parallel.chunk_size(self.num_envs)  # 4 096 environments: 1.4-1.6x faster as chunks
            self._parts = parallel.split_count(self._chunk, self._split_from)
        self._sf = self._si = None
        self._last_host = None
        example = self._scodec.unravel_host(np.zeros(self._scodec.n_float, np.float32), np.zeros(self._scodec.n_int, np.int32))
        # the row program packs everything (one compiled body for every use); the batched one what is asked
        self._layout = Layout(params, example, with_physics=self.info_state or self._loop,
                              final_obs=self._final or self._loop)
        self._trails: list[np.ndarray] = []
        self._renderers: dict[int, Any] = {}

    # -- gymnasium API ---------------------------------------------------------------------------

    def _seeds(self, seed) -> np.ndarray:
        """Per-environment episode seeds. An int ``seed`` seeds env i like a single env reset with
        ``seed + i`` (so its first episode is identical); a list gives one seed (or None) per env."""
        from gymnasium.utils import seeding  # noqa: PLC0415

        def episode_seed(s):
            if s is None:
                return self.np_random.integers(0, 2**32 - 1, dtype=np.uint32)
            return seeding.np_random(int(s))[0].integers(0, 2**32 - 1, dtype=np.uint32)

        if seed is None:
            return self.np_random.integers(0, 2**32 - 1, size=self.num_envs, dtype=np.uint32)
        if isinstance(seed, (int, np.integer)):
            seed = [int(seed) + i for i in range(self.num_envs)]
        if len(seed) != self.num_envs:
            raise ValueError(f"seed list must have {self.num_envs} entries, got {len(seed)}")
        return np.asarray([episode_seed(s) for s in seed], np.uint32)

    def _on_cores(self, x):
        """``x`` (chunk, ...) split over the host devices for the batched program (one half per core from
        ``MIN_ENVS_PER_DEVICE`` environments per core), else unchanged."""
        return shard(x, self._chunk, 0, self._split_from)

    def _chunks(self, x: np.ndarray) -> list:
        """``x`` (num_envs, ...) as the batched program's chunks (:func:`trackenv.parallel.chunk_size`), each padded and
        on the cores."""
        c = self._chunk
        return [self._on_cores(_pad_rows(np.asarray(x[i:i + c]), c)) for i in range(0, self.num_envs, c)]

    def _joined(self, outs) -> tuple:
        """The chunks' (state float, state int, packed) outputs: the states kept per chunk on the devices, the
        packed rows joined on the host (padding dropped)."""
        sf, si, packed = zip(*outs)
        host = np.concatenate([np.asarray(p) for p in packed])[: self.num_envs]
        return list(sf), list(si), host

    def _host_state(self) -> tuple[np.ndarray, np.ndarray]:
        """The flat state (num_envs, n_float), (num_envs, n_int) as numpy arrays."""
        if self._loop:
            return np.asarray(self._sf), np.asarray(self._si)
        return (np.concatenate([np.asarray(x) for x in self._sf])[: self.num_envs],
                np.concatenate([np.asarray(x) for x in self._si])[: self.num_envs])

    def reset(self, *, seed=None, options: dict | None = None):
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if options:
            raise ValueError(f"unsupported reset options {sorted(options)} (only 'reset_mask')")
        seeds = self._seeds(seed)
        if mask is not None:
            mask = np.asarray(mask)
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({self.num_envs},)")
            if self._sf is None:
                raise RuntimeError("reset_mask needs a previous full reset()")
        if self._loop:
            if mask is None:
                sf = np.zeros((self.num_envs, self._scodec.n_float), np.float32)
                si = np.zeros((self.num_envs, self._scodec.n_int), np.int32)
            else:
                sf, si = self._sf, self._si
            self._sf, self._si, packed = run_split(
                self._reset_rows, (sf, si, seeds, np.ones(self.num_envs, bool) if mask is None else mask),
                self._rows_shared, self._row_devices)
            host = np.array(packed)
        elif mask is not None:
            self._sf, self._si, host = self._joined(
                self._vreset_masked(sf, si, s, m, self._pf, self._pi, with_physics=self.info_state, final=self._final,
                                    parts=self._parts)
                for sf, si, s, m in zip(self._sf, self._si, self._chunks(seeds), self._chunks(mask)))
        else:
            self._sf, self._si, host = self._joined(
                self._vreset(s, self._pf, self._pi, with_physics=self.info_state, final=self._final, parts=self._parts)
                for s in self._chunks(seeds))
        if mask is not None:  # environments that were not reset keep their last observation and info
            host = np.where(mask[:, None], host, self._last_host)
        self._last_host = host
        if self.render_mode is not None:
            xy = self._pose(host)[:, :2]
            if mask is None or not self._trails:
                self._trails = [[p.copy()] for p in xy]
            else:
                for i in np.flatnonzero(mask):
                    self._trails[i] = [xy[i].copy()]
        obs, info = self._split(host, mask)
        return obs, info

    def check_actions(self, actions) -> np.ndarray:
        try:
            a = np.asarray(actions, dtype=np.float32)
        except (TypeError, ValueError):
            raise ValueError(f"actions must be numbers of shape ({self.num_envs}, 2)") from None
        if a.shape != (self.num_envs, 2):
            raise ValueError(f"actions must have shape ({self.num_envs}, 2) [V_left, V_right], got {a.shape}")
        bad = ~np.isfinite(a).all(axis=1)
        if bad.any():
            raise ValueError(f"actions must be finite: NaN/inf in environment(s) {np.flatnonzero(bad)[:10].tolist()}")
        return a

    def step(self, actions):
        if self._sf is None:
            raise RuntimeError("call reset() before step()")
        a = self.check_actions(actions)
        if self._loop:
            self._sf, self._si, packed = run_split(self._step_rows, (self._sf, self._si, a),
                                                   (self._mode_index,) + self._rows_shared, self._row_devices)
            host = np.array(packed)  # the one device-to-host transfer
        else:  # one call and one transfer per chunk (one chunk below MAX_PER_DEVICE environments per core)
            self._sf, self._si, host = self._joined(
                self._vstep(sf, si, ac, self._pf, self._pi, mode=self._mode, with_physics=self.info_state,
                            final=self._final, parts=self._parts)
                for sf, si, ac in zip(self._sf, self._si, self._chunks(a)))
        self._last_host = host
        lay = self._layout
        rewards = host[:, lay.reward].astype(np.float64)
        term = host[:, lay.terminated] > 0.5
        trunc = host[:, lay.truncated] > 0.5
        obs, info = self._split(host, None)
        if self._final:
            done = term | trunc
            if done.any():
                final_obs = np.full(self.num_envs, None, dtype=object)
                for i in np.flatnonzero(done):
                    final_obs[i] = host[i, lay.final_obs].copy()
                info["final_obs"] = final_obs
                info["_final_obs"] = done.copy()
                fin = {}
                for k, j in lay.final_info.items():
                    col = host[:, j]
                    fin[k] = col > 0.5 if k in core.BOOL_INFO else col.astype(np.float64)
                    fin["_" + k] = done.copy()
                info["final_info"] = fin
                info["_final_info"] = done.copy()
        if self.render_mode is not None:
            xy = self._pose(host)[:, :2]
            for i in range(self.num_envs):
                self._trails[i].append(xy[i].copy())
            if self._mode == "same_step":
                for i in np.flatnonzero(term | trunc):
                    self._trails[i] = [xy[i].copy()]
        return obs, rewards, term, trunc, info

    def render(self):
        """Frames of every sub-environment (tuple of (H, W, 3) uint8); slow for large N."""
        if self.render_mode is None:
            gym.logger.warn("render() called without render_mode='rgb_array'")
            return None
        return tuple(self.render_env(i) for i in range(self.num_envs))

    def render_env(self, i: int) -> np.ndarray:
        from . import render as _render  # noqa: PLC0415

        if self._sf is None:
            raise RuntimeError("call reset() before render()")
        sf, si = self._host_state()
        one = self._scodec.unravel_host(sf[i], si[i])
        drawing = self.params.task.drawing(one.task)
        info = {"time": float(one.steps) * self.params.control_dt,
                "state": {"pose": np.asarray(one.physics.pose), "vel": np.asarray(one.physics.vel),
                          "current": np.asarray(one.physics.current)}}
        r = self._renderers.get(i)
        if r is None:
            r = self._renderers[i] = _render.Renderer()
        trail = self._trails[i] if self._trails else []
        return r.frame(drawing, trail, info, self.params, self.task_name)

    def close_extras(self, **kwargs):
        for r in self._renderers.values():
            r.close()
        self._renderers = {}

    # -- helpers ---------------------------------------------------------------------------------

    def _pose(self, host):
        for name, sl, _shape in self._layout.physics:
            if name == "pose":
                return host[:, sl]
        raise RuntimeError("physics state not packed")

    def _split(self, host: np.ndarray, mask) -> tuple[np.ndarray, dict]:
        lay = self._layout
        obs = np.ascontiguousarray(host[:, : lay.n_obs])
        present = np.ones(self.num_envs, bool) if mask is None else mask.copy()
        info: dict[str, Any] = {}
        for k, j in lay.info.items():
            col = host[:, j]
            info[k] = col > 0.5 if k in core.BOOL_INFO else col.astype(np.float64)
            info["_" + k] = present.copy()
        if lay.dr_paths:
            dr = host[:, lay.dr]
            info["params"] = {p: dr[:, n].astype(np.float64) for n, p in enumerate(lay.dr_paths)}
            info["_params"] = present.copy()
        if lay.physics and self.info_state:
            info["state"] = {name: host[:, sl].reshape((self.num_envs,) + shape) for name, sl, shape in lay.physics}
            info["_state"] = present.copy()
        return obs, info

    @property
    def state(self) -> core.EnvState | None:
        """The batched :class:`~trackenv.envs.core.EnvState` as numpy arrays (leading N axis; a copy)."""
        if self._sf is None:
            return None
        return self._scodec.unravel_host(*self._host_state(), batch=(self.num_envs,))

    def physical_state(self) -> dict[str, np.ndarray]:
        """The full physical state of every environment (numpy, leading N axis), on demand."""
        phys = self.state.physics
        names = [".".join(p) for p, _ in core.physics_layout(jax.tree.map(lambda x: x[0], self.state))]
        return dict(zip(names, jax.tree.leaves(phys)))


def _task_vector_env(task_cls) -> type[TrackVectorEnv]:
    """The ``VectorEnv`` class of one task (``<TaskClass>VectorEnv``, the vector entry point of its env id)."""

    class _V(TrackVectorEnv):
        def __init__(self, num_envs: int = 8, **kwargs):
            kwargs.pop("max_episode_steps", None)
            if "task" in kwargs:
                raise TypeError("the task is fixed by the environment id")
            super().__init__(task_cls.name, num_envs, **kwargs)

    _V.__doc__ = f"``gym.make_vec('{task_cls.env_id}', num_envs=N)``: TrackVectorEnv with the {task_cls.__name__} task."
    _V.__name__ = _V.__qualname__ = f"{task_cls.__name__}VectorEnv"
    _V.__module__ = __name__
    return _V


def _define_task_vector_envs() -> dict[str, type[TrackVectorEnv]]:
    from .tasks import TASK_CLASSES  # noqa: PLC0415

    classes = {c.__name__: c for c in map(_task_vector_env, TASK_CLASSES)}
    globals().update(classes)  # GoStopVectorEnv, JTurnVectorEnv, ... (the registered vector entry points)
    return classes


TASK_VECTOR_ENVS = _define_task_vector_envs()  # class name -> class, one per task of TASK_CLASSES


# ----------------------------------------------------------------------------------------------
# Stable-Baselines3 adapter

try:
    from stable_baselines3.common.vec_env import VecEnv as _SB3VecEnv
except ImportError:  # pragma: no cover - SB3 is a dependency, but keep the module importable
    _SB3VecEnv = object


class SB3VecEnv(_SB3VecEnv):
    """Stable-Baselines3 ``VecEnv`` over :class:`TrackVectorEnv` (same-step autoreset).

    ``SB3VecEnv("trackenv/GoStop-v0", num_envs=64, normalize_action=True, terrain="asphalt")`` or
    ``SB3VecEnv(task="go_stop", ...)`` or ``SB3VecEnv(vec_env=TrackVectorEnv(..., autoreset_mode="same_step"))``.
    ``seed(s)`` seeds env i with s + i at the next ``reset()``, as SB3's own vector envs do.
    """

    def __init__(self, env_id: str | None = None, num_envs: int = 8, *, vec_env: TrackVectorEnv | None = None,
                 task: str | None = None, **kwargs):
        if vec_env is None:
            if env_id is not None:
                from . import TASK_OF_ID  # noqa: PLC0415

                if env_id not in TASK_OF_ID:
                    raise ValueError(f"unknown env id {env_id!r}; known: {', '.join(TASK_OF_ID)}")
                task = TASK_OF_ID[env_id]
            vec_env = TrackVectorEnv(task or "go_stop", num_envs, autoreset_mode="same_step", **kwargs)
        elif vec_env.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError("SB3VecEnv needs a TrackVectorEnv with autoreset_mode='same_step'")
        self.venv = vec_env
        self._actions = None
        super().__init__(vec_env.num_envs, vec_env.single_observation_space, vec_env.single_action_space)

    def reset(self):
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else seeds
        obs, _ = self.venv.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rew, term, trunc, info = self.venv.step(self._actions)
        dones = term | trunc
        infos: list[dict] = [{} for _ in range(self.num_envs)]
        if dones.any():
            fin = info["final_info"]
            for i in np.flatnonzero(dones):
                d = infos[i]
                d["terminal_observation"] = info["final_obs"][i]
                d["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
                d["is_success"] = bool(fin["success"][i])
                for k in core.INFO_KEYS:
                    v = fin[k][i]
                    d[k] = bool(v) if k in core.BOOL_INFO else float(v)
        return obs, rew.astype(np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        if method_name == "render":
            return [self.venv.render_env(i) for i in self._get_indices(indices)]
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self):
        return [self.venv.render_env(i) for i in range(self.num_envs)]
