"""What a shacc worker does as it starts: one Dask ``WorkerPlugin``.

The local cluster (:func:`sweeps.distributed.cluster.connect`) hands every worker a
:class:`WorkerSetup` when it creates it; distributed runs its ``setup`` in the new
worker process, before the worker joins the scheduler. It does four things:

- SIGINT is ignored: Ctrl-C reaches the whole process group, and the command, not each
  worker, decides what it means (the cluster is closed, ``interrupted``);
- a precompute worker runs at nice 5: with one per core, the precompute would otherwise
  take CPU time from the evaluation worker's compilation and from the host loop that
  drives the accelerator, which every chunk waits on;
- an evaluation worker configures JAX's runtime (``shacc_jax.configure_runtime``)
  before anything of it starts JAX;
- an evaluation worker given a warm-up (the first chunk's job and one of its scenes)
  begins it at once, in a thread (:class:`sweeps.distributed.evaluation_worker.EarlyWarmUp`): JAX's
  start, the accelerator's and the program's load or compilation then overlap the
  start of the other workers. The sweep's warm-up task takes it
  (``evaluation_worker.early_warm_up``).

The worker's environment (its GPU, ``JAX_PLATFORMS``, the allocator) is not set here
but by its nanny, before the process starts: the nanny also refreshes dask's config
from it, which a plugin running inside the worker comes too late for.

A worker started apart (``dask worker ... --preload sweeps.distributed.worker_setup``) gets the
same setup, without a warm-up (:func:`dask_setup`).
"""

from __future__ import annotations

import contextlib
import os
import signal
from typing import TYPE_CHECKING, Any

from distributed.diagnostics.plugin import WorkerPlugin

from sweeps.distributed.kinds import EVALUATE, PLUGIN, PRECOMPUTE

if TYPE_CHECKING:
    from sweeps.distributed.evaluation_worker import ChunkJob, EarlyWarmUp


class WorkerSetup(WorkerPlugin):
    """The setup of one shacc worker (module docstring). ``warm_up``: ``(job, scene)``
    of :func:`sweeps.distributed.evaluation_worker.warm_up`, begun as an evaluation worker starts;
    None: no early warm-up.

    >>> WorkerSetup().name
    'shacc-setup'
    """

    name = PLUGIN

    def __init__(self, warm_up: tuple[ChunkJob, Any] | None = None) -> None:
        self.warm_up = warm_up
        self.early: EarlyWarmUp | None = None

    def setup(self, worker) -> None:
        with contextlib.suppress(ValueError):  # not the main thread: nothing to do
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        resources = worker.state.total_resources or {}
        if PRECOMPUTE in resources:
            with contextlib.suppress(OSError):
                os.nice(5)
        elif EVALUATE in resources:
            # JAX's runtime before anything of this worker starts JAX (the pinned CPU
            # code generation: shacc_jax/runtime.py).
            from shacc_jax import configure_runtime  # deferred: 1.1 s to import

            configure_runtime()
            if self.warm_up is not None:
                # deferred: importing it takes 106 ms
                from sweeps.distributed.evaluation_worker import EarlyWarmUp

                self.early = EarlyWarmUp(*self.warm_up).start()


def dask_setup(worker) -> None:
    """``dask worker --preload sweeps.distributed.worker_setup``: a worker started apart gets the
    local workers' setup (SIGINT ignored, nice 5 for ``--resources precompute=1``)."""
    WorkerSetup().setup(worker)
