"""Seeded random scenes (the experiments' random set).

Each scene has ``n_tasks`` objects (uniform in [min_tasks, max_tasks]), one
task each: a mug with a side grasp or a cup with a handle grasp, with equal
probability (the paper's two representative tasks). Positions are ``uniform``
over a square table area centred at the origin or ``gaussian`` around its centre;
handle yaws are uniform in [-pi, pi). Objects are placed one at a time by rejection
sampling so that every pair of bodies is at least ``gap`` (0.01 m) apart; a scene
whose objects cannot be placed in ``max_attempts`` draws is started again.
Everything comes from ``numpy.random.default_rng(seed)``.

The table area and the gaussian's spread are a named *preset* (:data:`PRESETS`):

- ``compact``: a 0.6 m x 0.6 m area and sigma 0.10 m, the project's first reading of
  the paper. Its uniform scenes are far more cluttered than the paper's (C_init near
  0.32 where the paper's had at most 0.11), so the paper's "no gain on uniform scenes"
  cannot be checked on them.
- ``paper``: the area and sigma chosen so that C_init of 1 000 scenes of each sampling
  matches what the paper reports of its own (uniform: mean at most 0.11; gaussian:
  0.30 +- 0.05); the measurements are in benchmarks/RESULTS.md and the README.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .scene import Scene, SceneObject, Task
from .settings import OBJECT_DEFAULTS


class Preset(NamedTuple):
    table_half: float  # m: uniform positions in [-table_half, table_half]^2
    sigma: float       # m: gaussian positions N(0, sigma^2) per coordinate
    doc: str


PRESETS = {
    "compact": Preset(0.30, 0.10, "0.6 m x 0.6 m table, sigma 0.10 m (the first reading)"),
    "paper": Preset(0.65, 0.18, "1.3 m x 1.3 m table, sigma 0.18 m: mean C_init 0.095 (uniform) "
                    "and 0.309 (gaussian) over 1 000 scenes each"),
}
# The most objects the generator places: 30 fill the 0.6 m table to about half of the
# random-packing limit, and rejection sampling still succeeds at once (measured: 0.1 s
# for 30 uniform objects); much beyond, it restarts without end.
MAX_TASKS = 30
MAX_RESTARTS = 100
# The version of what random_scene returns for given arguments. The precompute cache
# keys a random scene by its arguments and this number (building a scene costs about
# as much as reading its cached result), so any change to the scenes a seed gives must
# raise it; tests/test_precompute_fast.py holds a digest of a few seeds' scenes.
GENERATOR_VERSION = 1


def random_scene(seed: int, kind: str = "uniform", min_tasks: int = 5, max_tasks: int = 10,
                 preset: str = "compact", *, gap: float = 0.01, max_attempts: int = 2000,
                 name: str | None = None) -> Scene:
    """A seeded random scene (module docstring; docs/reference/experiments.md).

    :param seed: the generator's seed (``numpy.random.default_rng``).
    :param kind: "uniform" (positions uniform over the table area) or "gaussian"
        (around its centre).
    :param min_tasks, max_tasks: the number of objects, one task each, is uniform in
        this range (1 to 30).
    :param preset: the table area and gaussian spread, a name of :data:`PRESETS`:
        "compact" (0.6 m table, sigma 0.10 m) or "paper" (1.3 m, 0.18 m: the paper's
        C_init distribution).
    :param gap: the smallest distance between two bodies, m.
    :returns: a :class:`Scene` named ``random-[PRESET-]KIND-SEED``; the same arguments
        give the same scene on every machine.

    Example::

        scenes = [random_scene(seed, "gaussian", 5, 10, "paper") for seed in range(100)]
    """
    if preset not in PRESETS:
        raise ValueError(f"generator preset must be one of {', '.join(PRESETS)}, got "
                         f"{preset!r}")
    half, sigma = PRESETS[preset].table_half, PRESETS[preset].sigma
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
                    xy = rng.uniform(-half, half, size=2)
                else:
                    xy = rng.normal(0.0, sigma, size=2)
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
    label = kind if preset == "compact" else f"{preset} {kind}"
    return Scene(name or f"random-{label.replace(' ', '-')}-{seed}", tuple(objects),
                 tuple(tasks), {}, f"random {label} scene, seed {seed}, {n} tasks",
                 f"<random {label} {seed}>")
