"""Ctrl-C at any moment: the line ``interrupted``, exit status 130, nothing written after
it, no temporary file and no process left.

Python turns SIGINT into a KeyboardInterrupt raised wherever the main thread happens
to be, which went wrong in every way: a traceback while modules were imported, an
exception swallowed by a callback inside JAX (the command ran on to exit 0 and wrote
its output), and a crash at exit while XLA's compiler threads were still running
(the interpreter tore down under them: a segmentation fault, 14 times out of 14).

So the command line never lets SIGINT become an exception. :func:`install`, the first
thing ``shacc`` does, blocks SIGINT in the main thread (threads started later,
JAX's and XLA's included, inherit the mask) and starts one thread that waits for it
with ``sigwait``. On Ctrl-C that thread, holding ``fileio.COMMIT`` (so no output file
is being renamed into place and no JSON is half written to stdout), removes the
temporary files of writes under way, silences stdout, prints ``interrupted`` and ends
the process with ``os._exit(130)``: no Python clean-up runs, nothing can run after
the line, and the process ends as it would on SIGKILL. Worker processes end with it
as they do then (the local cluster's workers, ``sweep``'s and ``reproduce``'s, hold a
pipe from their nanny and the fork server one from each worker: tested with SIGKILL
and with Ctrl-C).

Only the console script installs this; a Python program that calls
``sweeps.app.cli.main`` keeps Python's own KeyboardInterrupt (and ``main`` reports it as
``interrupted``, status 130).
"""

from __future__ import annotations

import os
import signal
import sys
import threading

_INSTALLED = False


def install() -> None:
    """Handle Ctrl-C (SIGINT) as the module docstring says, from now on, in this
    process. Call it before any other thread starts."""
    global _INSTALLED
    if _INSTALLED or not hasattr(signal, "pthread_sigmask"):
        return
    # Where the main thread receives it after all (multiprocessing's resource tracker
    # unblocks SIGINT once it has spawned its process), the same end, as soon as the
    # main thread runs Python again.
    signal.signal(signal.SIGINT, lambda *_: end(130, "interrupted"))
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    threading.Thread(target=_wait, name="shacc-ctrl-c", daemon=True).start()
    _INSTALLED = True


def reblock() -> None:
    """Block SIGINT in the calling thread again, after code that unblocked it
    (starting multiprocessing's resource tracker does)."""
    if _INSTALLED:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now (before the first worker process),
    writing to /dev/null, and block SIGINT again after it. Its start unblocks SIGINT
    in the calling thread, so that every process spawned afterwards (the fork server,
    the workers) would receive Ctrl-C while it imports its modules and print
    a KeyboardInterrupt traceback; and once the command ends on Ctrl-C it would report
    the worker queues' semaphores as leaked, after the line ``interrupted``."""
    from multiprocessing import resource_tracker  # deferred: 12 ms to import

    # The tracker inherits file descriptor 2: /dev/null for the moment it is spawned.
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        resource_tracker.ensure_running()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)
        reblock()


def _wait() -> None:
    signal.sigwait({signal.SIGINT})
    try:
        end(130, "interrupted")
    finally:  # `end` does not return; should it ever raise, the process still ends
        os._exit(130)


def end(status: int, line: str) -> None:
    """End this process now with ``line`` on stderr and exit ``status``, as Ctrl-C
    does (module docstring)."""
    # Only a process that imported `fileio` can be writing (importing it here could
    # wait on the main thread's import lock): the interrupt lands within milliseconds
    # of start-up, before the command line is imported. The module may be in
    # sys.modules half imported (the main thread is running its first lines): without
    # its lock or its list of pending files, nothing has been written through it yet.
    fileio = sys.modules.get("geometry_precompute.fileio")
    commit = getattr(fileio, "COMMIT", None)
    if commit is not None:
        commit.acquire()  # held until the process ends: no rename, no write after
        abandon = getattr(fileio, "abandon_pending", None)
        if abandon is not None:
            abandon()
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
    try:
        os.write(2, (line + "\n").encode())
    except OSError:
        pass
    os._exit(status)
