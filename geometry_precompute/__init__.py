"""CPU half of the ShaCC evaluator: scenes, templates, meshes, clutteredness,
clusters, Shrinking and the bake (never imports jax)."""

from importlib.resources import files
from pathlib import Path

from .bake import BakedScenes, bake
from .errors import InputError
from .generate import random_scene
from .loading import load_scene, scene_from_dict
from .precompute import PrecomputeResult, precompute
from .scene import Scene, save_scene
from .settings import DEFAULTS, SPECS, Settings


def shipped_scene_paths() -> list[Path]:
    """The manual scenes that ship with the package, in file-name order: the twelve of
    the paper's experiment (``reproduce`` uses these), not the ``extra`` ones."""
    return sorted(Path(str(p)) for p in files(__package__).joinpath("scenes").iterdir()
                  if str(p).endswith(".toml"))


def extra_scene_paths() -> list[Path]:
    """Scenes that ship beside the paper's twelve (``scenes/extra``), for cases those do
    not cover: a cluster that mixes a top grasp with side grasps."""
    return sorted(Path(str(p)) for p in files(__package__).joinpath("scenes", "extra").iterdir()
                  if str(p).endswith(".toml"))


__all__ = ["DEFAULTS", "SPECS", "BakedScenes", "InputError", "PrecomputeResult", "Scene",
           "Settings", "bake", "extra_scene_paths", "load_scene", "precompute", "random_scene",
           "save_scene", "scene_from_dict", "shipped_scene_paths"]
