"""The precompute's worker processes (CPU only, no JAX).

Started with spawn (forking a process in which JAX runs threads can deadlock). They
ignore SIGINT: Ctrl-C reaches the whole process group, and the command, not each
worker, decides what an interruption means (one line, exit 130, the pool shut down).
And they die with the command: on Linux each asks the kernel for SIGKILL when its
parent ends (``PR_SET_PDEATHSIG``), so a command killed with SIGKILL leaves no worker
behind (before, they waited on their task queue for ever, about 400 MB each).
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _worker_setup(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        if os.getppid() != parent:  # the parent ended before the request was made
            os._exit(1)


@contextlib.contextmanager
def precompute_pool(workers: int | None):
    """A process pool that, on any exception (Ctrl-C included), drops its queued tasks
    and waits only for the running ones, so no worker outlives the command."""
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_worker_setup, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
