"""Running an evaluation: a :class:`RunPlan` computed once on the host, then executed
against the one jitted :func:`~shacc_jax.evaluation.evaluate`.

Every way of evaluating a bake (``shacc evaluate``, ``optimize``, ``reproduce``, a
sweep's evaluation worker, Python) goes through :func:`run`:

1. :func:`plan` decides, in NumPy and before anything is traced, everything about the
   run that is not a rollout: the static :class:`~geometry_precompute.schema.Layout`
   (with the backend's block size), the sweep points, the pieces of the start grid the
   memory budget allows, the devices the scenes are split over and their padding, and
   the fields copied back. It is a pure function of the bake's shapes and its
   arguments; ``shacc evaluate --plan`` prints it.
2. :func:`execute` runs the plan: each piece of starts, each device's share of the
   scenes (an accelerator's from its own host thread; several CPU devices as one
   program over a mesh of them, compiled once), through the exported program cache;
   the pieces and parts are joined once, and the per-scene metrics computed once, in
   double precision, over the joined rollouts (``host_metrics``).

Each rollout depends only on its own scene, start and task, so neither the pieces nor
the device split change an answer: every part holds at least two scenes and every piece
at least two starts, because XLA simplifies an axis of length one differently and a
rollout's last bits would then depend on its part (``determinism``; a test holds the
answers to a recording, bit for bit).

The memory budget: ``$SHACC_MEMORY_BUDGET`` (bytes; suffixes K, M, G allowed) if set,
else half of what the device has free (an accelerator's free memory, or the host's
available memory on a CPU).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import partial
from types import SimpleNamespace
from typing import Any, NamedTuple

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from geometry_precompute.errors import InputError
from geometry_precompute.schema import (
    ALL_MODES,
    GEOMETRY,
    INTENT_MODES,
    MODES,
    OPTIMIZED,
    PARAMS,
    Layout,
    batch_layout,
    lanes_per_block_default,
)

from . import program_cache
from .evaluation import evaluate
from .metrics import host_metrics
from .optimize import optimized_spaces, search, search_sizes
from .runtime import configure_runtime
from .types import Evaluation, Geometry, Params, Rollouts, SceneMetrics, Search

# Memory one rollout needs during evaluation (rollout outputs, the activation pass, the
# tracking blocks, and with collision checks each rollout's per-object windows and the
# checks' blocks), with a safety factor of about 1.2 over the largest measured: peak
# device memory on an H100 (10 000 and 1 000 random 10-task scenes) 251-393 bytes
# without checks and 2 194-3 051 with; XLA's memory analysis of the CPU program (100
# and 1 000 scenes) 1 004-1 089 and 3 554-5 420 (benchmarks/RESULTS.md, memory per
# rollout). Stepped users' program (the third key) holds only its queue's slots beside
# the outputs: on a CPU 172-254 bytes without checks and 190-482 with (1 000 and 100
# scenes, about 160 a rollout plus 10-35 MB of slots), on an H100 124-387 and 210-665
# (10 000 and 1 000 scenes).
BYTES_PER_ROLLOUT = {("accelerator", False, False): 600, ("accelerator", True, False): 3700,
                     ("cpu", False, False): 1300, ("cpu", True, False): 6500,
                     ("accelerator", False, True): 600, ("accelerator", True, True): 800,
                     ("cpu", False, True): 400, ("cpu", True, True): 700}
ENV = "SHACC_MEMORY_BUDGET"
# The stepped users on a CPU run on all its devices from this many rollouts (scenes x
# starts x tasks x modes x points) up; below it the program compiled for a second
# device costs more than the run it shares (docs/DECISIONS.md, issue 53).
CPU_SPLIT_ROLLOUTS = 500_000
MAX_BUDGET = 2**60  # bytes: an exbibyte, beyond any machine
_GEOMETRY_FIELDS = tuple(f.name for f in GEOMETRY)
_PARAM_FIELDS = tuple(f.name for f in PARAMS)


@dataclass(frozen=True)
class RunPlan:
    """How one evaluation runs, decided before anything is traced (:func:`plan`).

    ``layout``: the compiled program's static side, its block size resolved for the backend
    and its ``n_starts`` that of one piece. ``n_scenes``, ``n_starts``: the bake's S and N.
    ``n_points``: P sweep points over one geometry (None: Params of shape (S,)). ``pieces``:
    the first start of each piece of the start grid, ``starts_per_piece`` starts each (the
    last piece padded by repeating the grid's last start, so every piece has one shape and
    one program). ``devices``: where the scene parts run (one host thread per accelerator; CPU
    devices as one program);
    ``scenes_per_part`` scenes each, the scenes padded by repeating the last one to
    ``padded_scenes``. ``fields``: the Rollouts fields copied to the host (the others stay
    None). ``metrics``: whether :func:`execute` computes the per-scene metrics.
    ``bytes_per_piece`` of the ``budget`` (bytes), the estimate that chose the pieces.
    ``calls``: how many times the caller runs this plan (a sweep's chunks); with the
    pieces, the calls of one program, whose work together decides its compiler options."""

    layout: Layout
    n_scenes: int
    n_starts: int
    n_points: int | None
    pieces: tuple[int, ...]
    starts_per_piece: int
    devices: tuple[str, ...]
    scenes_per_part: int
    padded_scenes: int
    fields: tuple[str, ...]
    metrics: bool
    bytes_per_piece: int
    budget: int
    calls: int = 1

    def describe(self) -> str:
        """The plan as a few lines for people (``shacc evaluate --plan``).

        Example::

            print(shacc_jax.plan(bake(results)).describe())
        """
        lay = self.layout
        points = "" if self.n_points is None else f" x {self.n_points} points"
        return "\n".join([
            f"batch: {self.n_scenes} scenes{points} x {self.n_starts} starts x "
            f"{lay.n_tasks} tasks (padded) x {len(lay.modes)} modes "
            f"({', '.join(lay.modes)})",
            f"program: meta formula {lay.meta_formula}, collision checks "
            f"{'on' if lay.collision_checks else 'off'}, "
            f"{_how(lay)} rollouts, blocks of {lay.lanes_per_block} "
            f"lanes x {lay.samples_per_block} samples",
            f"memory: {_size(self.bytes_per_piece)} per piece of a budget of "
            f"{_size(self.budget)}: {len(self.pieces)} piece(s) of "
            f"{self.starts_per_piece} starts",
            f"devices: {len(self.devices)} ({', '.join(self.devices)}), "
            f"{self.scenes_per_part} scenes each ({self.padded_scenes - self.n_scenes} "
            f"padding)",
            f"copied back: {', '.join(self.fields)}; metrics "
            f"{'on the host, once' if self.metrics else 'left to the caller'}",
        ])


class Run(NamedTuple):
    """What :func:`run` returns: the evaluation (NumPy arrays; a leading P axis with
    sweep points) and the optimized mode's search (None without that mode; with sweep
    points, one per point)."""

    evaluation: Evaluation
    search: Search | list[Search] | None


def _parse_bytes(text: str) -> int:
    units = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    t = text.strip().upper().removesuffix("B")
    scale = units.get(t[-1:], 1)
    number = t[:-1] if t[-1:] in units else t
    value: float
    try:
        value = int(number) * scale if len(number) <= 30 else -1
    except ValueError:
        try:
            value = float(number) * scale
        except (ValueError, OverflowError):
            value = -1
    if not 1 <= value <= MAX_BUDGET:  # NaN, inf and 400-digit numbers fail here too
        raise InputError(f"${ENV}", ENV, f"must be a number of bytes from 1 to 2^60 such as "
                         f"2G, got {text[:40]!r}")
    return int(value)


def budget() -> int:
    """Bytes one evaluation may use: ``$SHACC_MEMORY_BUDGET``, else half of what the
    first local device has free.

    Example::

        shacc_jax.budget() // 2**20      # MiB
    """
    if os.environ.get(ENV):
        return _parse_bytes(os.environ[ENV])
    dev = jax.local_devices()[0]
    stats = dev.memory_stats() if hasattr(dev, "memory_stats") else None
    if stats and "bytes_limit" in stats:
        free = stats["bytes_limit"] - stats.get("bytes_in_use", 0)
    else:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    return int(0.5 * free)


def bytes_per_rollout(collision: bool, backend: str | None = None,
                      stepped: bool = False) -> int:
    """:data:`BYTES_PER_ROLLOUT` of the program that runs on ``backend`` ("cpu" or an
    accelerator's; default the one in use), with or without collision checks, closed
    form or ``stepped`` (imperfect users)."""
    backend = backend or jax.default_backend()
    return BYTES_PER_ROLLOUT[("cpu" if backend == "cpu" else "accelerator", bool(collision),
                              bool(stepped))]


def _size(n: float) -> str:
    for unit, scale in (("GB", 2**30), ("MB", 2**20), ("KB", 2**10)):
        if n >= scale:
            return f"{n / scale:,.1f} {unit}"
    return f"{int(n)} bytes"


def _fields(fields: Sequence[str] | None) -> tuple[str, ...]:
    """The Rollouts fields named by ``fields`` (None: all), each checked (the metrics of
    a field not named are NaN: ``geometry_precompute.outcomes.scene_metrics``)."""
    if fields is None:
        return Rollouts._fields
    if isinstance(fields, str):
        raise ValueError(f"fields: a sequence of Rollouts field names, not the string "
                         f"{fields!r}")
    unknown = [f for f in fields if f not in Rollouts._fields]
    if unknown:
        raise ValueError(f"fields: {', '.join(map(repr, unknown))} not among the Rollouts "
                         f"fields ({', '.join(Rollouts._fields)})")
    return tuple(f for f in Rollouts._fields if f in fields)


def _stacked_params(points: Sequence) -> Params:
    """P bakes' (or Params') rollout settings as one Params with a points axis, NumPy."""
    return Params._make(np.stack([np.asarray(getattr(p, k)) for p in points])
                        for k in _PARAM_FIELDS)


def plan(baked, modes: Sequence[str] = MODES, *, points: Sequence | None = None,
         fields: Sequence[str] | None = None, metrics: bool = True,
         budget_bytes: int | None = None, devices: Sequence | None = None,
         backend: str | None = None, calls: int = 1) -> RunPlan:
    """The :class:`RunPlan` of evaluating ``baked`` in ``modes`` (of
    ``shacc_jax.MODES``), decided in NumPy. A pure function of its arguments; the
    defaults read the machine (``budget()``, ``jax.local_devices()``,
    ``jax.default_backend()``).

    :param baked: a bake (``geometry_precompute.bake``), (S, ...) arrays.
    :param points: P bakes (or Params) of the same scenes that differ only in their
        rollout settings: evaluated as one call with a points axis.
    :param fields: the Rollouts fields to copy back (default all).
    :param metrics: compute the per-scene metrics (else left None).
    :param budget_bytes: the memory budget (default :func:`budget`).
    :param devices: where to split the scenes (default every local accelerator; on a
        CPU the first device, or every one for stepped users).
    :param backend: the backend whose block size and memory model apply (default the
        one in use).
    :param calls: how many times the caller will run this plan (a sweep runs one
        program for each of its chunks): a small CPU program is compiled quickly
        (``program_cache.quick``) only where the work of all its calls is small.
    :raises InputError: when two start poses of the batch do not fit the budget.

    Example::

        p = shacc_jax.plan(bake(results), budget_bytes=2**30, devices=["cpu:0"])
        p.pieces, p.layout.lanes_per_block
    """
    configure_runtime()  # before JAX starts, where nothing has started it yet
    backend = backend or jax.default_backend()
    limit = budget() if budget_bytes is None else int(budget_bytes)
    S, N, T = baked.task_mask.shape[0], baked.starts.shape[1], baked.task_mask.shape[1]
    modes = tuple(modes)
    P = None if points is None else len(points)
    if points is None:
        layout = batch_layout(baked, modes)
    else:
        # The geometry's layout with every point's settings: collision checks if any
        # point has them on.
        arrays = {k: getattr(baked, k) for k in _GEOMETRY_FIELDS}
        arrays.update(_stacked_params(points)._asdict())
        layout = batch_layout(SimpleNamespace(**arrays), modes)
    layout = replace(layout, lanes_per_block=layout.lanes_per_block
                     or lanes_per_block_default(backend, layout.collision_checks,
                                                layout.stepped_users))
    if devices is None:
        # An accelerator's devices each add their own compute. A CPU's devices
        # (jax_num_cpu_devices, split_cpu) share its cores: the closed form keeps them
        # busy from one device; the stepped users' loop does not, and runs on all when
        # the batch is large enough to pay for a program per device (each device
        # compiles its own: 10-23 s each on 2 cores).
        local = jax.local_devices()
        rollouts = S * N * T * len(modes) * (P or 1)
        one = backend == "cpu" and (not layout.stepped_users
                                    or rollouts < CPU_SPLIT_ROLLOUTS)
        devices = local[:1] if one else local
    devices = list(devices)
    per_start = (bytes_per_rollout(layout.collision_checks, backend, layout.stepped_users)
                 * S * T * len(modes) * (P or 1))
    # At least two starts in every program, even a one-start grid (padded by repeating
    # it): where an axis has length one, XLA simplifies the arithmetic around it
    # differently, and a rollout's last bits would depend on its piece.
    n_per = N if per_start * N <= limit and N >= 2 else limit // per_start
    if n_per < 2:
        raise InputError("<memory>", "batch", f"two start poses of this batch "
                         f"({P or 1} x {S} scenes x {T} tasks x {len(modes)} modes) need "
                         f"{_size(2 * per_start)}, more than the budget of {_size(limit)}; "
                         f"evaluate fewer scenes at once or raise ${ENV}")
    n_per = min(n_per, max(N, 2))
    # As few pieces as fit, as even as they can be: the last piece is padded to the
    # others' size with repeats of the last start, which are evaluated and dropped
    # (36 starts in pieces of 23 evaluated 46; in two of 18, 36).
    n_per = max(2, -(-N // -(-N // n_per)))
    # Parts of at least two scenes, for the same reason.
    devices = devices[:max(1, S // 2)]
    per_part = -(-S // len(devices))
    return RunPlan(layout=replace(layout, n_starts=n_per), n_scenes=S, n_starts=N, n_points=P,
                   pieces=tuple(range(0, N, n_per)), starts_per_piece=n_per,
                   devices=tuple(str(d) for d in devices), scenes_per_part=per_part,
                   padded_scenes=per_part * len(devices), fields=_fields(fields),
                   metrics=metrics, bytes_per_piece=per_start * n_per, budget=limit,
                   calls=calls)


def _how(lay: Layout) -> str:
    """How the program computes its rollouts, in words."""
    intent = [m for m in lay.modes if m in INTENT_MODES]
    if lay.stepped_users:
        return "stepped (imperfect users)"
    if intent:
        return f"closed-form and stepped ({', '.join(intent)}: the assistance moves the user)"
    return "closed-form"


def _pad(a: np.ndarray, n: int, axis: int) -> np.ndarray:
    """``a`` grown to ``n`` along ``axis`` by repeating its last entry."""
    extra = n - a.shape[axis]
    if extra <= 0:
        return a
    return np.concatenate([a, np.repeat(np.take(a, [-1], axis=axis), extra, axis)], axis=axis)


_EVALUATION_STRUCTURE = Evaluation(Rollouts._make([0] * len(Rollouts._fields)),
                                   SceneMetrics._make([0] * len(SceneMetrics._fields)))


def _on_device(device, geometry: Geometry, params: Params, layout: Layout,
               fields: tuple[str, ...], calls: int) -> Rollouts:
    """One part on one device, through the program cache; the fields copied back
    (every copy started before the first is waited for). ``calls``: of this program,
    which with its work decide its compiler options."""
    geometry, params = jax.device_put((geometry, params), device)
    ev = program_cache.call("evaluate", evaluate, {"layout": layout}, (geometry, params),
                            _EVALUATION_STRUCTURE,
                            work=calls * program_work(geometry, params, layout))
    return _copied_back({k: getattr(ev.rollouts, k) for k in fields})


# A rollout's run time against a perfect user's closed-form one, on the 2-core CPU at
# XLA's default level (benchmarks/RESULTS.md, 100 random 10-task scenes): 8.3 us
# closed form; 20 us with collision checks; 46 us stepped with every user setting; 536
# us in the intent modes. What decides whether the optimized mode reuses its batch's
# program (OPTIMIZED_REUSE_WORK) is the rollouts weighted by these.
RUN_COST = {"closed": 1, "collision": 3, "stepped": 6, "intent": 64}

# What a rollout weighs in the choice of a CPU program's compiler options
# (program_cache.quick): the run time that level 0 adds to it against the compile time
# level 0 saves, relative to the closed form's (benchmarks/bench_levels.py). The run
# time's ratios, but for the intent modes: their programs are the largest, so level 0
# saves the most compile time on them (10 s on four random 10-task scenes, 2 s on the
# closed form), and their break-even lies at about 330 000 rollouts weighted by 64
# where the closed form's lies at 66 000.
LEVEL_COST = {**RUN_COST, "intent": 16}


def program_work(geometry: Geometry, params: Params, layout: Layout) -> int:
    """The work of one evaluation program, in closed-form rollouts: points x scenes x
    starts x tasks (padding included) per mode, each weighted by its :data:`LEVEL_COST`
    (intent modes, stepped users, collision checks): what decides its compiler options."""
    S, N = geometry.starts.shape[:2]
    points = params[0].shape[0] if params[0].ndim > 1 else 1
    return layout_work(layout, points * S * N * geometry.task_mask.shape[1], LEVEL_COST)


def layout_work(layout: Layout, per_mode: int, cost: dict[str, int] = RUN_COST) -> int:
    """The rollouts of a program of ``layout`` with ``per_mode`` rollouts (points x scenes
    x starts x tasks) in each of its modes, each weighted by its ``cost`` (default
    :data:`RUN_COST`, run time)."""
    base = cost["stepped"] if layout.stepped_users else cost["closed"]
    if layout.collision_checks:
        base *= cost["collision"]
    return sum(per_mode * (cost["intent"] if m in INTENT_MODES else base)
               for m in layout.modes)


def _copied_back(wanted: dict) -> Rollouts:
    """The Rollouts fields ``wanted`` (name -> device array) on the host, every copy
    started before the first is waited for; the other fields None."""
    host = jax.tree.map(np.asarray, jax.device_get(wanted))
    return Rollouts._make(host.get(k) for k in Rollouts._fields)


@partial(jax.jit, static_argnames=("layout", "fields", "mesh", "lead"))
def _evaluate_parts(geometry: Geometry, params: Params, layout: Layout,
                    fields: tuple[str, ...], mesh: Mesh, lead: int) -> tuple:
    """The fields of :func:`evaluate` over a one-axis mesh of CPU devices, each device
    evaluating its part of the scenes as it would alone (``shard_map``: no value crosses
    between the parts)."""
    def part(g: Geometry, p: Params) -> tuple:
        rollouts = evaluate(g, p, layout).rollouts
        return tuple(getattr(rollouts, k) for k in fields)

    scenes = PartitionSpec(*[None] * lead, "scenes")
    # No collective inside, so JAX's check of which values vary across the devices has
    # nothing to guard (and the kernel's conditionals mix both kinds).
    return jax.shard_map(part, mesh=mesh, in_specs=(PartitionSpec("scenes"), scenes),
                         out_specs=scenes, check_vma=False)(geometry, params)


def _on_cpu_devices(devices: list, geometry: Geometry, params: Params, layout: Layout,
                    fields: tuple[str, ...], lead: int, calls: int) -> Rollouts:
    """Every part on its CPU device, as one program (compiled once, not once per
    device: XLA's CPU client runs each device's part on its own thread); the fields
    copied back. ``calls`` as for :func:`_on_device`."""
    mesh = Mesh(np.array(devices), ("scenes",))
    geometry = jax.device_put(geometry, NamedSharding(mesh, PartitionSpec("scenes")))
    params = jax.device_put(params, NamedSharding(
        mesh, PartitionSpec(*[None] * lead, "scenes")))
    out = program_cache.call("evaluate-parts", _evaluate_parts,
                             {"layout": layout, "fields": fields, "mesh": mesh, "lead": lead},
                             (geometry, params), tuple(fields),
                             work=calls * program_work(geometry, params, layout))
    return _copied_back(dict(zip(fields, out, strict=True)))


def execute(p: RunPlan, baked, points: Sequence | None = None) -> Evaluation:
    """Run a :func:`plan` against the bake (and the points) it was made for; NumPy
    results, joined once, metrics once.

    Example::

        ev = shacc_jax.execute(shacc_jax.plan(baked), baked)
        ev.metrics.u_scene          # (S, M)
    """
    if (baked.task_mask.shape[0], baked.starts.shape[1]) != (p.n_scenes, p.n_starts) \
            or (points is None) != (p.n_points is None):
        raise ValueError("execute: the plan was made for another bake or other points")
    dtype = jax.dtypes.canonicalize_dtype(np.float64)
    geometry = Geometry.from_bake(baked, dtype, on_host=True)
    params = Params.from_bake(baked if points is None else _stacked_params(points), dtype,
                              on_host=True)
    lead = 0 if points is None else 1  # a points axis before the scenes axis
    S, N, n, per = p.n_scenes, p.n_starts, p.starts_per_piece, p.scenes_per_part
    if p.padded_scenes > S:
        geometry = jax.tree.map(lambda a: _pad(a, p.padded_scenes, 0), geometry)
        params = jax.tree.map(lambda a: _pad(a, p.padded_scenes, lead), params)
    local = {str(d): d for d in jax.local_devices()}
    devices = [local[name] for name in p.devices]
    on_cpu = all(d.platform == "cpu" for d in devices)

    def part(k: int, piece: Geometry) -> tuple[Geometry, Params]:
        if len(devices) == 1:
            return piece, params
        rows = np.arange(k * per, (k + 1) * per)
        return (jax.tree.map(lambda a: a[rows], piece),
                jax.tree.map(lambda a: np.take(a, rows, axis=lead), params))

    def join(outs: list[Rollouts], axis: int, keep: int) -> Rollouts:
        """Parts (or pieces) joined along ``axis``, cut to ``keep`` (padding dropped)."""
        def one(*xs):
            if xs[0] is None:
                return None
            a = xs[0] if len(xs) == 1 else np.concatenate(xs, axis=axis)
            return a if a.shape[axis] == keep else np.take(a, np.arange(keep), axis=axis)
        return Rollouts._make(one(*xs) for xs in zip(*outs, strict=True))

    pieces = []
    calls = p.calls * len(p.pieces)  # of each device's program
    with ThreadPoolExecutor(len(devices)) as pool:
        for first in p.pieces:
            idx = np.minimum(np.arange(first, first + n), N - 1)  # the last piece padded
            piece = geometry if n == N else geometry._replace(
                starts=geometry.starts[:, idx], start_index=geometry.start_index[:, idx])
            if len(devices) == 1:
                outs = [_on_device(devices[0], *part(0, piece), p.layout, p.fields, calls)]
            elif on_cpu:
                outs = [_on_cpu_devices(devices, piece, params, p.layout, p.fields, lead,
                                        calls)]
            else:
                outs = list(pool.map(lambda k, piece=piece: _on_device(
                    devices[k], *part(k, piece), p.layout, p.fields, calls),
                    range(len(devices))))
            pieces.append(join([join(outs, lead, S)], lead + 2, min(n, N - first)))
    rollouts = join(pieces, lead + 2, N)
    dt = np.asarray(baked.dt if points is None else [b.dt for b in points])
    metrics = host_metrics(rollouts, baked.task_mask, dt) if p.metrics else None
    # Fields not copied back (and the metrics, when the caller computes them) are None.
    return Evaluation._make((rollouts, metrics))


def search_scenes_per_call(baked, budget_bytes: int | None = None) -> int:
    """Scenes the optimized mode's search may take in one call: each holds population x
    search starts x tasks activation rollouts at once."""
    limit = budget() if budget_bytes is None else budget_bytes
    T = baked.task_mask.shape[1]
    # The larger of a generation (population x search starts) and the final validation
    # (the candidates, Shrinking's and the initial sizes x validation starts).
    at_once = max(int(np.max(baked.optimize_population)) * baked.opt_starts.shape[1],
                  (int(np.max(baked.optimize_candidates)) + 2)
                  * int(np.max(baked.optimize_validation_starts)))
    per_scene = bytes_per_rollout(False) * at_once * T
    if per_scene > limit:
        raise InputError("<memory>", "optimize_population x optimize_starts", "the search "
                         f"of one scene ({T} tasks) needs {_size(per_scene)}, more than "
                         f"the budget of {_size(limit)}; lower them or raise ${ENV}")
    return limit // per_scene


def run(baked, modes: Sequence[str] = MODES, *, points: Sequence | None = None,
        fields: Sequence[str] | None = None, metrics: bool = True, found: Any = None,
        budget_bytes: int | None = None, devices: Sequence | None = None,
        calls: int = 1) -> Run:
    """Evaluate a bake in ``modes`` (any of ``shacc_jax.ALL_MODES``, in the order of the
    result's mode axis): :func:`plan`, then :func:`execute`. The ``optimized`` mode
    runs its search first (``shacc_jax.optimize``), then shacc's rules on the spaces it
    found, from the scene's usual starts.

    :param baked: a bake, (S, ...) arrays.
    :param points: P bakes of the same scenes that differ only in rollout settings:
        one call with a points axis (with ``optimized``, each point searches on its own).
    :param fields: the Rollouts fields to copy back (default all; the others None).
    :param metrics: compute the per-scene metrics (else None).
    :param found: a search already run for these scenes (its parameters are used).
    :param budget_bytes: the memory budget, ``devices`` the devices (:func:`plan`).
    :param calls: how many batches of this shape the caller evaluates (a sweep's
        chunks), for the programs' compiler options (:func:`plan`).
    :returns: a :class:`Run`: the Evaluation as NumPy arrays, (S, M, N, T) rollouts and
        (S, M) metrics, or (P, S, M, ...) with points; and the search.

    Example::

        out = shacc_jax.run(bake(results), ("baseline", "shacc", "optimized"))
        out.evaluation.metrics.u_scene      # (S, 3)
        out.search.q                        # the optimized mode's parameters
    """
    modes = tuple(modes)
    bad = [m for m in modes if m not in ALL_MODES]
    if bad or not modes or len(set(modes)) != len(modes):
        raise ValueError(f"modes must be distinct names from {ALL_MODES}, got {modes}")
    for b in points or ():  # a grouping error would evaluate one point on another's spaces
        for name in _GEOMETRY_FIELDS:
            if not np.array_equal(getattr(b, name), getattr(baked, name)):
                raise ValueError(f"run: the points differ from the bake in {name}")
    options: dict[str, Any] = {"fields": fields, "metrics": metrics,
                               "budget_bytes": budget_bytes, "devices": devices,
                               "calls": calls}
    if points is not None and (OPTIMIZED in modes or len(points) == 1):
        # Each point on its own (the search depends on the rollout settings; one point
        # needs no points axis), stacked.
        runs = [run(b, modes, **options) for b in points]
        stacked = jax.tree.map(lambda *xs: None if xs[0] is None else np.stack(xs),
                               *[r.evaluation for r in runs],
                               is_leaf=lambda x: x is None)
        searches: list[Any] = [r.search for r in runs]
        return Run(stacked, searches if OPTIMIZED in modes else None)
    plain = tuple(m for m in modes if m != OPTIMIZED)
    parts: dict[str, tuple[Evaluation, int]] = {}
    if plain:
        ev = execute(plan(baked, plain, points=points, **options), baked, points)
        parts.update({m: (ev, i) for i, m in enumerate(plain)})
    if OPTIMIZED in modes:

        if found is None:
            try:
                search_sizes(baked)
            except ValueError as e:
                raise InputError("<batch>", "optimize_population/optimize_generations",
                                 str(e)) from None
            found = search(baked, search_scenes_per_call(baked, budget_bytes), calls)
        center, dims = optimized_spaces(baked, found)
        best = replace(baked, center_opt=center, dims_opt=dims)
        again = _optimized_modes(baked, plain)
        parts[OPTIMIZED] = (execute(plan(best, again, **options), best), again.index("shacc"))
    return Run(_join_modes(parts, modes), found)


# The optimized mode runs in the program of the other modes of its batch (all of them
# run again on the searched spaces, and only shacc's rollouts are kept) where that
# program's work is at most this, in closed-form rollouts: the rollouts thrown away
# then cost at most about 9 s on the 2-core CPU (8.3 us each, RUN_COST), less than a
# second program's compile there (4-30 s measured; `shacc reproduce --quick`'s
# robustness batch, 622 080 of work, 26 s), and nothing much on an accelerator.
OPTIMIZED_REUSE_WORK = 2**20


def _optimized_modes(baked, plain: tuple[str, ...]) -> tuple[str, ...]:
    """The modes of the program that evaluates the optimized mode (shacc's rules on the
    searched spaces): the plain modes' own program where it holds shacc and its work is
    at most :data:`OPTIMIZED_REUSE_WORK`, so that no second program is compiled; else a
    program of shacc alone. The same layout gives the same program (nothing in it
    depends on the optimised spaces), and a mode's rollouts do not depend on the other
    modes of its program."""
    if "shacc" not in plain:
        return ("shacc",)
    S, N = baked.starts.shape[:2]
    work = layout_work(batch_layout(baked, plain), S * N * baked.task_mask.shape[1])
    return plain if work <= OPTIMIZED_REUSE_WORK else ("shacc",)


def _join_modes(parts: dict[str, tuple[Evaluation, int]], modes: tuple[str, ...]
                ) -> Evaluation:
    """One evaluation whose mode axis is ``modes``, from mode -> (evaluation, index):
    the evaluation itself when it already holds the modes in that order."""
    ev0 = parts[modes[0]][0]
    if all(parts[m][0] is ev0 and parts[m][1] == i for i, m in enumerate(modes)) and \
            np.shape(ev0.rollouts.outcome)[-3] == len(modes):
        return ev0
    axis = np.ndim(ev0.rollouts.outcome) - 3  # the mode axis: (..., S, M, N, T)

    def pick(get):
        if get(ev0) is None:  # a field not copied back
            return None
        return np.concatenate([np.take(np.asarray(get(parts[m][0])), [parts[m][1]], axis=axis)
                               for m in modes], axis=axis)

    rollouts = Rollouts._make(pick(lambda e, k=k: e.rollouts[k])
                              for k in range(len(Rollouts._fields)))
    metrics = None if ev0.metrics is None else SceneMetrics._make(
        pick(lambda e, k=k: e.metrics[k]) for k in range(len(SceneMetrics._fields)))
    return Evaluation._make((rollouts, metrics))
