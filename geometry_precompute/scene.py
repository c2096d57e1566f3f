"""The scene model and its TOML files (reference/scenes, errors, settings).

:func:`parse_scene` validates a parsed table (``source`` names where it came
from): names, types, ranges and references; :func:`save_scene` writes the same
format back. Every rule of bad input (reference/errors) raises
:class:`~geometry_precompute.errors.InputError` naming the file, the field and
the rule. The rules that need the templates (a template fits its object, bounds
min <= init) are checked above this module (``loading``: ``load_scene``,
``scene_from_dict``); that objects do not interpenetrate needs coal and is checked
where the geometry is built (``precompute``).

One key beyond the scene format (reference/scenes) is accepted: an optional top-level
``description`` (one line of text), used by the shipped scenes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomli_w

from .errors import InputError, shown, unknown_field
from .errors import SceneWarning as SceneWarning  # its home before errors.py; imported from here
from .fileio import check_depth, write_atomic
from .fileio import read_toml as read_toml  # its home before fileio.py
from .mesh_objects import PLACEMENT_KEYS, MeshInfo, check_height, load, parse_placement
from .settings import (
    COORD_LIMIT,
    DEFAULTS,
    LENGTH_LIMIT,
    OBJECT_DEFAULTS,
    Settings,
    flatten_settings,
)
from .template_files import BUILTIN_SET, OBJECT_KINDS, TemplateSet, template_set
from .template_files import builtin as builtin_templates

# The built-in templates' names, fits, shrinkable parameters and fixed dimensions
# (geometry_precompute/builtin_templates.toml); a scene's own files add to them.
TEMPLATE_OBJECTS = {n: t.fits for n, t in builtin_templates().items()}
TEMPLATE_PARAMS = {n: t.param_names for n, t in builtin_templates().items()}
TEMPLATE_FIXED = {n: t.fixed_names for n, t in builtin_templates().items()}
# Objects interpenetrate when coal's signed distance between bodies is below this.
INTERPENETRATION_TOL = 1e-6
YAW_LIMIT = 1000.0  # rad; any angle is allowed, but not one whose cosine is rounding noise


@dataclass(frozen=True)
class SceneObject:
    id: str
    kind: str
    position: tuple[float, float, float]
    yaw: float = 0.0
    radius: float | None = None
    height: float | None = None
    half_extents: tuple[float, float, float] | None = None
    mesh: MeshInfo | None = None  # kind "mesh": its file and measures

    @property
    def body_radius(self) -> float:
        """The object's radius; for a box the half-diagonal of its top face; for a mesh its
        bounding upright cylinder's about the vertical axis through its origin."""
        if self.kind == "box":
            ex, ey, _ = self.box_half_extents
            return math.hypot(ex, ey)
        if self.mesh is not None:
            return self.mesh.radius
        assert self.radius is not None  # the loader gives every cylinder kind its size
        return self.radius

    @property
    def body_height(self) -> float:
        """The object's height; for a mesh its vertices' height range."""
        if self.kind == "box":
            return 2.0 * self.box_half_extents[2]
        if self.mesh is not None:
            return self.mesh.z_max - self.mesh.z_min
        assert self.height is not None
        return self.height

    @property
    def base(self) -> tuple[float, float, float]:
        """The centre of the object's base on its vertical axis: ``position``, and for a
        mesh the point below its origin at its lowest vertex's height."""
        if self.mesh is None:
            return self.position
        x, y, z = self.position
        return (x, y, z + self.mesh.z_min)

    @property
    def box_half_extents(self) -> tuple[float, float, float]:
        """A box's half extents (m); the loader gives every box its extents."""
        assert self.half_extents is not None, f"object {self.id} is not a box"
        return self.half_extents


