"""How a command that did not succeed ends: one line on stderr and an exit status.

The command line's one boundary (``cli.main``) hands every exception here:

======================================================  ======  =====================
fault                                                   status  line
======================================================  ======  =====================
bad input (``InputError``)                              2       source: field: rule
the machine refused (``HostError``, any ``OSError``:     1       path: cannot ... (why)
a full disk, a read-only or unreadable path)
out of memory (``MemoryError``)                         1       what to lower
the cluster's scheduler went away (``ClusterLost``)     1       scheduler, chunks kept
Ctrl-C (``KeyboardInterrupt``: only where the console   130     interrupted
script's handler, ``interrupt``, is not installed)
a bug of ours (any other exception)                     70      the exception, and
                                                                SHACC_DEBUG=1
======================================================  ======  =====================

``SHACC_DEBUG=1`` prints the traceback as well, for any of them.
"""

from __future__ import annotations

import os
import sys
import traceback

from geometry_precompute.errors import HostError, InputError, one_line

DEBUG_ENV = "SHACC_DEBUG"
BUG = 70  # EX_SOFTWARE of sysexits.h


def _say(line: str) -> None:
    try:
        print(one_line(line, 2000), file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def report(error: BaseException) -> int:
    """Print ``error`` as its one line (module docstring) and return the exit status."""
    from sweeps.distributed.cluster import ClusterLost  # deferred: 64 ms to import

    if os.environ.get(DEBUG_ENV, "").strip() not in ("", "0"):
        traceback.print_exception(error, file=sys.stderr)
    if isinstance(error, KeyboardInterrupt):
        _say("interrupted")
        return 130
    if isinstance(error, BrokenPipeError):
        # The reader of stdout went away (`shacc settings | head`): not an error of ours.
        _silence_stdout()
        return 0
    if isinstance(error, InputError):
        _say(f"error: {error}")
        return 2
    if isinstance(error, ClusterLost):
        _say(f"error: {error}")
        return 1
    if isinstance(error, HostError):
        _say(f"error: {error}")
        return 1
    if isinstance(error, OSError):
        where = error.filename if error.filename is not None else "<system>"
        _say(f"error: {HostError(where, 'go on', error.strerror or type(error).__name__)}")
        return 1
    if isinstance(error, MemoryError):
        _say("error: <memory>: out of memory; evaluate fewer scenes or starts at once, or "
             "lower SHACC_MEMORY_BUDGET")
        return 1
    if isinstance(error, ImportError):
        _say(f"error: <installation>: {error} (reinstall shacc with its dependencies)")
        return 1
    _say(f"error: internal error: {type(error).__name__}: {error} (a bug in shacc: "
         f"please report it with the traceback that {DEBUG_ENV}=1 prints)")
    return BUG


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that Python's flush at exit has nothing to fail
    on."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass


CLOSED = "standard output is closed"


def guard_standard_streams() -> None:
    """Standard input, output and error that were closed when the command started
    (``shacc settings >&-``) are opened on /dev/null, so that no file the command opens
    later takes their numbers (a result written to "standard output" would land in it);
    Python's ``sys.stdout`` stays None then, which :class:`GuardedStdout` reports as
    ``<stdout>: cannot write (standard output is closed)``, and a closed stderr
    swallows the messages, not the exit status."""
    for fd, mode in ((0, os.O_RDONLY), (1, os.O_WRONLY), (2, os.O_WRONLY)):
        try:
            os.fstat(fd)
        except OSError:
            try:
                opened = os.open(os.devnull, mode)
                if opened != fd:
                    os.dup2(opened, fd)
                    os.close(opened)
            except OSError:
                pass
    if sys.stderr is None:
        try:
            sys.stderr = open(os.devnull, "w")  # kept for the process's life
        except OSError:
            pass


class _ClosedBuffer:
    """The ``buffer`` of a closed stdout: every write is the fault of the machine."""

    def write(self, data):
        raise HostError("<stdout>", "write", CLOSED)

    def flush(self):
        raise HostError("<stdout>", "write", CLOSED)


class GuardedStdout:
    """stdout whose write and flush failures (a full disk behind ``> FILE``, a stdout
    closed before the command began) are a :class:`HostError` naming ``<stdout>``, not
    a bare ``OSError`` or an ``AttributeError``; everything else is the wrapped
    stream's."""

    def __init__(self, stream):
        self._stream = stream

    def _guard(self, call, *args):
        try:
            return call(*args)
        except BrokenPipeError:
            raise
        except OSError as e:
            _silence_stdout()
            raise HostError("<stdout>", "write", e.strerror or type(e).__name__) from None

    def write(self, text):
        if self._stream is None:
            raise HostError("<stdout>", "write", CLOSED)
        return self._guard(self._stream.write, text)

    def flush(self):
        if self._stream is None:
            return None  # nothing was written: nothing to lose
        return self._guard(self._stream.flush)

    def __getattr__(self, name):
        if self._stream is None:
            if name == "buffer":
                return _ClosedBuffer()
            raise HostError("<stdout>", "write", CLOSED)
        return getattr(self._stream, name)


def flush_stdout() -> None:
    """Flush stdout now, inside the boundary: a full disk behind ``> FILE`` is then
    reported as a fault of the machine, not as Python's message at exit."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as e:
        _silence_stdout()
        raise HostError("<stdout>", "write", e.strerror or type(e).__name__) from None
