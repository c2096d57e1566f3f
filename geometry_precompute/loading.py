"""Reading a scene (reference/scenes, errors): a file (:func:`load_scene`) or a parsed
table (:func:`scene_from_dict`).

``scene.parse_scene`` validates every name, type, range and reference; then the
task spaces are resolved (``templates``: a template fits its object, bounds min <=
init) and two legal oddities are warned about.
Neither needs coal: that objects do not interpenetrate is checked where the
geometry is built (``precompute``, through ``bodies.check_bodies_apart``).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from .bodies import inside_object
from .errors import InputError
from .fileio import read_toml
from .scene import Scene, SceneWarning, large_sizes, parse_scene
from .templates import resolve_tasks


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene file (TOML; the format is in docs/reference/scenes.md).

    :param path: the file.
    :returns: the :class:`~geometry_precompute.scene.Scene`, with its own ``[settings]``
        (``scene.settings()`` gives them over the defaults).
    :raises InputError: the file cannot be read, or a field breaks a rule; the message
        names the file, the field and the rule.

    Values that are legal but look like a unit mistake (a yaw above 2 pi, sizes or
    positions that look like centimetres) give a :class:`SceneWarning`. Whether objects
    interpenetrate is checked by :func:`~geometry_precompute.precomputing.precompute`.

    Example::

        from geometry_precompute import load_scene, precompute
        scene = load_scene("geometry_precompute/scenes/09_mug_behind_two.toml")
        result = precompute(scene)          # C, clusters, Shrinking
        print(scene.name, result.C_init, result.C_final)
    """
    return scene_from_dict(read_toml(path, "a scene TOML file"), str(path))


def scene_files(folder: str | Path) -> list[Path]:
    """The scene files of a folder: its ``*.toml`` files, sorted, less its template files
    (a file whose one table is ``[templates]``, which scenes of the folder may name).

    :param folder: a folder.
    :returns: the paths, in name order.

    Example::

        >>> from geometry_precompute import shipped_scene_paths
        >>> from geometry_precompute.loading import scene_files
        >>> len(scene_files(shipped_scene_paths()[0].parent))
        12
    """
    out = []
    for p in sorted(Path(folder).glob("*.toml")):
        try:
            data = read_toml(p)
        except InputError:  # not TOML: a scene file with an error, reported when read
            data = None
        if not (isinstance(data, dict) and set(data) == {"templates"}
                and isinstance(data["templates"], dict)):
            out.append(p)
    return out


def scene_from_dict(data, source: str = "<scene>") -> Scene:
    """A validated Scene of a parsed table (what ``load_scene`` does after reading the
    file): every field checked (an ``InputError`` naming ``source``, the field and the
    rule), unit slips warned about, ``_deg`` spellings converted. A loaded scene is one
    the precompute can run, but for objects that interpenetrate (checked there).

    :param data: the scene as a dict, the TOML file's structure (positions in m, yaws
        in rad).
    :param source: the name errors use for the input.

    Example::

        >>> from geometry_precompute import scene_from_dict
        >>> scene = scene_from_dict({"name": "one-mug",
        ...     "objects": [{"id": "m", "kind": "mug", "position": [0.0, 0.0, 0.0]}],
        ...     "tasks": [{"id": "grasp", "object": "m", "template": "side_grasp"}]})
        >>> [t.id for t in scene.tasks]
        ['grasp']
    """
    scene = parse_scene(data, source)
    _warn_units(scene)  # before the templates are fitted: their errors may be its cause
    _warn_legal_oddities(scene, resolve_tasks(scene, scene.settings()))
    return scene


# Legal values that are almost certainly a unit mistake (a warning names the field).
CM_POSITION = 5.0   # m: a position coordinate further out looks like cm (or mm)


def _warn_units(scene: Scene) -> None:
    """Warn, once per field, of values that look like degrees where radians are meant or
    centimetres where metres are."""
    def warn(field: str, text: str) -> None:
        warnings.warn(SceneWarning(f"{scene.source}: {field}: {text}"), stacklevel=4)

    for o in scene.objects:
        where = f"objects[{o.id}]"
        rpy = o.mesh is not None and o.mesh.placement.turned_by != "yaw"  # warned of there
        if abs(o.yaw) > 2 * math.pi and not rpy:
            warn(f"{where}.yaw", f"{o.yaw:g} rad is more than a full turn; if degrees were "
                 f"meant, that is yaw = {math.radians(o.yaw):.4f} (or write yaw_deg = "
                 f"{o.yaw:g})")
        for name, v in large_sizes(o).items():
            warn(f"{where}.{name}", f"{v:g} m is large for a {o.kind}; centimetres? "
                 f"{v:g} cm is {v / 100:g} m")
        far = [i for i, v in enumerate(o.position) if abs(v) > CM_POSITION]
        if far:
            warn(f"{where}.position", f"{list(o.position)} m is more than {CM_POSITION:g} m "
                 f"from the origin; centimetres? that would be "
                 f"{[round(v / 100, 6) for v in o.position]} m")


def _warn_legal_oddities(scene: Scene, spaces) -> None:
    """Things a scene may hold that are legal but rarely meant (besides the unit slips
    of :func:`_warn_units`, checked before the templates are fitted): identical tasks
    on one object, whose spaces coincide so that every rollout towards either is
    ambiguous; and a handle grasp point inside another object's body."""
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
            if o.id != t.object and inside_object(o, g):
                warnings.warn(SceneWarning(
                    f"{scene.source}: tasks[{t.id}]: the handle grasp point "
                    f"{np.round(g, 4).tolist()} lies inside object {o.id!r}"), stacklevel=4)
