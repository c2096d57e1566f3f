"""Where a sweep runs: a Dask distributed cluster (SPEC section 12).

Two kinds of worker, told apart by Dask resources:

- ``precompute``: one thread per CPU core, no JAX (``sweeps.workers``);
- ``evaluate``: one per GPU, pinned to it (``CUDA_VISIBLE_DEVICES``), or one on the
  CPU where there is no GPU (``sweeps.evaluation_worker``).

By default :func:`connect` starts a local cluster of both kinds in this process (the
scheduler and the nannies run in its event loop; each worker is a process of its own)
and closes it when the sweep ends, also on Ctrl-C and on errors. Worker processes
die with this process even when it is killed with SIGKILL: distributed's nanny hands
each a pipe whose closing makes it exit at once.

Given a scheduler address, it connects to an existing cluster instead, which it
neither starts nor stops. Workers started with ``--resources precompute=1`` take the
precompute and ``--resources evaluate=1`` the evaluation; a cluster whose workers
advertise neither runs every task on any worker.
"""

from __future__ import annotations

import contextlib
import logging
import os
import shutil
import signal
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass

from geometry_precompute import InputError

PRECOMPUTE = "precompute"
EVALUATE = "evaluate"
QUIET = {"DASK_LOGGING__DISTRIBUTED": "critical"}  # a closing cluster logs errors


@dataclass(frozen=True)
class Pool:
    """What :func:`connect` found: the client, the resources each kind of task asks
    for (None: any worker), and how many threads take each kind."""

    client: object
    precompute: dict | None
    evaluate: dict | None
    precompute_threads: int
    evaluators: tuple[str, ...]  # addresses of the workers that take the evaluation

    @property
    def evaluate_workers(self) -> int:
        return len(self.evaluators)

    @property
    def dashboard(self) -> str | None:
        return getattr(self.client, "dashboard_link", None)


def local_gpus() -> list[str]:
    """This host's GPUs, as CUDA_VISIBLE_DEVICES values: those that variable lists when
    set, else those ``nvidia-smi -L`` lists; none when JAX_PLATFORMS asks for the CPU."""
    if os.environ.get("JAX_PLATFORMS", "").strip().lower() == "cpu":
        return []
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    if visible is not None:
        return [v.strip() for v in visible.split(",") if v.strip() and v.strip() != "-1"]
    smi = shutil.which("nvidia-smi")
    if smi is None:
        return []
    try:
        listed = subprocess.run([smi, "-L"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired):
        return []
    return [str(i) for i, line in enumerate(listed.stdout.splitlines())
            if line.startswith("GPU ")]


def dask_setup(worker) -> None:
    """Preloaded into every local worker process: Ctrl-C reaches the whole process group,
    and the command, not each worker, decides what it means (the cluster is closed).
    The precompute workers run at a lower priority (nice 5): with one per core, they
    would otherwise take CPU time from the evaluation worker's compilation and from the
    host loop that drives the accelerator, which every chunk waits on. (Starting JAX on
    the evaluation worker here, in the foreground or in a thread, made the sweep no
    faster: measured, benchmarks/RESULTS.md.)"""
    with contextlib.suppress(ValueError):  # not the main thread: nothing to do
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    if PRECOMPUTE in (worker.state.total_resources or {}):
        with contextlib.suppress(OSError):
            os.nice(5)



def _local(workers: int | None) -> tuple[object, int, int]:
    from distributed import Nanny, Scheduler, SpecCluster

    n_cpu = workers or os.cpu_count() or 1
    gpus = local_gpus()
    # Workers log nothing below CRITICAL: a closing cluster makes them log connection
    # errors (with tracebacks) that are no error of the sweep's; task errors reach the
    # command through their futures.
    base = {"nthreads": 1, "preload": ["sweeps.cluster"], "silence_logs": logging.CRITICAL}
    spec = {f"precompute-{i}": {"cls": Nanny, "options": {
        **base, "resources": {PRECOMPUTE: 1}, "env": dict(QUIET)}} for i in range(n_cpu)}
    evals = [{"CUDA_VISIBLE_DEVICES": g} for g in gpus] or [{"JAX_PLATFORMS": "cpu"}]
    for i, env in enumerate(evals):
        spec[f"evaluate-{i}"] = {"cls": Nanny, "options": {
            **base, "resources": {EVALUATE: 1}, "memory_limit": 0,
            "env": {**QUIET, **env}}}
    scheduler = {"cls": Scheduler, "options": {"dashboard_address": ":0"}}
    cluster = SpecCluster(workers=spec, scheduler=scheduler, silence_logs=logging.CRITICAL,
                          name="shacc-sweep")
    return cluster, n_cpu, len(evals)


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None,
            timeout: float = 60.0) -> Iterator[Pool]:
    """A :class:`Pool` on a new local cluster (``scheduler`` None; ``workers``: its
    precompute processes, default one per core) or on the cluster at ``scheduler``."""
    import warnings

    from distributed import Client

    logging.getLogger("distributed").setLevel(logging.ERROR)
    cluster = None
    with warnings.catch_warnings():
        # distributed warns when a port is taken (it picks another) or bokeh is missing.
        warnings.simplefilter("ignore")
        if scheduler is None:
            cluster, n_cpu, n_eval = _local(workers)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=timeout)
            except (OSError, TimeoutError, ValueError) as e:
                raise InputError("<arguments>", "--scheduler", f"no Dask scheduler answered at "
                                 f"{scheduler!r} ({e})") from None
    try:
        if cluster is None:
            pool = _remote(client, scheduler, timeout)
        else:
            client.wait_for_workers(n_cpu + n_eval, timeout=timeout)
            info = client.scheduler_info(n_workers=-1)["workers"]
            pool = Pool(client, {PRECOMPUTE: 1}, {EVALUATE: 1}, n_cpu,
                        tuple(a for a, w in info.items() if w["resources"].get(EVALUATE)))
        yield pool
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            client.close()
            if cluster is not None:
                cluster.close()


def _remote(client, scheduler: str, timeout: float) -> Pool:
    try:
        client.wait_for_workers(1, timeout=timeout)
    except TimeoutError:
        raise InputError("<arguments>", "--scheduler", f"the scheduler at {scheduler!r} has no "
                         f"workers after {timeout:.0f} s; start some (README: \"Sweeps on a "
                         "cluster\")") from None
    from .config import installed_version

    versions = client.run(installed_version)
    mine = installed_version()
    odd = {w: v for w, v in versions.items() if v != mine}
    if odd:
        w, v = next(iter(odd.items()))
        raise InputError("<arguments>", "--scheduler", f"worker {w} has shacc {v}, this "
                         f"machine {mine}; install the same version on every worker")
    info = client.scheduler_info(n_workers=-1)["workers"]

    def having(name: str) -> dict[str, dict]:
        return {a: w for a, w in info.items() if w.get("resources", {}).get(name)}

    pre, ev = having(PRECOMPUTE), having(EVALUATE)
    return Pool(client, {PRECOMPUTE: 1} if pre else None, {EVALUATE: 1} if ev else None,
                sum(w.get("nthreads", 1) for w in (pre or info).values()),
                tuple(ev or info))

