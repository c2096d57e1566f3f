"""A sweep's chunk plan and the padded shapes its chunks are evaluated at.

Both are functions of the config alone (the config's hash names them), never of the
machine that runs or resumes the sweep: chunk k holds the same sweep points and
scenes on a laptop and on a cluster of GPUs, so a sweep resumed elsewhere writes the
same tables.

- Points that differ only in rollout settings (the schema's Params: speeds,
  tolerances, collisions, gripper sizes) share their geometry; they form one group,
  precomputed once per scene and evaluated in one call with a points axis. With the
  optimized mode each point is its own group (its search depends on those settings).
- Chunks: for each group in turn, its scenes in runs of ``chunk`` (the config's).
- Shapes: every chunk of a sweep is padded to one scene count (the config's chunk
  size rounded up to a bucket: four per octave, so chunk sizes a few percent apart
  share a program), one task count and one object count (the most any scene of the
  source can have). What else the static layout holds is read off the chunk's
  arrays (``geometry_precompute.schema.batch_layout``): the meta formula (every random
  scene's meta skill takes the closed form for horizontal approaches, so a random
  sweep has one) and the collision branches. A sweep compiles one program per group
  size and layout, and a later sweep of similar chunk size and task range loads it
  from the persistent compilation cache.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from geometry_precompute import SPECS
from geometry_precompute.schema import OPTIMIZED
from sweeps.config import SweepConfig


@dataclass(frozen=True)
class Chunk:
    index: int
    points: tuple[int, ...]  # sweep points, evaluated together
    scenes: range            # scene indices of the source


@dataclass(frozen=True)
class Shapes:
    """The padded sizes every chunk of a sweep is evaluated at."""

    scenes: int
    tasks: int
    objects: int


def point_groups(cfg: SweepConfig) -> list[tuple[int, ...]]:
    """The sweep's points grouped by everything but their rollout settings (in the order
    of each group's first point); one point per group when the optimized mode runs."""
    groups: dict[str, list[int]] = {}
    for i, point in enumerate(cfg.points):
        shared = {k: v for k, v in point.items() if SPECS[k].stage != "rollout"}
        key = json.dumps(shared, sort_keys=True, default=str) if OPTIMIZED not in cfg.modes \
            else str(i)
        groups.setdefault(key, []).append(i)
    return [tuple(g) for g in groups.values()]


def plan(cfg: SweepConfig) -> list[Chunk]:
    n = cfg.n_scenes()
    out: list[Chunk] = []
    for points in point_groups(cfg):
        for start in range(0, n, cfg.chunk):
            out.append(Chunk(len(out), points, range(start, min(start + cfg.chunk, n))))
    return out


def bucket(n: int) -> int:
    """``n`` rounded up to the next of 1, 2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, ...
    (four sizes per octave: at most 25 % padding, under 3 % near 10 000)."""
    if n <= 8:
        return max(1, n)
    step = 2 ** (math.floor(math.log2(n)) - 2)
    return -(-n // step) * step


def shapes(cfg: SweepConfig) -> Shapes:
    most = cfg.max_tasks()
    return Shapes(scenes=bucket(min(cfg.chunk, cfg.n_scenes())), tasks=most, objects=most)


def precompute_batches(scenes: range, workers: int) -> list[range]:
    """A chunk's scenes split into precompute tasks: about two per worker thread, at
    most 64 scenes each. The precompute of later chunks is queued behind, so the threads
    stay busy across a chunk's end; only the sweep's last tasks end unevenly. Four per
    thread (at most 32 scenes) made a warm 10 000-scene sweep 0.7 s slower, one per
    thread 0.4 s faster than two, in tasks for the scheduler and the client
    (benchmarks/RESULTS.md). Only the scheduling depends on this, never the results."""
    size = max(1, min(64, -(-len(scenes) // (2 * max(1, workers)))))
    return [scenes[i:i + size] for i in range(0, len(scenes), size)]
