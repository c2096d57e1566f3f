"""The JSON Schema (draft 2020-12) of the scene file and of a settings table, built from
the loaders' own definitions: the allowed keys and templates of ``scene`` and the
limits of ``settings`` (every setting's rule carries its schema). ``shacc schema
scene`` prints it (``sweeps.app.schema_cmd`` adds the sweep config's), for editors whose
TOML plugin validates against a JSON Schema, and for other tools.

A schema cannot state every rule; those are listed in each schema's ``description``
and checked by the loaders alone (``LOADER_ONLY``).
"""

from __future__ import annotations

import math
from typing import Any

from .mesh_objects import ORIGINS, PLACEMENT_KEYS, UPS
from .mesh_objects import UNITS as MESH_UNITS
from .population import MAX_VALUES, POPULATED
from .scene import (
    DEG_FIELDS,
    ID_LIMIT,
    OBJECT_KINDS,
    TEMPLATE_FIXED,
    TEMPLATE_OBJECTS,
    TEMPLATE_PARAMS,
    YAW_LIMIT,
)
from .settings import COORD_LIMIT, LENGTH_LIMIT, OLD_COLLISION, SPECS
from .template_files import (
    _PARAM_KEYS,
    EXPR_LIMIT,
    MAX_PARAMS,
    MAX_TEMPLATES,
    SHAPE_DIMS,
    UNITS,
)

DRAFT = "https://json-schema.org/draft/2020-12/schema"

LOADER_ONLY = {
    "scene": [
        "object ids are unique, and so are task ids",
        "a task's object exists, and its template fits that object's kind",
        "bounds: min <= init",
        "yaw and yaw_deg (half_angle and half_angle_deg) are not both given",
        "objects do not interpenetrate (checked when the geometry is built)",
        "a mesh file exists and holds a solid (read when the scene is)",
        "a mesh's quat is not of zero norm; placed, it reaches at most 1 mm below the "
        "table",
        "a template file exists and is valid; where a scene names template files, its "
        "tasks' templates, bounds and fixed dimensions are checked against them",
        "start_grid: n_y * n_z <= 16 777 216; start_z_range: low <= high",
        "a uniform population's low <= high",
        "names, ids and the description are printable text (a pattern approximates "
        "Unicode's rule)",
    ],
}


def _text(max_length: int = ID_LIMIT) -> dict:
    return {"type": "string", "minLength": 1, "maxLength": max_length,
            "pattern": r"^[^\u0000-\u001f\u007f]*\S[^\u0000-\u001f\u007f]*$"}


def _number(lo: float, hi: float, lo_open: bool = False) -> dict:
    return {"type": "number", "exclusiveMinimum" if lo_open else "minimum": lo,
            "maximum": hi}


def _vector(n: int, item: dict) -> dict:
    return {"type": "array", "items": item, "minItems": n, "maxItems": n}


def settings_schema(values_as_lists: bool = False) -> dict:
    """A settings table: every setting by its flat (quoted) name, and the templates'
    and the gripper's settings also as nested tables (``side_grasp.radius_init = 0.2``
    written bare). ``values_as_lists``: each value a non-empty list of values (a
    sweep's ``[axes]``)."""
    def value(s) -> dict:
        v = {**s.schema, "description": s.doc, "default": _plain(s.default)}
        if s.name == "collision":  # the old name of "on" is still read (with a warning)
            v["enum"] = [*s.choices, OLD_COLLISION]
        if s.name in POPULATED:
            v = {"description": s.doc, "default": s.default,
                 "anyOf": [s.schema, _population_schema(s.schema)]}
        return {"type": "array", "items": v, "minItems": 1} if values_as_lists else v

    props: dict[str, Any] = {name: value(s) for name, s in SPECS.items()}
    groups: dict[str, dict] = {}
    for name, s in SPECS.items():
        if "." in name:
            head, tail = name.split(".", 1)
            groups.setdefault(head, {})[tail] = value(s)
    for head, inner in groups.items():
        props[head] = {"type": "object", "properties": inner, "additionalProperties": False}
    return {"type": "object", "properties": props, "additionalProperties": False}


def _population_schema(number: dict) -> dict:
    """A population table of a setting whose number schema is ``number``: one key,
    uniform [low, high], normal [mean, sd > 0] or values [1 to MAX_VALUES numbers]."""
    def pair(second: dict) -> dict:
        return {"type": "array", "prefixItems": [number, second], "items": False,
                "minItems": 2}
    return {"type": "object", "minProperties": 1, "maxProperties": 1,
            "additionalProperties": False,
            "properties": {"uniform": pair(number),
                           "normal": pair({"type": "number", "exclusiveMinimum": 0}),
                           "values": {"type": "array", "items": number, "minItems": 1,
                                      "maxItems": MAX_VALUES}}}


