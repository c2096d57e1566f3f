"""The traced evaluation program kept on disk (``jax.export``), off unless asked for.

JAX's persistent compilation cache skips XLA's compilation, but every new process
still traces and lowers the evaluation (about 1.6 s of Python on a CPU for the
vmapped Automaton, more than the rest of ``shacc evaluate`` together). This module
stores the lowered program itself, serialised by ``jax.export``, keyed by everything
that decides it: the source of this package and of the bake's schema, the jax and
jaxlib versions, the backend, x64 mode, the stack frames kept in source locations,
the static arguments and the input shapes and dtypes. A later
process with the same key deserialises the program and calls it; its compilation
then comes from the persistent cache. Any change to the code gives a new key; a file's
name holds the code's version, and the first program a process stores removes other
versions' programs that nothing has used for a day (``fileio.prune_stale``).

:func:`set_dir` turns it on (the command line does, beside the compilation cache);
a library user who never calls it traces as usual.
"""

from __future__ import annotations

import contextlib
import gc
import hashlib
import logging
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import jax
import jaxlib
from jax import export

from geometry_precompute import schema
from geometry_precompute.fileio import (
    mark_used,
    prune_stale,
    seal,
    source_digest,
    unseal,
    write_atomic,
)

_DIR: Path | None = None
_SOURCE_HASH: str | None = None
_LOADED: dict[str, Callable] = {}  # key -> the deserialised program, jitted, this process
# Each program a process prepares (traced or read back, then compiled) is told at INFO,
# with its seconds: a command's progress lines (``shacc reproduce`` shows them); a
# library user sees them only after configuring ``logging``.
LOG = logging.getLogger("shacc_jax.programs")
_QUICK: dict[str, Callable] = {}  # name -> the jitted function compiled with QUICK_OPTIONS
_QUICK_LOCK = threading.Lock()  # ahead()'s threads may ask for the same name at once

# A CPU program whose work is at most this many closed-form rollouts (a stepped or an
# intent mode's rollout counts as several: shacc_jax.runplan.LEVEL_COST) is compiled with
# LLVM's passes off (QUICK_OPTIONS). On the 2-core CPU a program then compiles 3-35 s
# faster and runs about 10x slower (74 us more a closed-form rollout), so below this
# size the compile time saved outweighs the run time lost (docs/DECISIONS.md,
# "Small CPU programs"). The answers are the same bits at either level: XLA fixes the
# arithmetic before LLVM, which may not reassociate or fuse without fast math, and the
# CPU code generation is pinned without FMA (tests/test_quick_compile.py).
QUICK_COMPILE_ROLLOUTS = 32_768
QUICK_OPTIONS = {"xla_backend_optimization_level": 0}


def set_dir(path: str | Path | None) -> None:
    """Keep exported programs in ``path`` (None turns the cache off)."""
    global _DIR
    _DIR = None if path is None else Path(path)


def get_dir() -> Path | None:
    """The folder in use, None when the cache is off."""
    return _DIR


def forget_loaded() -> None:
    """Drop the programs deserialised by this process (the next call reads the folder
    again, as a new process would)."""
    _LOADED.clear()


def release_compiled() -> None:
    """Free the machine code of every program this process compiled or loaded: the
    deserialised programs and JAX's in-memory caches (``jax.clear_caches``). The next
    evaluation of a shape loads its program again from the compilation cache (or
    compiles it, with the cache off).

    A process that compiles many programs needs this now and then: each CPU program
    maps its code into the process in many small regions (about 800 for an
    evaluation), and Linux allows 65 530 per process (``vm.max_map_count``). Past it,
    the next compilation fails inside XLA with a segmentation fault. The test suite
    releases after every module, and after any test that leaves 30 000 maps; a
    notebook that sweeps hundreds of settings in one kernel can call it between them."""
    _LOADED.clear()
    _QUICK.clear()
    jax.clear_caches()
    gc.collect()


def _source_hash() -> str:
    global _SOURCE_HASH
    if _SOURCE_HASH is None:
        _SOURCE_HASH = source_digest([*sorted(Path(__file__).parent.glob("*.py")),
                                      Path(schema.__file__)])
    return _SOURCE_HASH


