"""A disk cache of compiled XLA programs, so that a new process does not compile the simulator again.

Every process that simulates compiles its programs first: one per effect, batch shape and output grid.
A diagnosis of a 2-test blind case compiles the simulation core 26 times, about 4 s each; run twice in
one process, the same diagnosis took 159 s cold and 91 s warm. JAX's persistent compilation cache
(https://docs.jax.dev/en/latest/persistent_compilation_cache.html) keeps the compiled programs on disk,
keyed by the program, the compile options and the JAX/XLA versions, so a change of the code or of JAX
compiles afresh and a cache hit runs the very same executable (the results do not change).

The command line (:mod:`trackenv.cli`, hence ``make demo``) turns it on; a library user calls
:func:`enable_compilation_cache` once, before the first simulation. Where it lives:

- ``JAX_COMPILATION_CACHE_DIR`` (JAX's own setting) wins if set: nothing is changed;
- else ``TRACKENV_COMPILATION_CACHE``: a directory, or ``off`` (also ``0``, ``false``, ``no``) to disable;
- else ``$XDG_CACHE_HOME/trackenv/jax/<host>-<arch>`` (``~/.cache`` by default). The host name is part of the
  path because XLA compiles for the host's CPU features, and a home directory shared by different machines
  would otherwise keep replacing one machine's programs with another's.

Every compiled program is stored, however fast it compiled (:data:`MIN_COMPILE_TIME_S`; JAX's default
keeps only those that took at least 1 s, the simulation cores). A diagnosis also compiles several hundred
small programs (the array operations between its simulations); with those cached too, a second process
ran a 2-test diagnosis 1.20x faster than with the simulation cores alone (docs/performance.md, "Compiled
programs across processes", which gives the command and the measurements). A threshold set
through ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` or ``jax.config`` is kept. The directory grows with
every new program (batch shape, effect, test length) and is never pruned: deleting it only costs the next
process its compilations. The cache is trusted code: do not point it at a directory that others can write
to.
"""

from __future__ import annotations

import os
import platform
import warnings
from pathlib import Path

ENV = "TRACKENV_COMPILATION_CACHE"
OFF = ("off", "0", "false", "no")
MIN_COMPILE_TIME_S = 0.0  # s: store every program (JAX's default, 1 s, stores the simulation cores only)
JAX_DEFAULT_MIN_COMPILE_TIME_S = 1.0


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/trackenv/jax/<host>-<arch>`` (``~/.cache`` when ``XDG_CACHE_HOME`` is unset)."""
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    host = "".join(c if c.isalnum() or c in "-_." else "_" for c in (platform.node() or "host"))
    return root / "trackenv" / "jax" / f"{host}-{platform.machine() or 'cpu'}"


def enable_compilation_cache(path: str | Path | None = None) -> Path | None:
    """Store compiled programs in ``path`` (default: see the module docstring) and reuse them across processes;
    every program, unless a minimum compile time was set for JAX (module docstring).

    Returns the directory in use, or ``None`` where ``TRACKENV_COMPILATION_CACHE`` is ``off`` or the directory
    cannot be created (a warning says why; nothing else changes). A cache directory already set for JAX
    (``JAX_COMPILATION_CACHE_DIR`` or ``jax.config``) is kept and returned. Call it before the first
    compilation: JAX reads the setting when it first compiles.
    """
    import jax

    current = jax.config.jax_compilation_cache_dir
    if current:
        return Path(current)
    setting = os.environ.get(ENV, "").strip()
    if path is None and setting.lower() in OFF:
        return None
    target = Path(path if path is not None else (setting or default_cache_dir())).expanduser()
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        warnings.warn(f"trackenv: compilation cache disabled, cannot create {target}: {exc}", stacklevel=2)
        return None
    jax.config.update("jax_compilation_cache_dir", str(target))
    if ("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ
            and jax.config.jax_persistent_cache_min_compile_time_secs == JAX_DEFAULT_MIN_COMPILE_TIME_S):
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_TIME_S)
    return target