def _plain(v: Any) -> Any:
    return list(v) if isinstance(v, tuple) else v


def _task_schema() -> dict:
    variants = []
    for template, kinds in TEMPLATE_OBJECTS.items():
        params = TEMPLATE_PARAMS[template]
        bounds = {p: _vector(2, _number(0, LENGTH_LIMIT, lo_open=True)) for p in params}
        for deg, rad in DEG_FIELDS.items():
            if rad in params:
                bounds[deg] = _vector(2, {"type": "number", "exclusiveMinimum": 0,
                                          "exclusiveMaximum": 90})
        if "half_angle" in bounds:
            bounds["half_angle"] = _vector(2, {"type": "number", "exclusiveMinimum": 0,
                                               "exclusiveMaximum": 1.5707963267948966})
        fixed = {f: _number(0, LENGTH_LIMIT, lo_open=True) for f in TEMPLATE_FIXED[template]}
        variants.append({
            "if": {"properties": {"template": {"const": template}}},
            "then": {"properties": {
                "bounds": {"type": "object", "properties": bounds,
                           "additionalProperties": False},
                "fixed": {"type": "object", "properties": fixed,
                          "additionalProperties": False}},
                "description": f"{template} fits: {', '.join(kinds)}"}})
    return {
        "type": "object",
        "required": ["id", "object", "template"],
        "properties": {"id": _text(), "object": _text(),
                       "template": {**_text(), "description": "a built-in template ("
                                    f"{', '.join(TEMPLATE_OBJECTS)}) or one of the scene's "
                                    "template files"},
                       "bounds": {"type": "object"}, "fixed": {"type": "object"}},
        "additionalProperties": False,
        "allOf": variants,
    }


def _object_schema() -> dict:
    size = _number(0, LENGTH_LIMIT, lo_open=True)
    return {
        "type": "object",
        "required": ["id", "kind", "position"],
        "properties": {
            "id": _text(),
            "kind": {"enum": list(OBJECT_KINDS)},
            "position": {**_vector(3, _number(-COORD_LIMIT, COORD_LIMIT)),
                         "description": "centre of the base, m"},
            "yaw": {**_number(-YAW_LIMIT, YAW_LIMIT), "description": "rad"},
            "yaw_deg": {**_number(-math.degrees(YAW_LIMIT), math.degrees(YAW_LIMIT)),
                        "description": "degrees"},
            "radius": {**size, "description": "m (mugs and cups)"},
            "height": {**size, "description": "m (mugs and cups)"},
            "half_extents": {**_vector(3, size), "description": "m (boxes)"},
            "mesh": {**_text(4096), "description": "mesh objects: the mesh file (OBJ, STL, "
                     "PLY, GLB), relative to the scene file"},
            **placement_properties(),
        },
        "additionalProperties": False,
        "allOf": [
            {"if": {"properties": {"kind": {"const": "box"}}},
             "then": {"required": ["half_extents"],
                      "not": {"anyOf": [{"required": ["radius"]}, {"required": ["height"]}]}},
             "else": {"not": {"required": ["half_extents"]}}},
            {"if": {"properties": {"kind": {"const": "mesh"}}},
             "then": {"required": ["mesh"],
                      "not": {"anyOf": [{"required": ["radius"]}, {"required": ["height"]}]}},
             "else": {"not": {"anyOf": [{"required": [k]} for k in ("mesh", *PLACEMENT_KEYS)]}}},
            *placement_rules(),
            {"not": {"required": ["yaw", "yaw_deg"]}},
            *({"not": {"required": [a, b]}} for a in ("yaw", "yaw_deg") for b in ("rpy", "quat")),
        ],
    }


def placement_properties() -> dict:
    """The mesh placement keys (``geometry_precompute.mesh_objects``), for scenes and a
    generator's mesh entries."""
    angle = _number(-1000.0, 1000.0)
    return {
        "up": {"enum": list(UPS), "description": "mesh objects: the file's up axis"},
        "unit": {"enum": list(MESH_UNITS), "description": "mesh objects: the file's length "
                 "unit (or scale)"},
        "scale": {**_number(0, 1000.0, lo_open=True),
                  "description": "mesh objects: metres per unit of the file"},
        "rpy": {**_vector(3, angle), "description": "mesh objects: roll, pitch, yaw (rad)"},
        "quat": {**_vector(4, angle), "description": "mesh objects: [w, x, y, z]"},
        "origin": {"enum": list(ORIGINS), "description": "mesh objects: \"file\" (the "
                   "file's origin at position) or \"base\" (the centre of its bounding box's "
                   "lowest face)"},
    }


