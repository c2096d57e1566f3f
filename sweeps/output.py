"""Writing results: atomic files and the one-scene JSON (reference/outputs)."""

from __future__ import annotations

import contextlib
import datetime
import fnmatch
import json
import math
import os
import platform
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from geometry_precompute import HostError, InputError
from geometry_precompute.fileio import COMMIT, write_atomic
from geometry_precompute.precomputing import PrecomputeResult


def clean_json(x: Any) -> Any:
    """JSON-safe: NaN/inf become null, numpy scalars plain Python."""
    if isinstance(x, dict):
        return {str(k): clean_json(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [clean_json(v) for v in x]
    if hasattr(x, "tolist"):
        return clean_json(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def nearest_existing(path: Path) -> Path:
    """``path`` or the nearest of its parents that exists (``.`` at worst)."""
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return p
    return Path(".")


def _check_parents(path: Path, option: str) -> None:
    """The folders above ``path`` exist or can be made, and can be written to."""
    base = nearest_existing(path.parent)
    if not base.is_dir():
        raise InputError(path, option, f"{base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise InputError(path, option, f"folder {base} is not writable")


def check_output_file(path: str | Path, option: str) -> Path:
    """Before any work: ``path`` can become a file (missing folders are made)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(path, option, "is a folder, expected a file name")
    _check_parents(path, option)
    if path.exists() and not os.access(path, os.W_OK):
        raise InputError(path, option, "exists and is not writable")
    return path


def check_output_dir(path: str | Path, option: str, own: tuple[str, ...] = ()) -> Path:
    """Before any work: ``path`` is, or can become, a folder this command owns.

    A folder that exists must be empty or hold only names matching the glob patterns
    ``own`` (what this command writes there), so a rerun resumes or overwrites its
    own results and never mixes them with someone else's files.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(path, option, "is a file, expected a folder")
    if path.is_dir():
        if not os.access(path, os.W_OK | os.X_OK):
            raise InputError(path, option, "folder is not writable")
        other = sorted(p.name for p in path.iterdir()
                       if not any(fnmatch.fnmatch(p.name, pat) for pat in own))
        if other:
            raise InputError(path, option, f"folder holds files this command did not write "
                             f"({', '.join(other[:3])}{', ...' if len(other) > 3 else ''}); "
                             f"use an empty or new folder")
    else:
        _check_parents(path / "x", option)
    return path


def stdout_alias(path: str) -> str:
    """``-`` where ``path`` names this process's standard output under another name
    (``/dev/stdout``, ``/dev/fd/1``, the file or pipe that ``> FILE`` or ``| jq``
    opened), else ``path``: a JSON written there is then written as ``--json -``
    writes it, with the readable summary on stderr, not mixed into it.

    >>> stdout_alias("-"), stdout_alias("out.json")
    ('-', 'out.json')
    """
    if path == "-":
        return path
    try:
        target, out = os.stat(path), os.fstat(1)
    except (OSError, ValueError):
        return path
    same = (target.st_dev, target.st_ino) == (out.st_dev, out.st_ino)
    return "-" if same else path


def write_output(path: str | Path, data: bytes) -> None:
    """A command's ``--json`` output: ``-`` is standard output, else :func:`write_atomic`
    (announced on stderr, which keeps stdout for results)."""
    if str(path) == "-":
        # Whole, before a Ctrl-C ends the command (fileio.COMMIT), or not at all.
        with COMMIT:
            try:
                sys.stdout.flush()
                sys.stdout.buffer.write(data)
                sys.stdout.flush()
            except (BrokenPipeError, HostError):
                raise
            except OSError as e:
                raise HostError("<stdout>", "write", e.strerror or type(e).__name__) from None
        return
    write_atomic(path, data)


def write_json(path: str | Path, obj: Any) -> None:
    write_output(path, (json.dumps(clean_json(obj), indent=1) + "\n").encode())


def announce(path: str | Path) -> None:
    if str(path) != "-":
        print(f"wrote {path}", file=sys.stderr)


class _Aside:
    """stderr for a summary that is not the command's result: a write it refuses (a
    full or closed stderr) loses the summary, never the result on stdout."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except (OSError, ValueError, AttributeError):
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except (OSError, ValueError, AttributeError):
            pass


def human_output(json_target: str | None):
    """Where a command's readable summary goes: stdout, or stderr when the JSON itself
    goes to stdout (``--json -``), so that stdout parses; there a stderr that cannot be
    written loses the summary, not the JSON."""
    return contextlib.redirect_stdout(_Aside(sys.stderr)) if json_target == "-" else \
        contextlib.nullcontext()


_COMMAND: list[str] | None = None


def record_command(argv: Sequence[str]) -> None:
    """The arguments ``main`` was called with, for ``provenance`` (``sys.argv`` is the
    caller's when ``main`` is called from Python)."""
    global _COMMAND
    _COMMAND = list(argv)


def provenance(device: bool = False) -> dict[str, Any]:
    """What produced a result: the command line, the versions of shacc and of what it
    runs on, the machine and the time; with ``device``, JAX's backend and device too
    (a sweep's client never starts JAX: its evaluation workers record theirs in every
    Parquet part)."""
    import importlib.metadata as md  # deferred: 62 ms to import

    versions: dict[str, str | None] = {}
    for name in ("shacc", "jax", "jaxlib", "numpy", "scipy", "pyarrow", "mujoco", "evosax",
                 "dask", "distributed"):
        try:
            versions[name] = md.version(name)
        except md.PackageNotFoundError:
            versions[name] = None
    argv = sys.argv[1:] if _COMMAND is None else _COMMAND
    out = {"command": shlex.join(["shacc", *argv]), "versions": versions,
           "python": platform.python_version(), "platform": platform.platform(),
           "host": platform.node(),
           "time": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
    if device:
        import jax  # deferred: 1.9 s to import

        dev = jax.devices()[0]
        out.update(backend=jax.default_backend(),
                   device=getattr(dev, "device_kind", str(dev)))
    return out


def precompute_json(r: PrecomputeResult) -> dict[str, Any]:
    """The precompute keys of the one-scene JSON (reference/outputs)."""
    ids = r.task_ids
    return {
        "scene": r.scene.name,
        "tasks": ids,
        "clutteredness": {"init": r.C_init, "final": r.C_final},
        "clusters": [[ids[i] for i in c] for c in r.meta_clusters()],
        "shrinking": {"iterations": r.iterations, "params": r.shrunk_params()},
        "metrics": {"d": r.d, "h": r.h},
    }