def program_key(name: str, static: tuple, tree, leaves: list) -> str:
    """The cache key of an exported program: its name, the package's source, the JAX
    and jaxlib versions, the backend, the flags that change a trace (x64, the stack
    frames kept in source locations), the static arguments and the arguments' tree,
    shapes and dtypes."""

    flags: Any = jax.config  # its flags are attributes that type checkers do not see
    parts = [name, _source_hash(), jax.__version__, jaxlib.__version__,
             jax.default_backend(), str(flags.jax_enable_x64), repr(static), str(tree),
             # the stack frames kept in the program's source locations
             str(flags.jax_traceback_in_locations_limit),
             str(flags.jax_include_full_tracebacks_in_locations)]
    parts += [f"{tuple(x.shape)}:{x.dtype}" for x in leaves]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


def quick(work: int, leaves: list) -> bool:
    """Whether a program of ``work`` (closed-form rollouts, or rollouts weighted by their
    run time against one) on the device of ``leaves`` is compiled with
    :data:`QUICK_OPTIONS`: CPU programs of at most :data:`QUICK_COMPILE_ROLLOUTS`. An
    accelerator's programs keep XLA's defaults.

    >>> quick(400, []) == (jax.default_backend() == "cpu")
    True
    >>> quick(10**6, [])
    False
    """
    if work > QUICK_COMPILE_ROLLOUTS:
        return False
    first = leaves[0] if leaves else None
    if isinstance(first, jax.Array):
        return all(d.platform == "cpu" for d in first.devices())
    return jax.default_backend() == "cpu"


def _options(work: int | None, leaves: list) -> dict | None:
    """The compiler options of a program of ``work`` on the device of ``leaves``:
    :data:`QUICK_OPTIONS` where :func:`quick` picks it, else None (XLA's defaults; also
    for ``work`` None)."""
    return QUICK_OPTIONS if work is not None and quick(work, leaves) else None


def call(name: str, jitted: Callable, static: dict, args: tuple, out_example, *,
         work: int | None = None):
    """``jitted(*args, **static)`` through the exported program cache.

    ``jitted`` is a ``jax.jit`` function whose static arguments are ``static``; it
    takes the pytrees ``args`` and returns a pytree shaped like ``out_example`` (any
    instance of the output type: only its structure is used). ``work``: what the
    program evaluates, in closed-form rollouts, which decides its compiler options
    (:func:`quick`; None: XLA's defaults). Without a cache folder this is the plain
    call.
    """
    leaves, in_tree = jax.tree.flatten(args)
    if _DIR is None:
        return compiled_as(name, jitted, tuple(static), work, leaves)(*args, **static)
    run = _loaded(_DIR, name, jitted, static, in_tree, leaves, _options(work, leaves), work)
    return jax.tree.unflatten(jax.tree.structure(out_example), run(*leaves))


def compiled_as(name: str, jitted: Callable, static_names: tuple[str, ...],
                work: int | None, leaves: list) -> Callable:
    """The jitted function that a call of ``work`` on the arguments ``leaves`` runs
    when no cache folder is set: ``jitted`` itself, or for a program that
    :func:`quick` picks, the same function compiled with :data:`QUICK_OPTIONS` (one per
    ``name`` and process). :func:`call` uses it; so does code that calls a jitted
    function itself and wants the commands' choice of compiler options."""
    if _options(work, leaves) is None:
        return jitted
    with _QUICK_LOCK:
        fast = _QUICK.get(name)
        if fast is None:
            fast = _QUICK[name] = jax.jit(jitted.__wrapped__,  # type: ignore[attr-defined]
                                          static_argnames=static_names,
                                          compiler_options=QUICK_OPTIONS)
    return fast