@dataclass(frozen=True)
class Task:
    id: str
    object: str
    template: str
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    fixed: Mapping[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Scene:
    name: str
    objects: tuple[SceneObject, ...]
    tasks: tuple[Task, ...]
    settings_overrides: Mapping[str, Any] = field(default_factory=dict)
    description: str = ""
    source: str = "<scene>"
    templates: TemplateSet = BUILTIN_SET  # the built-in templates and the scene's files

    def object(self, object_id: str) -> SceneObject:
        for o in self.objects:
            if o.id == object_id:
                return o
        raise KeyError(object_id)

    def settings(self, base: Settings = DEFAULTS,
                 overrides: Mapping[str, Any] | None = None) -> Settings:
        """Settings in the settings' precedence: the scene's [settings] over the
        defaults, then ``overrides`` (command line or sweep axes) over those."""
        s = base.with_overrides(self.settings_overrides, self.source, "settings.")
        if overrides:
            s = s.with_overrides(overrides, "<overrides>")
        return s


_TOP_KEYS = {"name", "description", "objects", "tasks", "settings", "templates"}
_OBJECT_KEYS = {"id", "kind", "position", "yaw", "yaw_deg", "radius", "height", "half_extents",
                "mesh", *PLACEMENT_KEYS}
# Spellings in degrees, converted on load: the field, and the radian field it stands for.
DEG_FIELDS = {"yaw_deg": "yaw", "half_angle_deg": "half_angle"}
_TASK_KEYS = {"id", "object", "template", "bounds", "fixed"}


CM_SIZE = 1.0       # m: an object radius, height or half extent above this looks like cm


def large_sizes(o: SceneObject) -> dict[str, float]:
    """An object's sizes (field name -> m) above ``CM_SIZE``: a scene in centimetres."""
    sizes = {"radius": o.radius, "height": o.height}
    if o.half_extents is not None:
        sizes = {f"half_extents[{i}]": v for i, v in enumerate(o.half_extents)}
    return {n: v for n, v in sizes.items() if v is not None and v > CM_SIZE}


def _unit_slip(value: float, limit: float) -> str:
    """A number past a metre limit that fits once read as centimetres or millimetres:
    the words that say so, each reading that fits (empty if none does)."""
    if value <= limit or value > 1e6 * limit:  # far past any unit: no reading fits
        return ""
    value = float(value)
    fits = [f"{value:g} {u} is {value / f:g} m" for f, u in ((100, "cm"), (1000, "mm"))
            if value / f <= limit / 10]  # well inside once converted
    return f"; a unit slip? {', '.join(fits)} (scenes are written in metres)" if fits else ""


def ratio_slip(lo: float, hi: float) -> str:
    """A lower bound 30 to 3 000 times its upper one, the factor a unit slip makes: the
    words that say so (empty otherwise)."""
    if not (hi > 0 and 30 <= lo / hi <= 3000):
        return ""
    factor = 100 if lo / hi < 300 else 1000
    return (f"; min is {lo / hi:.0f} times init: a unit slip ({factor}x, "
            f"{'centimetres' if factor == 100 else 'millimetres'} for metres) is the likely "
            "cause")


def _number(value: Any, src: str, fld: str, positive: bool = False,
            limit: float = COORD_LIMIT) -> float:
    """A finite number; a size (``positive``) in (0, LENGTH_LIMIT], anything else within
    ``limit`` of zero (settings.py says why every number has a range). Integers are
    range-checked before they become floats (one beyond 64 bits cannot)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(src, fld, f"must be a number, got {shown(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InputError(src, fld, "must be finite (no NaN or inf)")
    if positive and not 0 < value <= LENGTH_LIMIT:
        raise InputError(src, fld, f"must be > 0 and at most {LENGTH_LIMIT:g} m, got "
                         f"{shown(value)}" + _unit_slip(value, LENGTH_LIMIT))
    if not positive and abs(value) > limit:
        raise InputError(src, fld, f"must be within [-{limit:g}, {limit:g}], got {shown(value)}"
                         + _unit_slip(abs(value), limit))
    return float(value)


def _vector(value: Any, n: int, src: str, fld: str, positive: bool = False) -> tuple:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise InputError(src, fld, f"must be a list of {n} numbers, got {shown(value)}")
    return tuple(_number(v, src, f"{fld}[{i}]", positive) for i, v in enumerate(value))


ID_LIMIT = 200  # characters of an id or a name


def _string(value: Any, src: str, fld: str) -> str:
    """A non-empty line of text: an id, a name, a kind (no control characters, so that
    every message quoting it stays one line)."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(src, fld, f"must be a non-empty string, got {shown(value)}")
    if not value.isprintable():
        raise InputError(src, fld, f"must be one line of printable text, got {shown(value)}")
    if len(value) > ID_LIMIT:
        raise InputError(src, fld, f"must be at most {ID_LIMIT} characters, got {len(value)}")
    return value


def _check_keys(table: Any, allowed: set[str], required: set[str], src: str, where: str) -> None:
    if not isinstance(table, Mapping):
        raise InputError(src, where or "<top>", "must be a table")
    for key in table:
        if key not in allowed:
            raise InputError(src, f"{where}{key}", unknown_field(allowed, key))
    for key in sorted(required):
        if key not in table:
            raise InputError(src, f"{where}{key}", "missing required field")


def _parse_object(raw: Any, i: int, src: str) -> SceneObject:
    where = f"objects[{i}]."
    _check_keys(raw, _OBJECT_KEYS, {"id", "kind", "position"}, src, where)
    oid = _string(raw["id"], src, where + "id")
    where = f"objects[{oid}]."
    kind = raw["kind"]
    if not isinstance(kind, str) or kind not in OBJECT_KINDS:
        raise InputError(src, where + "kind", f"unknown object kind {shown(kind)} "
                         f"(known: {', '.join(OBJECT_KINDS)})")
    position = _vector(raw["position"], 3, src, where + "position")
    if "yaw" in raw and "yaw_deg" in raw:
        raise InputError(src, where + "yaw_deg", "give yaw (rad) or yaw_deg, not both")
    if "yaw_deg" in raw:
        yaw = math.radians(_number(raw["yaw_deg"], src, where + "yaw_deg",
                                   limit=math.degrees(YAW_LIMIT)))
    else:
        yaw = _number(raw.get("yaw", 0.0), src, where + "yaw", limit=YAW_LIMIT)
    if kind != "mesh":
        for key in ("mesh", *PLACEMENT_KEYS):
            if key in raw:
                raise InputError(src, where + key, f"not a field of a {kind} (mesh objects "
                                 "only)")
    if kind == "mesh":

        for key in ("radius", "height", "half_extents"):
            if key in raw:
                raise InputError(src, where + key, "not a field of a mesh (its size is its "
                                 "file's, placed)")
        if "mesh" not in raw:
            raise InputError(src, where + "mesh", "missing required field for a mesh object")
        written = _string(raw["mesh"], src, where + "mesh")
        placement, yaw = parse_placement(
            raw, yaw if ("yaw" in raw or "yaw_deg" in raw) else None, src, where)
        mesh = load(written, placement, src, where)
        check_height(mesh, position[2], src, where)
        return SceneObject(oid, kind, position, yaw, mesh=mesh)
    if kind == "box":
        for key in ("radius", "height"):
            if key in raw:
                raise InputError(src, where + key, "not a field of a box (use half_extents)")
        if "half_extents" not in raw:
            raise InputError(src, where + "half_extents", "missing required field for a box")
        he = _vector(raw["half_extents"], 3, src, where + "half_extents", positive=True)
        return SceneObject(oid, kind, position, yaw, half_extents=he)
    if "half_extents" in raw:
        raise InputError(src, where + "half_extents", f"not a field of a {kind} (boxes only)")
    radius = _number(raw.get("radius", OBJECT_DEFAULTS[kind]["radius"]), src, where + "radius",
                     positive=True)
    height = _number(raw.get("height", OBJECT_DEFAULTS[kind]["height"]), src, where + "height",
                     positive=True)
    return SceneObject(oid, kind, position, yaw, radius=radius, height=height)


def _parse_task(raw: Any, i: int, src: str, objects: Mapping[str, SceneObject],
                templates: TemplateSet = BUILTIN_SET) -> Task:
    where = f"tasks[{i}]."
    _check_keys(raw, _TASK_KEYS, {"id", "object", "template"}, src, where)
    tid = _string(raw["id"], src, where + "id")
    where = f"tasks[{tid}]."
    obj_id = _string(raw["object"], src, where + "object")
    template = raw["template"]
    if not isinstance(template, str) or template not in templates:
        raise InputError(src, where + "template", f"unknown template {shown(template)} "
                         f"(known: {', '.join(templates.names())}; a scene adds its own "
                         "with templates = [\"file.toml\"])")
    if obj_id not in objects:
        raise InputError(src, where + "object", f"no object with id {obj_id!r} in the scene")
    kind = objects[obj_id].kind
    spec = templates[template]
    if kind not in spec.fits:
        raise InputError(src, where + "template", f"{template} does not fit a {kind} "
                         f"(fits: {', '.join(spec.fits)})")
    bounds_raw = raw.get("bounds", {})
    units = spec.units
    deg = {f"{n}_deg": n for n, u in units.items() if u == "rad"}
    _check_keys(bounds_raw, set(units) | set(deg), set(), src, where + "bounds.")
    bounds = {}
    for key, value in bounds_raw.items():
        name = deg.get(key, key)
        if key != name and name in bounds_raw:
            raise InputError(src, f"{where}bounds.{key}", f"give {name} (rad) or {key}, "
                             "not both")
        if units[name] == "rad":  # in radians, or in degrees as NAME_deg
            lo, hi = _vector(value, 2, src, f"{where}bounds.{key}")
            if key != name:
                lo, hi = math.radians(lo), math.radians(hi)
            if not (0 < lo < math.pi / 2 and 0 < hi < math.pi / 2):
                hint = "" if key != name else \
                    f" (degrees? write half_angle_deg = {shown(value)})"
                raise InputError(src, f"{where}bounds.{key}", f"must be two angles in "
                                 f"(0, {'90) degrees' if key != name else 'pi/2) rad'}, got "
                                 f"{shown(value)}{hint}")
        else:
            lo, hi = _vector(value, 2, src, f"{where}bounds.{name}", positive=True)
        if lo > hi:
            raise InputError(src, f"{where}bounds.{key}", f"min {lo} > init {hi}"
                             + ratio_slip(lo, hi))
        bounds[name] = (lo, hi)
    fixed_raw = raw.get("fixed", {})
    _check_keys(fixed_raw, set(spec.fixed_names), set(), src, where + "fixed.")
    fixed = {name: _number(v, src, f"{where}fixed.{name}", positive=True)
             for name, v in fixed_raw.items()}
    return Task(tid, obj_id, template, bounds, fixed)


def parse_scene(data: Mapping[str, Any], source: str = "<scene>") -> Scene:
    """Validate a parsed scene table's names, types, ranges and references (docs/reference/scenes.md
    and errors.md) and build a Scene."""
    src = str(source)
    check_depth(data, src)
    _check_keys(data, _TOP_KEYS, {"name"}, src, "")
    name = _string(data["name"], src, "name")
    description = data.get("description", "")
    if not isinstance(description, str) or not description.isprintable():
        raise InputError(src, "description", "must be one line of printable text")
    raw_objects = data.get("objects", [])
    raw_tasks = data.get("tasks", [])
    if not isinstance(raw_objects, list) or not raw_objects:
        raise InputError(src, "objects", "a scene needs at least one object (empty scene)")
    if not isinstance(raw_tasks, list) or not raw_tasks:
        raise InputError(src, "tasks", "a scene needs at least one task (empty scene)")
    objects: dict[str, SceneObject] = {}
    for i, raw in enumerate(raw_objects):
        obj = _parse_object(raw, i, src)
        if obj.id in objects:
            raise InputError(src, f"objects[{i}].id", f"duplicate object id {obj.id!r}")
        objects[obj.id] = obj
    templates = BUILTIN_SET
    if "templates" in data:
        templates = template_set(data["templates"], src, "templates",
                                 None if src.startswith("<") else Path(src).parent)
    tasks: dict[str, Task] = {}
    for i, raw in enumerate(raw_tasks):
        task = _parse_task(raw, i, src, objects, templates)
        if task.id in tasks:
            raise InputError(src, f"tasks[{i}].id", f"duplicate task id {task.id!r}")
        tasks[task.id] = task
    settings_raw = data.get("settings", {})
    if not isinstance(settings_raw, Mapping):
        raise InputError(src, "settings", "must be a table")
    settings_raw = flatten_settings(settings_raw, src, "settings.")  # bare dotted names too
    DEFAULTS.with_overrides(settings_raw, src, "settings.")  # validates every key and value
    scene = Scene(name, tuple(objects.values()), tuple(tasks.values()), settings_raw,
                  description, src, templates)
    return scene


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    out: dict[str, Any] = {"name": scene.name}
    if scene.description:
        out["description"] = scene.description
    objs = []
    for o in scene.objects:
        d: dict[str, Any] = {"id": o.id, "kind": o.kind, "position": list(o.position)}
        if o.yaw and o.mesh is None:
            d["yaw"] = o.yaw
        if o.kind == "box":
            d["half_extents"] = list(o.box_half_extents)
        elif o.mesh is not None:
            d["mesh"] = o.mesh.path  # where it is: the written path may be relative
            d.update(o.mesh.placement.written(o.yaw))
        else:
            if o.radius != OBJECT_DEFAULTS[o.kind]["radius"]:
                d["radius"] = o.radius
            if o.height != OBJECT_DEFAULTS[o.kind]["height"]:
                d["height"] = o.height
        objs.append(d)
    tasks = []
    for t in scene.tasks:
        d = {"id": t.id, "object": t.object, "template": t.template}
        if t.bounds:
            d["bounds"] = {k: list(v) for k, v in t.bounds.items()}
        if t.fixed:
            d["fixed"] = dict(t.fixed)
        tasks.append(d)
    if scene.templates.files:
        out["templates"] = list(scene.templates.files)
    out["objects"] = objs
    out["tasks"] = tasks
    if scene.settings_overrides:
        out["settings"] = {k: (list(v) if isinstance(v, tuple) else v)
                           for k, v in scene.settings_overrides.items()}
    return out


def save_scene(scene: Scene, path: str | Path) -> None:
    """Write ``scene`` as a scene file (TOML, the format ``load_scene`` reads; written
    atomically, so a full disk leaves no half file). Values equal to an object kind's
    default size are left out.

    :param scene: a :class:`Scene` (``load_scene``, ``random_scene``, ``scene_from_dict``).
    :param path: the file to write.

    Example::

        >>> import tempfile, pathlib
        >>> from geometry_precompute import load_scene, random_scene, save_scene
        >>> path = pathlib.Path(tempfile.mkdtemp()) / "scene.toml"
        >>> save_scene(random_scene(seed=3), path)
        >>> len(load_scene(path).tasks) == len(random_scene(seed=3).tasks)
        True
    """
    write_atomic(path, tomli_w.dumps(scene_to_dict(scene)).encode())
