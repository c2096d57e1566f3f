"""Files as the project reads and writes them: bounded reads, atomic writes, and the
cache folder. One place for each, used by both halves and the command line.

Reading: a text file (a scene, a sweep config) is read whole, but at most
:data:`MAX_TEXT_BYTES`; a larger file (or an endless one such as ``/dev/zero``) is
refused with the limit in the message, before any memory is spent on it. Parsed
documents are at most :data:`MAX_DEPTH` tables or arrays deep (:func:`check_depth`).

Writing (:func:`write_atomic`):

- a regular file (or a new name) is written to a temporary file beside it, flushed
  to disk and renamed over it, so a reader never sees half of it and a failure (a
  full disk, Ctrl-C) leaves the old file, or nothing, and no temporary file; it gets
  the mode the user's umask gives a new file;
- a symbolic link is followed: its target is written, the link stays;
- anything else that exists (a named pipe, a device such as ``/dev/null``, a process
  substitution's ``/dev/fd/N``) is opened and written directly: it cannot be renamed
  over, and its reader is waiting on it.

Every failure is a :class:`~geometry_precompute.errors.HostError` naming the path and
the operating system's reason. Renames happen under :data:`COMMIT`, a lock the
command line's Ctrl-C handler takes before it ends the process, so an interrupted
command has either renamed a file or left none (and removes its temporary files:
:func:`abandon_pending`).
"""

from __future__ import annotations

import hashlib
import os
import stat
import tempfile
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

from .errors import HostError, InputError

MAX_TEXT_BYTES = 8 * 2**20  # a scene or a sweep config
MAX_DEPTH = 32              # nested tables and arrays in one document

COMMIT = threading.Lock()
_PENDING: set[str] = set()  # temporary files being written by this process


