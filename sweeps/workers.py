"""The precompute's worker processes (CPU only, no JAX).

Started with spawn (forking a process in which JAX runs threads can deadlock), and
they ignore SIGINT: Ctrl-C reaches the whole process group, and the command, not each
worker, decides what an interruption means (one line, exit 130, the pool shut down).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import signal
from concurrent.futures import ProcessPoolExecutor


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def precompute_pool(workers: int | None):
    """A process pool that, on any exception (Ctrl-C included), drops its queued tasks
    and waits only for the running ones, so no worker outlives the command."""
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_ignore_sigint)
    try:
        yield pool
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
