"""The per-scene CPU pipeline: spaces, C_init, clusters, Shrinking, C_final, d, h.

:func:`precompute` is what ``shacc precompute`` runs and what the bake
consumes. It runs once per scene; its cost is measured by
``benchmarks/bench_precompute.py``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .bodies import check_bodies_apart
from .clusters import clusters_from_pairs
from .clutteredness import clutteredness_of_sets
from .errors import InputError
from .intersect import SpaceSet
from .scene import Scene
from .settings import Settings
from .shapes import Shape
from .shrinking import shrink
from .spread import entropic_clutteredness, mean_distance
from .templates import TaskSpace, resolve_tasks

# Part of every precompute cache key: raised when the same scene and settings would
# give other answers (2: fast intersection volumes, issue 15; 3: 12 quadrature nodes per
# cone x cylinder piece), so that results cached by an earlier version are computed
# again rather than mixed with new ones.
PRECOMPUTE_VERSION = 4


@dataclass(frozen=True)
class PrecomputeResult:
    scene: Scene
    settings: Settings
    spaces: list[TaskSpace]
    shapes_init: list[Shape]
    shapes_opt: list[Shape]
    q_opt: list[np.ndarray]
    C_init: float
    C_final: float
    clusters: list[list[int]]  # every component, singletons included, in task order
    iterations: int
    still_intersecting: list[tuple[int, int]]
    d: float
    h: float
    seconds: dict[str, float] = field(default_factory=dict)

    @property
    def task_ids(self) -> list[str]:
        return [t.id for t in self.scene.tasks]

    def shrunk_params(self) -> dict[str, dict[str, float]]:
        return {s.task.id: {n: float(v) for n, v in zip(s.param_names, q, strict=True)}
                for s, q in zip(self.spaces, self.q_opt, strict=True)}

    def meta_clusters(self) -> list[list[int]]:
        return [c for c in self.clusters if len(c) >= 2]


def precompute(scene: Scene, settings: Settings | Mapping[str, Any] | None = None
               ) -> PrecomputeResult:
    """C, clusters, Shrinking, C_final, d and h of one scene, on the CPU in float64.

    :param scene: a validated :class:`Scene` (``load_scene``, ``random_scene``).
    :param settings: a :class:`Settings`, or a plain mapping of overrides (validated
        over the scene's own ``[settings]``, as ``--set`` is: a bad name or value raises
        :class:`InputError`), or None for the scene's settings.
    :returns: a :class:`PrecomputeResult`: ``C_init`` and ``C_final`` (dimensionless),
        ``clusters`` (task indices), the spaces before and after Shrinking
        (``spaces``, ``q_opt``: parameters in m and rad), ``d`` (m), ``h`` and the
        settings used. Objects that interpenetrate raise :class:`InputError`.

    Example::

        r = precompute(load_scene("geometry_precompute/scenes/09_mug_behind_two.toml"),
                       {"shrink_step": 0.02, "start_grid": [12, 12]})
        r.C_init, r.C_final, r.shrunk_params()
    """
    if not isinstance(scene, Scene):
        raise InputError("<precompute>", "scene", f"must be a Scene (load_scene), got "
                         f"{type(scene).__name__}")
    if settings is None:
        s = scene.settings()
    elif isinstance(settings, Settings):
        s = settings
    elif isinstance(settings, Mapping):
        s = scene.settings(overrides=settings)
    else:
        raise InputError("<precompute>", "settings", "must be a Settings or a mapping of "
                         f"setting = value, got {type(settings).__name__}")
    t0 = time.perf_counter()
    spaces = resolve_tasks(scene, s)
    check_bodies_apart(scene)
    shapes_init = [sp.shape() for sp in spaces]
    sections = s["mesh_sections"]
    t1 = time.perf_counter()
    coll = SpaceSet(shapes_init)
    pairs = coll.intersecting_pairs()
    clusters = clusters_from_pairs(len(spaces), pairs)
    t2 = time.perf_counter()
    if pairs:  # Shrinking (reference/model): a scene with C_init = 0 is left as it is (below)
        res = shrink(spaces, s["shrink_step"], s["shrink_max_iter"], space_set=coll,
                     pairs=pairs)
        q_opt, iterations, still = res.q_opt, res.iterations, res.still_intersecting
        shapes_opt = [sp.shape(q) for sp, q in zip(spaces, q_opt, strict=True)]
    t3 = time.perf_counter()
    # Volumes only for the pairs found intersecting (clutteredness.py says why); C_init
    # and C_final in one call.
    if pairs:
        c_init, c_final = clutteredness_of_sets([(shapes_init, pairs), (shapes_opt, still)],
                                                sections)
    else:
        c_init = c_final = 0.0
    if c_init == 0.0:  # no overlap of positive volume: nothing to shrink
        q_opt, iterations, still = [sp.q_init.copy() for sp in spaces], 0, []
        shapes_opt, c_final = list(shapes_init), 0.0
    t4 = time.perf_counter()
    positions = [o.position for o in scene.objects]
    d = mean_distance(positions)
    h = entropic_clutteredness(positions, s["entropy_variant"])
    t6 = time.perf_counter()
    seconds = {"spaces": t1 - t0, "clusters": t2 - t1, "shrinking": t3 - t2,
               "C_init_and_final": t4 - t3, "d_and_h": t6 - t4, "total": t6 - t0}
    return PrecomputeResult(scene, s, spaces, shapes_init, shapes_opt, q_opt, c_init, c_final,
                            clusters, iterations, still, d, h, seconds)
