"""Start poses of the Automaton (reference/model).

A grid of n_y x n_z points on the vertical plane x = min(object x) - offset,
y in [y_c - w, y_c + w] (y_c the mean object y), z in the height band, ordered
y-major (for each y ascending, every z ascending). A grid of one point along
an axis takes the middle of its range. Orientations: one uniformly random
rotation per grid point from ``numpy.random.default_rng(seed)``, scipy's
``Rotation.random`` to the bit (``frames.random_quats``; so they depend on the seed
and grid size only, not on the scene), or frame_from_approach((1, 0, 0)) for
``"forward"``.

The ``optimized`` mode's search scores candidates on other starts (reference/model):
``optimize_starts`` positions drawn uniformly on the same rectangle of the same plane,
then as many orientations from the same generator, all from
``numpy.random.default_rng(optimize_seed)`` (positions first, then orientations), so
they never coincide with the grid that the reported success is measured on.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .frames import quat_of_approach, random_quats
from .scene import Scene
from .settings import Settings


def _axis(lo: float, hi: float, n: int) -> np.ndarray:
    return np.array([(lo + hi) / 2.0]) if n == 1 else np.linspace(lo, hi, n)


@lru_cache(maxsize=64)
def _orientations(n: int, orientation: str, seed: int) -> np.ndarray:
    """The start orientations depend on the grid size and seed only: drawn once per
    process (read-only)."""
    if orientation == "forward":
        q = np.tile(np.array(quat_of_approach((1.0, 0.0, 0.0))), (n, 1))
    else:
        q = random_quats(n, np.random.default_rng(seed))
    q.flags.writeable = False
    return q


def start_orientations(settings: Settings) -> np.ndarray:
    ny, nz = settings["start_grid"]
    return _orientations(ny * nz, settings["start_orientation"], settings["seed"])


def start_plane(scene: Scene, settings: Settings) -> tuple[float, tuple, tuple]:
    """The start plane's x, its y range and its z range."""
    pos = np.array([o.position for o in scene.objects])
    x = pos[:, 0].min() - settings["start_plane_offset"]
    yc = pos[:, 1].mean()
    w = settings["start_y_halfwidth"]
    return x, (yc - w, yc + w), tuple(settings["start_z_range"])


def start_poses(scene: Scene, settings: Settings) -> np.ndarray:
    """(n_y * n_z, 7) rows of [x, y, z, qw, qx, qy, qz]."""
    x, (y0, y1), (z0, z1) = start_plane(scene, settings)
    ny, nz = settings["start_grid"]
    yy, zz = np.meshgrid(_axis(y0, y1, ny), _axis(z0, z1, nz), indexing="ij")
    points = np.stack([np.full(yy.size, x), yy.ravel(), zz.ravel()], axis=1)
    return np.concatenate([points, start_orientations(settings)], axis=1)


@lru_cache(maxsize=64)
def _search_draws(n: int, orientation: str, seed: int) -> tuple[np.ndarray, ...]:
    """The search starts' random numbers (unit y and z fractions, orientations), in the
    order one generator draws them; read-only and drawn once per process."""
    rng = np.random.default_rng(seed)
    uy, uz = rng.random(n), rng.random(n)
    if orientation == "forward":
        q = np.tile(np.array(quat_of_approach((1.0, 0.0, 0.0))), (n, 1))
    else:
        q = random_quats(n, rng)
    for a in (uy, uz, q):
        a.flags.writeable = False
    return uy, uz, q


def optimize_start_poses(scene: Scene, settings: Settings) -> np.ndarray:
    """(optimize_starts, 7): the optimized mode's search starts (module docstring).
    Positions are lo + (hi - lo) u, as numpy's ``uniform`` computes them."""
    x, (y0, y1), (z0, z1) = start_plane(scene, settings)
    uy, uz, quats = _search_draws(settings["optimize_starts"], settings["start_orientation"],
                                  settings["optimize_seed"])
    points = np.stack([np.full(len(uy), x), y0 + (y1 - y0) * uy, z0 + (z1 - z0) * uz], axis=1)
    return np.concatenate([points, quats], axis=1)
