"""Compiled programs kept on disk, on for every command that evaluates.

Compiling the evaluation takes seconds and the rollouts of one scene milliseconds,
so every ``shacc`` command that evaluates, and every evaluation through the Python API
(``sweeps.pipeline``, as notebooks use it), keeps what it built: a later run whose
padded shapes (tasks, starts, objects), modes and layout were seen before loads the
program instead of building it. Two kinds of entry, in two subfolders:

- ``xla/``: JAX's persistent compilation cache (XLA executables, keyed by JAX on the
  program, the backend and the jax/jaxlib versions);
- ``programs/``: the evaluation's traced and lowered program, serialised with
  ``jax.export`` (:mod:`shacc_jax.program_cache`), keyed on the source of
  ``shacc_jax``, the versions, the backend and the shapes, so tracing is skipped too.

The programs carry no Python stack frames in their source locations
(:func:`lean_locations`): XLA formats every instruction's frames into profiler
annotations each time it builds or loads a GPU executable, which took half of the
evaluation's load (0.35-0.45 s of 0.7-0.9 s on an H100, ``benchmarks/RESULTS.md``).
Error messages from Python are unaffected; an HLO dump or a profile names the
operations but not the Python lines. ``JAX_TRACEBACK_IN_LOCATIONS_LIMIT``, when set,
wins.

Where: ``$SHACC_COMPILE_CACHE`` if set (a folder, or ``off`` to disable), else
``$XDG_CACHE_HOME/shacc/compiled`` (``~/.cache/shacc/compiled`` when
``XDG_CACHE_HOME`` is unset). An entry never goes stale (a change of code or version
makes new keys), and old ones are removed: a traced program of another version of the
code that nothing has used for a day (:func:`geometry_precompute.fileio.prune_stale`),
and an XLA executable that nothing has loaded for a week (:data:`XLA_STALE_AFTER_S`:
JAX's keys do not say which code made them). Deleting the folder at any time is safe
(``rm -r ~/.cache/shacc/compiled``).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

from geometry_precompute.fileio import (
    cache_home,
    mark_used,
    prune_stale,
    seal,
    unseal,
    write_atomic,
)

ENV = "SHACC_COMPILE_CACHE"
# JAX's keys name the program, not the code that traced it, so an entry of older code
# cannot be told from a current one by its name: an entry nothing has loaded for this
# long is removed (by the first entry a process stores). Loading one touches it.
XLA_STALE_AFTER_S = 7 * 24 * 3600


def cache_dir() -> Path | None:
    """The folder in use, or None when the cache is turned off."""
    value = os.environ.get(ENV, "").strip()
    if value.lower() == "off":
        return None
    if value:
        return Path(value).expanduser()
    return cache_home() / "compiled"


def _verified_xla_cache(folder: Path):
    """JAX's persistent cache with every entry sealed (``fileio.seal``): a truncated
    entry, or another program's entry under this name, is a miss (compiled again),
    never loaded. JAX itself loads whatever file bears the name (its documentation:
    the cache is trusted). Installed through JAX's internal cache slot; where a JAX
    release has none, its own cache is used unverified."""
    from jax._src import compilation_cache as cc  # deferred: 1.5 s to import
    from jax._src.compilation_cache_interface import CacheInterface  # deferred: 1.7 s to import

    class VerifiedCache(CacheInterface):
        def __init__(self, path: Path):
            self._path = path

        def get(self, key: str) -> bytes | None:
            path = self._path / f"{key}-sealed"
            try:
                value = unseal(key, path.read_bytes())
            except OSError:
                return None
            if value is not None:  # a whole entry of this key: in use
                mark_used(path)
            return value

        def put(self, key: str, value: bytes) -> None:
            try:
                write_atomic(self._path / f"{key}-sealed", seal(key, value))
            except OSError:  # an unwritable cache costs time later, never this run
                return
            prune_stale(self._path, "*-sealed", None, after_s=XLA_STALE_AFTER_S)

    with cc._cache_initialized_mutex:
        cc._cache = VerifiedCache(folder)
        cc._cache_initialized = True


LOCATIONS_ENV = "JAX_TRACEBACK_IN_LOCATIONS_LIMIT"


def lean_locations() -> None:
    """Programs traced from now on in this process keep no Python stack frames in
    their source locations, unless the user set :data:`LOCATIONS_ENV`."""
    if os.environ.get(LOCATIONS_ENV, "").strip():
        return
    import jax  # deferred: 1.6 s to import

    jax.config.update("jax_traceback_in_locations_limit", 0)


@functools.cache
def enable() -> Path | None:
    """Turn both caches on for this process (before the first compilation), and
    :func:`lean_locations`. Called by every command that evaluates and by the Python
    API's first evaluation (``sweeps.pipeline.evaluate_results``), so notebooks and
    scripts keep their programs too; a second call does nothing."""
    lean_locations()
    path = cache_dir()
    if path is None:
        return None
    try:
        (path / "xla").mkdir(parents=True, exist_ok=True)
        (path / "programs").mkdir(parents=True, exist_ok=True)
    except OSError:
        return None  # an unwritable cache costs time, never a failed run
    import jax  # deferred: 1.6 s to import

    from shacc_jax import program_cache  # deferred: 1.6 s to import

    jax.config.update("jax_compilation_cache_dir", str(path / "xla"))
    # Cache every program, however quick to compile: the small ones add up.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    try:
        _verified_xla_cache(path / "xla")
    except (ImportError, AttributeError):
        pass
    program_cache.set_dir(path / "programs")
    return path
