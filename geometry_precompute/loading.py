"""Reading a scene (SPEC sections 3 and 13): a file (:func:`load_scene`) or a parsed
table (:func:`scene_from_dict`).

``scene.parse_scene`` validates every name, type, range and reference; then the
task spaces are resolved (``templates``: a template fits its object, bounds min <=
init) and two legal oddities are warned about.
Neither needs coal: that objects do not interpenetrate is checked where the
geometry is built (``precompute``, through ``bodies.check_bodies_apart``).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .bodies import inside, object_body
from .scene import Scene, SceneWarning, parse_scene, read_toml
from .templates import resolve_tasks


def load_scene(path: str | Path) -> Scene:
    return scene_from_dict(read_toml(path, "a scene TOML file"), str(path))


def scene_from_dict(data, source: str = "<scene>") -> Scene:
    """A validated Scene of a parsed table; a loaded scene is one the precompute can
    run, but for objects that interpenetrate (checked there)."""
    scene = parse_scene(data, source)
    _warn_legal_oddities(scene, resolve_tasks(scene, scene.settings()))
    return scene


def _warn_legal_oddities(scene: Scene, spaces) -> None:
    """Two things a scene may hold that are legal but rarely meant (SPEC is silent):
    identical tasks on one object, whose spaces coincide so that every rollout towards
    either is ambiguous; and a handle grasp point inside another object's body."""
    seen: dict[tuple, str] = {}
    for t in scene.tasks:
        key = (t.object, t.template, tuple(sorted(t.bounds.items())),
               tuple(sorted(t.fixed.items())))
        if key in seen:
            warnings.warn(SceneWarning(
                f"{scene.source}: tasks[{t.id}]: same object, template, bounds and fixed "
                f"dimensions as task {seen[key]!r}: their spaces coincide, so every rollout "
                "towards either ends ambiguous"), stacklevel=4)
        seen.setdefault(key, t.id)
    for t, sp in zip(scene.tasks, spaces, strict=True):
        if t.template != "handle_grasp":
            continue
        g = np.asarray(sp.shape().center)  # the cone's apex is the grasp point
        for o in scene.objects:
            if o.id != t.object and inside(object_body(o), g):
                warnings.warn(SceneWarning(
                    f"{scene.source}: tasks[{t.id}]: the handle grasp point "
                    f"{np.round(g, 4).tolist()} lies inside object {o.id!r}"), stacklevel=4)
