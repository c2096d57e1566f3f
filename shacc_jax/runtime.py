"""The process's JAX runtime, configured once, visibly, by whoever starts the work.

Importing ``shacc_jax`` (or ``geometry_precompute``, or ``sweeps``) changes no
environment variable and no JAX setting. Two things must nevertheless be in place
before JAX starts its CPU backend, because the backend reads them once, as it starts:

- the pinned CPU code generation (``determinism.FLAG`` in ``XLA_FLAGS`` on x86-64),
  without which a rollout's last bits depend on its position in the batch;
- the number of CPU devices (:func:`cpu_devices`), over which the stepped users'
  evaluation spreads its scenes.

:func:`configure_runtime` sets both. The entry points call it before anything else
touches JAX: the console script (``sweeps.app.launch``), each sweep worker as it starts
(``sweeps.distributed.worker_setup``), the Python API's evaluations (``sweeps.pipeline``, which
the notebooks use), ``shacc_jax.plan`` (so a library user's ``shacc_jax.run`` gets it
too) and the test suite (``tests/conftest.py``). Called again it does nothing; called
after JAX has started it can change nothing, and says so once, as a warning, where the
code generation is not pinned (the results are then still right, but their last bits
may differ from the command line's).
"""

from __future__ import annotations

import os
import platform
import warnings
from dataclasses import dataclass

import jax
from jax._src import xla_bridge

from . import determinism

DEVICES_ENV = "JAX_NUM_CPU_DEVICES"


@dataclass(frozen=True)
class Runtime:
    """What :func:`configure_runtime` found or set.

    :param pinned: CPU programs are compiled with ``determinism.FLAG``.
    :param cpu_devices: the CPU devices it asked JAX for; 0 where it left the number
        to the user (``JAX_NUM_CPU_DEVICES``, ``jax_num_cpu_devices``) or to JAX.
    :param late: JAX had started before the first call: nothing could be set.
    """

    pinned: bool
    cpu_devices: int
    late: bool


_RUNTIME: Runtime | None = None


def cpu_devices(cores: int | None = None) -> int:
    """How many XLA CPU devices a process starts with: half the cores the process may
    use, at least two, at most the cores. The stepped users' loop is a chain of small
    fusions that one device cannot spread over many cores, while devices run their
    shares of the scenes side by side (measured on 2 cores, 108 000 rollouts: 1 device
    9.2e4 rollouts/s, 2 devices 1.17e5; on 16 cores, 432 000 rollouts, 1, 2, 4, 8, 16
    devices: 4.0e4, 7.8e4, 1.44e5, 2.44e5, 2.10e5).

    >>> cpu_devices(1), cpu_devices(2), cpu_devices(4), cpu_devices(16)
    (1, 2, 2, 8)
    """
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") \
            else os.cpu_count() or 1
    return max(1, min(cores, max(2, cores // 2)))


def _started() -> bool:

    return bool(xla_bridge.backends_are_initialized())


def configure_runtime() -> Runtime:
    """Pin the CPU code generation and choose the CPU device count, before JAX starts
    (module docstring); once per process. Returns what was found or set.

    Example::

        from shacc_jax import configure_runtime
        configure_runtime()          # first, before anything else uses JAX
    """
    global _RUNTIME
    if _RUNTIME is not None:
        return _RUNTIME

    flags = os.environ.get("XLA_FLAGS", "")
    pinned_flags, pinned = determinism.pinned_flags(flags, platform.machine())
    if _started():
        # Too late to set anything: the backend read XLA_FLAGS as it started (from this
        # environment, unless someone changed it since).
        late_pinned = determinism.FLAG in flags.split()
        if not late_pinned and platform.machine().lower() in determinism.X86_64:
            warnings.warn("JAX started before shacc_jax.configure_runtime(): its CPU "
                          "programs are compiled for this processor's whole instruction "
                          "set, so results may differ in their last bits from the command "
                          "line's; call configure_runtime() before anything else uses JAX",
                          RuntimeWarning, stacklevel=2)
        _RUNTIME = Runtime(late_pinned, 0, True)
        return _RUNTIME
    os.environ["XLA_FLAGS"] = pinned_flags
    n = 0
    chosen: object = jax.config.jax_num_cpu_devices  # type: ignore[attr-defined]
    if chosen == -1 and not os.environ.get(DEVICES_ENV, "").strip():  # -1: JAX's one
        n = cpu_devices()
        jax.config.update("jax_num_cpu_devices", n)
    _RUNTIME = Runtime(pinned, n, False)
    return _RUNTIME


def configured() -> Runtime | None:
    """The runtime :func:`configure_runtime` set up in this process, None before."""
    return _RUNTIME
