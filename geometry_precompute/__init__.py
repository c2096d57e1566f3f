"""CPU half of the ShaCC evaluator: scenes, templates, meshes, clutteredness,
clusters, Shrinking and the bake (never imports jax).

The names below are loaded when first used (PEP 562), so that importing one light
module of the package (``errors``, ``fileio``, ``schema``) does not import NumPy and
the scene model: the command line reads its arguments, and starts its workers, before
it needs them. No module is named like a function the package exports (``bake`` lives
in ``baking``, ``precompute`` in ``precomputing``), so importing a module never hides
one.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # what __getattr__ loads, for type checkers and editors
    from .baking import BakedScenes, bake
    from .errors import HostError, InputError
    from .generate import random_scene
    from .loading import load_scene, scene_from_dict
    from .precomputing import PrecomputeResult, precompute
    from .scene import Scene, save_scene
    from .settings import DEFAULTS, SPECS, Settings

# The names the package loads on first use (PEP 562): name -> the module that defines it.
LAZY_NAMES = {
    "BakedScenes": "baking", "bake": "baking",
    "HostError": "errors", "InputError": "errors",
    "random_scene": "generate",
    "load_scene": "loading", "scene_from_dict": "loading",
    "PrecomputeResult": "precomputing", "precompute": "precomputing",
    "Scene": "scene", "save_scene": "scene",
    "DEFAULTS": "settings", "SPECS": "settings", "Settings": "settings",
}


def __getattr__(name: str):
    module = LAZY_NAMES.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *LAZY_NAMES})


def shipped_scene_paths() -> list[Path]:
    """The manual scenes that ship with the package, in file-name order: the twelve of
    the paper's experiment (``reproduce`` uses these), not the ``extra`` ones.

    Example::

        from geometry_precompute import load_scene, shipped_scene_paths
        scenes = [load_scene(p) for p in shipped_scene_paths()]   # 12 scenes
    """
    from importlib.resources import files  # deferred: 10 ms to import

    return sorted(Path(str(p)) for p in files(__package__).joinpath("scenes").iterdir()
                  if str(p).endswith(".toml"))


def extra_scene_paths() -> list[Path]:
    """Scenes that ship beside the paper's twelve (``scenes/extra``), for cases those do
    not cover: a cluster that mixes a top grasp with side grasps. Paths in file-name
    order.

    Example::

        >>> from geometry_precompute import extra_scene_paths, load_scene
        >>> [load_scene(p).name for p in extra_scene_paths()][:1]
        ['tray-between-mugs']
    """
    from importlib.resources import files  # deferred: 10 ms to import

    return sorted(Path(str(p)) for p in files(__package__).joinpath("scenes", "extra").iterdir()
                  if str(p).endswith(".toml"))


__all__ = ["DEFAULTS", "SPECS", "BakedScenes", "HostError", "InputError", "PrecomputeResult",
           "Scene", "Settings", "bake", "extra_scene_paths", "load_scene", "precompute",
           "random_scene", "save_scene", "scene_from_dict", "shipped_scene_paths"]
