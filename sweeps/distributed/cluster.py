"""Where a sweep runs: a Dask distributed cluster (reference/outputs).

Two kinds of worker, told apart by Dask resources:

- ``precompute``: one thread each, no JAX (``geometry_precompute.batch``); a local
  cluster starts :func:`default_precompute_workers` of them;
- ``evaluate``: one per GPU, pinned to it (``CUDA_VISIBLE_DEVICES``), or one on the
  CPU where there is no GPU (``sweeps.distributed.evaluation_worker``).

By default :func:`connect` starts a local cluster in this process (the scheduler and
the nannies run in its event loop; each worker is a process of its own, forked from a
server that has imported the workers' modules once, :func:`start_fork_server`) and
closes it when the command ends, also on Ctrl-C and on errors. It is the one place
where shacc starts processes: ``shacc sweep`` and ``shacc reproduce`` (precompute
workers only) both start their workers here. Each worker is set up by one Dask plugin
(``worker_setup.WorkerSetup``: SIGINT ignored, the precompute at nice 5, the
evaluation worker's warm-up begun with its process); its environment (its GPU, the
allocator) is its nanny's. Worker processes die with this process even when it is
killed with SIGKILL: distributed's nanny hands each a pipe whose closing makes it exit
at once, and the fork server exits when the last of them has.

Given a scheduler address, it connects to an existing cluster instead, which it
neither starts nor stops. Workers started with ``--resources precompute=1`` take the
precompute and ``--resources evaluate=1`` the evaluation; a cluster whose workers
advertise neither runs every task on any worker.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import os
import shutil
import subprocess
import threading
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import CancelledError
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from tornado import web

from geometry_precompute import InputError
from sweeps.distributed.interrupt import start_resource_tracker
from sweeps.distributed.kinds import EVALUATE, PRECOMPUTE

if TYPE_CHECKING:
    from distributed import Client

QUIET = {"DASK_LOGGING__DISTRIBUTED": "critical"}  # a closing cluster logs errors


@dataclass(frozen=True)
class Pool:
    """What :func:`connect` found: the client, the resources each kind of task asks
    for (None: any worker), and how many threads take each kind."""

    client: Client
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


class ClusterLost(RuntimeError):
    """The sweep's Dask scheduler went away while the sweep ran (killed, its host down,
    the network cut). What was written stays; the same command resumes from there."""


def lost_scheduler(client, error: BaseException) -> bool:
    """Whether ``error``, raised while a sweep waited on its tasks, means that the
    connection to the scheduler is gone (not a task's own error, nor the disk's)."""

    from distributed.comm.core import CommClosedError  # deferred: 1.2 s to import

    if isinstance(error, CommClosedError):
        return True
    # (TimeoutError is an OSError.)
    return isinstance(error, CancelledError | OSError) and client.status != "running"


# Seconds without any worker for a kind of task the sweep needs before the command says
# so, and how often it looks (a cluster started apart: local workers are replaced).
NO_WORKER_PATIENCE = 30.0
NO_WORKER_CHECK = 2.0


@contextlib.contextmanager
def watch_workers(pool: Pool, where: str, say) -> Iterator[None]:
    """While the block runs, look every :data:`NO_WORKER_CHECK` s whether some worker of
    the cluster at ``where`` offers each resource the sweep's tasks ask for. When one has
    been missing for :data:`NO_WORKER_PATIENCE` s (its only GPU host went down, say),
    ``say`` one line, once per absence: the tasks wait for such a worker, which Dask
    gives them as soon as one joins, and without the line a stalled bar is all a user
    would see."""

    kinds = [k for k, r in ((PRECOMPUTE, pool.precompute), (EVALUATE, pool.evaluate)) if r]
    stop = threading.Event()

    def run() -> None:
        missing: dict[str, list] = {}  # kind -> [since, said]
        while not stop.wait(NO_WORKER_CHECK):
            if pool.client.status != "running":  # the scheduler is gone: the sweep says so
                return
            try:
                workers = pool.client.scheduler_info(n_workers=-1)["workers"].values()
            except Exception:
                return
            have = {k for w in workers for k, v in (w.get("resources") or {}).items() if v}
            now = time.monotonic()
            for kind in kinds:
                if kind in have:
                    missing.pop(kind, None)
                    continue
                since = missing.setdefault(kind, [now, False])
                if not since[1] and now - since[0] >= NO_WORKER_PATIENCE:
                    since[1] = True
                    say(f"waiting: no worker of the cluster at {where} has the {kind!r} "
                        f"resource (for {now - since[0]:.0f} s); the sweep goes on when one "
                        f"joins (dask worker {where} --resources {kind}=1); stopped, it "
                        "keeps the chunks written")

    watcher = threading.Thread(target=run, name="shacc-worker-watch", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        stop.set()
        # A query sent as the scheduler died waits out the client's connection timeout
        # (60 s) before it fails; the command does not wait for it (the thread is a
        # daemon and ends with the process).
        watcher.join(timeout=1.0)


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


# What every local worker imports, loaded once in the fork server (below) rather than by
# each new interpreter. Kept short: the server imports one module after another, and a
# long list (pandas, pyarrow, scipy, the mesh libraries) made the workers start later
# than spawning them did. scipy's rotations (every bake's first use, 0.5 s a worker on
# the H100 hosts) joined once `shacc sweep` started the server before its own imports
# (benchmarks/RESULTS.md). Never JAX: preloaded, it made every worker start 1.4 s later
# and the evaluation worker's warm-up end no sooner.
FORK_PRELOAD = ("distributed", "sweeps.distributed.worker_setup", "geometry_precompute.batch",
                "sweeps.distributed.evaluation_worker", "scipy.spatial.transform")
# What distributed's nanny sets before it starts a worker (its
# distributed.nanny.pre-spawn-environ defaults): the fork server imports NumPy, so they
# must be set before the server starts.
PRE_SPAWN = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
             "MALLOC_TRIM_THRESHOLD_": "65536"}


def start_fork_server() -> bool:
    """Have this process's local clusters fork their worker processes from a server that
    has imported :data:`FORK_PRELOAD` once (``multiprocessing``'s forkserver, through
    distributed's ``multiprocessing-method``), and start that server now, so that its
    imports run while this process goes on with its own. Idempotent. The server ends
    when this process and every worker forked from it have ended (it waits on a pipe
    that each of them holds), SIGKILL included. False where the platform has no fork
    server: the workers are then spawned, each importing anew. This module imports
    nothing heavy, so that ``shacc sweep`` can start the server as soon as its
    arguments are parsed, before it imports NumPy, dask and the rest."""
    import multiprocessing  # deferred: 11 ms to import
    import multiprocessing.forkserver  # deferred: 43 ms to import

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False

    for k, v in PRE_SPAWN.items():
        os.environ.setdefault(k, v)
    # The server and its workers are spawned with SIGINT still blocked: Ctrl-C is the
    # command's to handle (interrupt.py), never a traceback of theirs.
    start_resource_tracker()
    multiprocessing.get_context("forkserver").set_forkserver_preload(list(FORK_PRELOAD))
    try:
        multiprocessing.forkserver.ensure_running()
        method = "forkserver"
    except OSError:  # no Unix socket or no process to be had: spawn, as distributed does
        method = "spawn"
    import dask  # after the server's start: its imports and these overlap

    dask.config.set({"distributed.worker.multiprocessing-method": method})
    return method == "forkserver"


def default_precompute_workers() -> int:
    """The local cluster's precompute workers when none are asked for: three quarters of
    the cores, at least one. More are slower: a worker's CPU time per scene grows with
    their number (shared caches and memory bandwidth), and the evaluation workers, the
    tables and the client need cores too. Measured with ``benchmarks/scaling.sh``
    (100 000 scenes, benchmarks/RESULTS.md): on 64 cores and 4 GPUs 32 and 48 workers
    took 40 s and 62 took 57 s; on 32 cores and 2 GPUs 24 took 55 s and 31 took 61 s.

    >>> default_precompute_workers() == max(1, (os.cpu_count() or 1) * 3 // 4)
    True
    """
    return max(1, (os.cpu_count() or 1) * 3 // 4)


def _local(workers: int | None, warm_up: tuple | None,
           evaluate: bool) -> tuple[object, int, int]:
    """The local cluster: ``workers`` precompute workers (default
    :func:`default_precompute_workers`) and, if
    ``evaluate``, one evaluation worker per GPU (one on the CPU where there is none)."""
    from distributed import Nanny, Scheduler, SpecCluster  # deferred: 1.1 s to import

    from sweeps.distributed.worker_setup import WorkerSetup  # deferred: 1.5 s to import

    start_fork_server()
    n_cpu = workers or default_precompute_workers()
    # Workers log nothing below CRITICAL: a closing cluster makes them log connection
    # errors (with tracebacks) that are no error of the sweep's; task errors reach the
    # command through their futures.
    base = {"nthreads": 1, "silence_logs": logging.CRITICAL}
    # This process's environment as it is now, as a spawned worker would inherit it (a
    # forked one has the fork server's, from when the server started).
    here = {**os.environ, **QUIET}
    spec = {f"precompute-{i}": {"cls": Nanny, "options": {
        **base, "resources": {PRECOMPUTE: 1}, "env": here, "plugins": (WorkerSetup(),)}}
        for i in range(n_cpu)}
    evals: list[dict] = []
    if evaluate:
        # An evaluation worker allocates GPU memory as it needs it: reserving 75 % of an
        # H100 up front took 0.9 s of every sweep's start (benchmarks/RESULTS.md); the
        # budget (shacc_jax.runplan) reads the allocator's limit either way. A user's
        # setting wins.
        alloc = {"XLA_PYTHON_CLIENT_PREALLOCATE":
                 os.environ.get("XLA_PYTHON_CLIENT_PREALLOCATE", "false")}
        evals = [{"CUDA_VISIBLE_DEVICES": g, **alloc} for g in local_gpus()] \
            or [{"JAX_PLATFORMS": "cpu"}]
    for i, env in enumerate(evals):
        spec[f"evaluate-{i}"] = {"cls": Nanny, "options": {
            **base, "resources": {EVALUATE: 1}, "memory_limit": 0, "env": {**here, **env},
            "plugins": (WorkerSetup(warm_up),)}}
    # The dashboard (bokeh) is built when it is first opened (_dashboard_on_demand).
    scheduler = {"cls": Scheduler, "options": {"dashboard_address": ":0", "dashboard": False}}
    cluster = SpecCluster(workers=spec, scheduler=scheduler, silence_logs=logging.CRITICAL,
                          name="shacc")
    _dashboard_on_demand(cluster)
    return cluster, n_cpu, len(evals)


def _dashboard_on_demand(cluster) -> None:
    """Build a local cluster's dashboard (bokeh) when a page of it is first asked for.
    Built with the scheduler, it took 1.0-1.3 s of every sweep's start on the H100
    hosts (importing bokeh), before any worker process was started; built in a thread
    once the workers were up, it slowed the scheduler as the sweep began
    (benchmarks/RESULTS.md). Its address is served from the start: the first request
    for any of its pages imports bokeh (in a thread, about a second), adds the
    dashboard to the scheduler's web server and is redirected to the page it asked
    for. distributed's own routes (/health, /metrics, /info, ...) are unaffected."""
    import asyncio  # deferred: 101 ms to import


    scheduler = cluster.scheduler
    app = scheduler.http_application  # distributed's RoutingApplication
    building: list = []  # the build, once asked for

    async def build() -> bool:
        try:
            dashboard = await asyncio.get_running_loop().run_in_executor(
                None, importlib.import_module, "distributed.dashboard.scheduler")
        except ImportError:
            return False
        dashboard.connect(app, scheduler.http_server, scheduler, prefix="/")
        app.applications.remove(on_demand)  # bokeh's pages answer from now on
        return True

    class Build(web.RequestHandler):
        async def get(self) -> None:
            if not building:
                building.append(asyncio.ensure_future(build()))
            if await asyncio.shield(building[0]):
                self.redirect(self.request.uri)
            else:
                self.set_status(404)
                self.finish("The Dask dashboard needs bokeh: pip install bokeh")

    # Asked only for paths that distributed's own routes do not take.
    on_demand = web.Application([(r"/.*", Build)])
    app.add_application(on_demand)


# Seconds a --scheduler has to answer: a connection refused is known at once, a host
# that does not answer (or a port where no Dask scheduler speaks) is given this long.
SCHEDULER_TIMEOUT = 10.0


def check_scheduler(address: str, timeout: float = SCHEDULER_TIMEOUT) -> None:
    """Refuse, before any work, a scheduler address that is not one, or where nothing
    listens (a refused connection is reported at once) or nothing answers within
    ``timeout`` seconds."""
    import socket  # deferred: 9 ms to import

    # deferred: importing it takes 1.2 s
    from distributed.comm.addressing import parse_address, parse_host_port


    def bad(rule: str) -> InputError:
        return InputError("<arguments>", "--scheduler", rule)

    try:
        scheme, location = parse_address(address, strict=True)
        host, port = parse_host_port(location) if scheme in ("tcp", "tls", "ws", "wss") \
            else (None, None)
    except (ValueError, TypeError) as e:
        raise bad(f"not a Dask scheduler address such as tcp://10.0.0.5:8786 ({e}), got "
                  f"{address!r}") from None
    if host is None:
        return
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except ConnectionRefusedError:
        raise bad(f"nothing listens at {address} (connection refused)") from None
    except TimeoutError:
        raise bad(f"no answer from {address} within {timeout:g} s") from None
    except OSError as e:
        raise bad(f"cannot reach {address} ({e.strerror or e})") from None
    # Something listens: it must be a Dask scheduler (a web server there answers the
    # handshake with bytes that Dask reads as a length of exabytes).
    client = _client(address, timeout)
    with contextlib.suppress(Exception):
        client.close()


def _client(address: str, timeout: float):
    """A distributed Client of the scheduler at ``address``, or the one-line error."""

    from distributed import Client  # deferred: 1.1 s to import


    logging.getLogger("distributed").setLevel(logging.ERROR)
    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return Client(address, timeout=timeout)
    except (OSError, TimeoutError, ValueError, MemoryError) as e:
        why = " ".join(str(e).split()) or type(e).__name__
        raise InputError("<arguments>", "--scheduler", f"no Dask scheduler answered at "
                         f"{address!r} within {timeout:g} s ({why})") from None


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None,
            timeout: float = 60.0, warm_up: tuple | None = None,
            evaluate: bool = True) -> Iterator[Pool]:
    """A :class:`Pool` on a new local cluster (``scheduler`` None; ``workers``: its
    precompute processes, default :func:`default_precompute_workers`; ``evaluate``:
    with evaluation workers)
    or on the cluster at ``scheduler``. ``warm_up``: ``(job, scene)`` of
    ``evaluation_worker.warm_up``, which a local cluster's evaluation workers begin as
    they start (``worker_setup.WorkerSetup``).

    >>> import inspect
    >>> list(inspect.signature(connect).parameters)
    ['scheduler', 'workers', 'timeout', 'warm_up', 'evaluate']
    """

    from distributed import Client  # deferred: 1.1 s to import

    logging.getLogger("distributed").setLevel(logging.ERROR)
    # Its failed reconnections, with tracebacks, when the scheduler is gone: the command
    # says that in one line (ClusterLost).
    logging.getLogger("distributed.client").setLevel(logging.CRITICAL)
    cluster: Any = None
    with warnings.catch_warnings():
        # distributed warns when a port is taken (it picks another) or bokeh is missing.
        warnings.simplefilter("ignore")
        if scheduler is None:
            cluster, n_cpu, n_eval = _local(workers, warm_up, evaluate)
            client = Client(cluster)
        else:

            client = _client(scheduler, SCHEDULER_TIMEOUT)
    try:
        if scheduler is not None:
            pool = _remote(client, scheduler, timeout)
        else:
            client.wait_for_workers(n_cpu + n_eval, timeout=timeout)
            info = client.scheduler_info(n_workers=-1)["workers"]
            pool = Pool(client, {PRECOMPUTE: 1}, {EVALUATE: 1} if n_eval else None, n_cpu,
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
    from sweeps.config import installed_version  # deferred: 362 ms to import

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

