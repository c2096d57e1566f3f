"""Writing results: atomic files and the JSON of SPEC section 12a."""

from __future__ import annotations

import contextlib
import fnmatch
import json
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from geometry_precompute import InputError
from geometry_precompute.precompute import PrecomputeResult


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


def _nearest_existing(path: Path) -> Path:
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return p
    return Path(".")


def _check_parents(path: Path, option: str) -> None:
    """The folders above ``path`` exist or can be made, and can be written to."""
    base = _nearest_existing(path.parent)
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


def _umask() -> int:
    mask = os.umask(0)  # the only way to read it; set straight back
    os.umask(mask)
    return mask


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` as a file should be written.

    - a regular file (or a new name) is written to a temporary file beside it and
      renamed over it, so a reader never sees half of it; it gets the mode the user's
      umask gives a new file (not the temporary file's 0600);
    - a symbolic link is followed: its target is written, the link stays;
    - anything else that exists (a named pipe, a device such as /dev/null, a process
      substitution's /dev/fd/N) is opened and written directly: it cannot be renamed
      over, and its reader is waiting on it.
    """
    path = Path(path)
    if path.is_symlink():
        path = path.resolve()
    if path.exists() and not path.is_file():
        if path.is_dir():
            raise InputError(path, "<file>", "is a folder, expected a file name")
        with path.open("wb") as f:
            f.write(data)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
            os.fchmod(f.fileno(), 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_output(path: str | Path, data: bytes) -> None:
    """A command's ``--json`` output: ``-`` is standard output, else :func:`write_atomic`
    (announced on stderr, which keeps stdout for results)."""
    if str(path) == "-":
        sys.stdout.flush()
        sys.stdout.buffer.write(data)
        sys.stdout.flush()
        return
    write_atomic(path, data)


def write_json(path: str | Path, obj: Any) -> None:
    write_output(path, (json.dumps(clean_json(obj), indent=1) + "\n").encode())


def announce(path: str | Path) -> None:
    if str(path) != "-":
        print(f"wrote {path}", file=sys.stderr)


def human_output(json_target: str | None):
    """Where a command's readable summary goes: stdout, or stderr when the JSON itself
    goes to stdout (``--json -``), so that stdout parses."""
    return contextlib.redirect_stdout(sys.stderr) if json_target == "-" else \
        contextlib.nullcontext()


def precompute_json(r: PrecomputeResult) -> dict[str, Any]:
    """The precompute keys of SPEC section 12a."""
    ids = r.task_ids
    return {
        "scene": r.scene.name,
        "tasks": ids,
        "clutteredness": {"init": r.C_init, "final": r.C_final},
        "clusters": [[ids[i] for i in c] for c in r.meta_clusters()],
        "shrinking": {"iterations": r.iterations, "params": r.shrunk_params()},
        "metrics": {"d": r.d, "h": r.h},
    }