@contextlib.contextmanager
def ahead(name: str, jitted: Callable, static: dict,
          calls: Sequence[tuple[tuple, int | None]]) -> Iterator[list[Future]]:
    """Compile, side by side in threads, the programs that ``call(name, jitted,
    static, args, ..., work=work)`` will run for each ``(args, work)`` of ``calls``.

    Yields one future per call, done when that call's program is compiled (calls of
    one program share it): wait for it, then make the call, which finds the program
    ready, so that a batch that needs several programs (the optimized mode's search,
    one per task count) compiles them together and runs the first while the others
    still compile. The programs are the ones :func:`call` would compile (the same
    options, through the exported cache when a folder is set), so nothing changes but
    when they compile. A compilation's error is raised by its future. On leaving,
    compilations not yet begun are cancelled and the running ones awaited.

    The threads take the caller's ``jax_enable_x64`` (a thread-local setting)."""
    flags: Any = jax.config  # its flags are attributes that type checkers do not see
    x64 = bool(flags.jax_enable_x64)

    def compile_one(args: tuple, work: int | None) -> None:
        with jax.enable_x64(x64):
            leaves, in_tree = jax.tree.flatten(args)
            program: Any
            if _DIR is None:
                program = compiled_as(name, jitted, tuple(static), work, leaves)
                program.lower(*args, **static).compile()
            else:
                _loaded(_DIR, name, jitted, static, in_tree, leaves, _options(work, leaves),
                        work)

    signatures = []  # the program of each call: its key, and its options
    for args, work in calls:
        leaves, in_tree = jax.tree.flatten(args)
        signatures.append((program_key(name, tuple(sorted(static.items())), in_tree, leaves),
                           _options(work, leaves) is not None))
    distinct = list(dict.fromkeys(signatures))
    pool = ThreadPoolExecutor(max(1, min(len(distinct), os.cpu_count() or 1)),
                              thread_name_prefix=f"compile-{name}")
    futures: dict[tuple, Future] = {}
    try:
        for sig, (args, work) in zip(signatures, calls, strict=True):
            if sig not in futures:
                futures[sig] = pool.submit(compile_one, args, work)
        yield [futures[sig] for sig in signatures]
    finally:
        for f in futures.values():
            f.cancel()
        pool.shutdown(wait=True)


def _loaded(folder: Path, name: str, jitted: Callable, static: dict, in_tree,
            leaves: list, options: dict | None, work: int | None = None) -> Callable:
    """The jitted program of a call, compiled for ``leaves``: this process's, else the
    one exported to ``folder``, else traced and exported now (each new one told on
    :data:`LOG`)."""
    key = program_key(name, tuple(sorted(static.items())), in_tree, leaves)
    loaded = key if options is None else f"{key}-quick"  # one export, either options
    run = _LOADED.get(loaded)
    if run is None:
        t0 = time.perf_counter()
        size = "" if work is None else f" ({work:,} rollouts of work)"
        LOG.info("%s program%s: preparing", name, size)
        version = _source_hash()[:16]
        path = folder / f"export-{name}-{version}-{key}.bin"
        exp = None
        try:
            payload = unseal(key, path.read_bytes())
        except OSError:
            payload = None
        if payload is not None:  # whole, and written for this key (fileio.seal)
            try:
                exp = export.deserialize(bytearray(payload))
                mark_used(path)
            except Exception:  # written by another jax: rebuilt
                exp = None
        traced = exp is None
        if exp is None:
            def flat(*xs):
                return tuple(jax.tree.leaves(jitted(*jax.tree.unflatten(in_tree, xs),
                                                    **static)))

            specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
            exp = export.export(jax.jit(flat))(*specs)
            _store(path, seal(key, bytes(exp.serialize())))
            # Any code change makes new keys: other versions' programs unused for a
            # day go.
            prune_stale(folder, "export-*.bin", version)
        run = jax.jit(exp.call, compiler_options=options)
        t1 = time.perf_counter()
        run.lower(*leaves).compile()  # the call finds it (a compilation cache hit, or XLA)
        LOG.info("%s program%s: %s in %.1f s, compiled in %.1f s", name, size,
                 "traced" if traced else "read back", t1 - t0,
                 time.perf_counter() - t1)
        _LOADED[loaded] = run
    return run


def _store(path: Path, data: bytes) -> None:
    try:
        write_atomic(path, data)
    except OSError:  # an unwritable cache costs time on the next run, never this one
        pass