def read_bytes_limited(path: str | Path, what: str, limit: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of ``path``, at most ``limit`` of them (InputError beyond, and for a
    path that cannot be read: missing, a folder, permission)."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            data = f.read(limit + 1)
    except FileNotFoundError:
        raise InputError(path, "<file>", f"no such file (expected {what})") from None
    except IsADirectoryError:
        raise InputError(path, "<file>", f"is a folder, expected {what}") from None
    except NotADirectoryError:
        raise InputError(path, "<file>", "a part of the path is a file, not a folder") from None
    except PermissionError:
        raise InputError(path, "<file>", "cannot be read (permission denied)") from None
    except OSError as e:
        raise InputError(path, "<file>", f"cannot be read ({e.strerror or e})") from None
    if len(data) > limit:
        raise InputError(path, "<file>", f"is larger than {limit // 2**20} MiB, the most "
                         f"{what} may be")
    return data


def check_depth(data, source: str, limit: int = MAX_DEPTH) -> None:
    """Refuse a parsed document (tables and lists) nested deeper than ``limit``;
    iterative, so any depth is checked without recursion."""
    stack = [(data, 0)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, dict | list | tuple):
            if depth >= limit:
                raise InputError(source, "<nesting>", f"tables and arrays nested deeper than "
                                 f"{limit} levels")
            children = value.values() if isinstance(value, dict) else value
            stack.extend((v, depth + 1) for v in children
                         if isinstance(v, dict | list | tuple))


def cache_home() -> Path:
    """``$XDG_CACHE_HOME/shacc`` (``~/.cache/shacc`` when it is unset): the folder of
    every cache this project keeps (precomputed scenes, compiled programs)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "shacc"


SEAL = b"shacc-sealed-1\0"


def seal(key: str, payload: bytes) -> bytes:
    """A cache entry: a header, the SHA-256 of ``key`` and ``payload``, then ``payload``
    (:func:`unseal` checks both)."""
    return SEAL + hashlib.sha256(key.encode() + b"\0" + payload).digest() + payload


def unseal(key: str, data: bytes | None) -> bytes | None:
    """The payload of a :func:`seal` entry written for ``key``; None for anything else:
    a truncated or damaged entry, another key's entry under this name, a file of
    another format. A cache treats None as a miss and builds the entry again."""
    if not data or not data.startswith(SEAL) or len(data) < len(SEAL) + 32:
        return None
    digest, payload = data[len(SEAL):len(SEAL) + 32], data[len(SEAL) + 32:]
    if hashlib.sha256(key.encode() + b"\0" + payload).digest() != digest:
        return None
    return payload


def _umask() -> int:
    mask = os.umask(0)  # the only way to read it; set straight back
    os.umask(mask)
    return mask


def _target(path: Path) -> tuple[Path, os.stat_result | None]:
    """Where writing ``path`` lands (a link followed) and what is there now."""
    try:
        st = os.stat(path)  # follows links; a loop raises ELOOP here
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise HostError.of(e, path, "write") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        return path, st  # a pipe, a device, /dev/fd/N: written in place
    return (Path(os.path.realpath(path)) if path.is_symlink() else path), st


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` as a file should be written (module docstring)."""
    path = Path(path)
    target, st = _target(path)
    if st is not None and stat.S_ISDIR(st.st_mode):
        raise HostError(path, "write", "it is a folder")
    if st is not None and not stat.S_ISREG(st.st_mode):
        try:
            with open(target, "wb") as f:
                f.write(data)
        except OSError as e:
            raise HostError(path, "write", e.strerror or type(e).__name__) from None
        return
    tmp = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
        _PENDING.add(tmp)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
            os.fchmod(f.fileno(), 0o666 & ~_umask())
        with COMMIT:
            os.replace(tmp, target)
            _PENDING.discard(tmp)
    except OSError as e:
        raise HostError(path, "write", e.strerror or type(e).__name__) from None
    finally:
        if tmp is not None and tmp in _PENDING:
            _PENDING.discard(tmp)
            Path(tmp).unlink(missing_ok=True)


def abandon_pending() -> None:
    """Remove the temporary files this process is writing (called with :data:`COMMIT`
    held, by the command line's Ctrl-C handler just before the process ends)."""
    for tmp in list(_PENDING):
        try:
            os.unlink(tmp)
        except OSError:
            pass


def read_toml(path: str | Path, what: str = "a TOML file") -> dict[str, Any]:
    """Parse a TOML file; anything that is not one (missing, a folder, unreadable,
    larger than :data:`MAX_TEXT_BYTES`, not UTF-8 text, bad syntax, nested deeper than
    :data:`MAX_DEPTH`) is an InputError naming the file, never a traceback."""
    path = Path(path)
    data = read_bytes_limited(path, what)
    try:
        parsed = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise InputError(path, "<file>", f"is not UTF-8 text (byte {e.start}); expected "
                         f"{what}") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(path, "<toml>", f"not valid TOML: {e}") from None
    except RecursionError:
        raise InputError(path, "<nesting>", f"tables and arrays nested deeper than "
                         f"{MAX_DEPTH} levels") from None
    check_depth(parsed, str(path))
    return parsed


def source_digest(files) -> str:
    """A SHA-256 of the files' names and contents in the order given: the version of
    the code that a cache entry's key holds."""
    h = hashlib.sha256()
    for f in files:
        f = Path(f)
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


# A cache file of another version of the code, unused this long, is removed.
STALE_AFTER_S = 24 * 3600
_PRUNED: set[tuple[str, str]] = set()


def mark_used(path: Path) -> None:
    """Note that a cache file was just used (its modification time, which
    :func:`prune_stale` reads): a file that another version of the code still uses is
    kept."""
    try:
        os.utime(path)
    except OSError:  # a read-only cache: nothing is pruned there either
        pass


def prune_stale(folder: Path, pattern: str, version: str | None, once: bool = True,
                after_s: float = STALE_AFTER_S) -> int:
    """Remove the files of ``folder`` matching ``pattern`` whose names do not hold
    ``-version-`` (the source digest of the code that writes them: a code change makes
    every older file unreachable; None: a name says no version, so every file may go)
    and that nothing has used for ``after_s`` seconds; returns how many it removed. A
    file that cannot be removed stays. With ``once``, only the first call of a process
    for a folder and pattern looks (a cache folder may hold a scene entry for every
    scene ever computed)."""
    if once:
        seen = (str(folder), pattern)
        if seen in _PRUNED:
            return 0
        _PRUNED.add(seen)
    removed = 0
    try:
        entries = list(folder.glob(pattern))
    except OSError:
        return 0
    now = time.time()
    for path in entries:
        if version is not None and f"-{version}-" in path.name:
            continue
        try:
            if now - path.stat().st_mtime > after_s:
                path.unlink()
                removed += 1
        except OSError:
            pass
    return removed
