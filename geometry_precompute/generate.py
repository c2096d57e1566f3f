"""Seeded random scenes (SPEC section 11's random set).

Each scene has ``n_tasks`` objects (uniform in [min_tasks, max_tasks]), one
task each: a mug with a side grasp or a cup with a handle grasp, with equal
probability (the paper's two representative tasks). Positions are
``uniform`` over a 0.6 m x 0.6 m table area centred at the origin or
``gaussian`` around its centre (sigma 0.10 m); handle yaws are uniform in
[-pi, pi). Objects are placed one at a time by rejection sampling so that
every pair of bodies is at least ``gap`` (0.01 m) apart; a scene whose
objects cannot be placed in ``max_attempts`` draws is started again.
Everything comes from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import numpy as np

from .scene import Scene, SceneObject, Task
from .settings import OBJECT_DEFAULTS

TABLE_HALF = 0.30
# The most objects the generator places: 30 fill the 0.6 m table to about half of the
# random-packing limit, and rejection sampling still succeeds at once (measured: 0.1 s
# for 30 uniform objects); much beyond, it restarts without end.
MAX_TASKS = 30
MAX_RESTARTS = 100
GAUSSIAN_SIGMA = 0.10
# The version of what random_scene returns for given arguments. The precompute cache
# keys a random scene by its arguments and this number (building a scene costs about
# as much as reading its cached result), so any change to the scenes a seed gives must
# raise it; tests/test_precompute_fast.py holds a digest of a few seeds' scenes.
GENERATOR_VERSION = 1


def random_scene(seed: int, kind: str = "uniform", min_tasks: int = 5, max_tasks: int = 10,
                 gap: float = 0.01, max_attempts: int = 2000, name: str | None = None) -> Scene:
    if kind not in ("uniform", "gaussian"):
        raise ValueError(f"sampling kind must be uniform or gaussian, got {kind!r}")
    if not 1 <= min_tasks <= max_tasks <= MAX_TASKS:
        raise ValueError(f"need 1 <= min_tasks <= max_tasks <= {MAX_TASKS}, got {min_tasks}, "
                         f"{max_tasks}")
    rng = np.random.default_rng(seed)
    n = int(rng.integers(min_tasks, max_tasks + 1))
    for _restart in range(MAX_RESTARTS):
        placed: list[tuple[float, float, float]] = []  # (x, y, radius)
        objects, tasks = [], []
        for i in range(n):
            is_mug = bool(rng.random() < 0.5)
            kind_i = "mug" if is_mug else "cup"
            radius = OBJECT_DEFAULTS[kind_i]["radius"]
            for _ in range(max_attempts):
                if kind == "uniform":
                    xy = rng.uniform(-TABLE_HALF, TABLE_HALF, size=2)
                else:
                    xy = rng.normal(0.0, GAUSSIAN_SIGMA, size=2)
                if all(np.hypot(xy[0] - x, xy[1] - y) - radius - r >= gap for x, y, r in placed):
                    break
            else:
                break
            placed.append((float(xy[0]), float(xy[1]), radius))
            yaw = 0.0 if is_mug else float(rng.uniform(-np.pi, np.pi))
            oid = f"{kind_i}{i}"
            objects.append(SceneObject(oid, kind_i, (float(xy[0]), float(xy[1]), 0.0), yaw,
                                       radius=radius, height=OBJECT_DEFAULTS[kind_i]["height"]))
            template = "side_grasp" if is_mug else "handle_grasp"
            tasks.append(Task(f"{template.split('_')[0]}-{oid}", oid, template))
        if len(objects) == n:
            break
    else:
        raise ValueError(f"could not place {n} objects {gap} m apart in {MAX_RESTARTS} tries")
    return Scene(name or f"random-{kind}-{seed}", tuple(objects), tuple(tasks), {},
                 f"random {kind} scene, seed {seed}, {n} tasks", f"<random {kind} {seed}>")