def placement_rules() -> list[dict]:
    """unit or scale, rpy or quat: not both."""
    return [{"not": {"required": ["unit", "scale"]}}, {"not": {"required": ["rpy", "quat"]}}]


def scene_schema() -> dict:
    """The JSON Schema of a scene file."""
    return {
        "$schema": DRAFT,
        "title": "ShaCC scene",
        "description": "A scene file (docs/reference/scenes.md). Checked by the loader "
                       "only: " + "; ".join(LOADER_ONLY["scene"]) + ".",
        "type": "object",
        "required": ["name", "objects", "tasks"],
        "properties": {
            "name": _text(),
            "description": {"type": "string", "pattern": r"^[^\u0000-\u001f\u007f]*$"},
            "objects": {"type": "array", "minItems": 1, "items": _object_schema()},
            "tasks": {"type": "array", "minItems": 1, "items": _task_schema()},
            "settings": settings_schema(),
            "templates": {"type": "array", "items": _text(4096),
                          "description": "template files, relative to the scene file, "
                          "whose templates the tasks may use beside the built-in ones"},
        },
        "additionalProperties": False,
        # Without template files, a task's template is a built-in one.
        "if": {"not": {"required": ["templates"]}},
        "then": {"properties": {"tasks": {"items": {"properties": {
            "template": {"enum": list(TEMPLATE_OBJECTS)}}}}}},
    }


TEMPLATE_LOADER_ONLY = [
    "expressions use numbers, + - * /, parentheses, pi, sqrt sin cos tan radians, "
    "object.<measure>, settings.<geometry setting>, and (where allowed) the template's "
    "fixed dimensions and parameters",
    "center and dims are affine in the parameters, and every parameter is used by them",
    "object.half_x, half_y and half_z only in templates that fit boxes only",
    "aim is given where the parameters move the centre",
    "a fixed dimension is not also a parameter; names are not reserved words (pi, the "
    "functions, object, settings)",
    "a direction is not the zero vector; a template's name is not defined twice",
    "the space of each task is finite, with dimensions > 0 and a cone's half angle below "
    "pi/2 at both bounds (checked when a task is resolved)",
]


def templates_schema() -> dict:
    """The JSON Schema of a template file (``geometry_precompute.template_files``)."""

    name = r"^(?!.*__)[a-z_][a-z0-9_]{0,63}$"
    expr = {"anyOf": [{"type": "number"},
                      {"type": "string", "minLength": 1, "maxLength": EXPR_LIMIT,
                       "pattern": r"\S"}],
            "description": "a number, or an expression in a string (docs/reference/"
                           "templates.md)"}
    direction = _vector(3, {"type": "number"})
    param_fields = {"min": expr, "init": expr, "unit": {"enum": list(UNITS)}}
    assert set(param_fields) == _PARAM_KEYS
    param = {"type": "object", "required": ["min", "init"], "properties": param_fields,
             "additionalProperties": False}
    shapes = [{"if": {"properties": {"shape": {"const": k}}},
               "then": {"properties": {"dims": _vector(len(dims), expr)}}}
              for k, dims in SHAPE_DIMS.items()]
    template = {
        "type": "object",
        "required": ["fits", "shape", "center", "dims", "orientation"],
        "properties": {
            "description": {"type": "string", "maxLength": 300},
            "fits": {"type": "array", "minItems": 1, "uniqueItems": True,
                     "items": {"enum": list(OBJECT_KINDS)}},
            "shape": {"enum": list(SHAPE_DIMS)},
            "params": {"type": "object", "maxProperties": MAX_PARAMS,
                       "propertyNames": {"pattern": name},
                       "additionalProperties": param},
            "fixed": {"type": "object", "propertyNames": {"pattern": name},
                      "additionalProperties": expr},
            "center": _vector(3, expr),
            "rotation": {"anyOf": [{"enum": ["world", "object"]}, direction]},
            "dims": {"type": "array", "items": expr},
            "orientation": {"anyOf": [{"const": "point_to_axis"}, direction]},
            "aim": _vector(3, expr),
        },
        "additionalProperties": False,
        "allOf": shapes,
    }
    return {
        "$schema": DRAFT,
        "title": "ShaCC template file",
        "description": "Skill templates as data (docs/reference/templates.md). Checked by "
                       "the loader only: " + "; ".join(TEMPLATE_LOADER_ONLY) + ".",
        "type": "object",
        "required": ["templates"],
        "properties": {"templates": {"type": "object", "minProperties": 1,
                                     "maxProperties": MAX_TEMPLATES,
                                     "propertyNames": {"pattern": name},
                                     "additionalProperties": template}},
        "additionalProperties": False,
    }
