"""The JSON Schema (draft 2020-12) of the scene file and of a settings table, built from
the loaders' own definitions: the allowed keys and templates of ``scene`` and the
limits of ``settings`` (every setting's rule carries its schema). ``shacc schema
scene`` prints it (``sweeps.schema_cmd`` adds the sweep config's), for editors whose
TOML plugin validates against a JSON Schema, and for other tools.

A schema cannot state every rule; those are listed in each schema's ``description``
and checked by the loaders alone (``LOADER_ONLY``).
"""

from __future__ import annotations

import math
from typing import Any

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

DRAFT = "https://json-schema.org/draft/2020-12/schema"

LOADER_ONLY = {
    "scene": [
        "object ids are unique, and so are task ids",
        "a task's object exists, and its template fits that object's kind",
        "bounds: min <= init",
        "yaw and yaw_deg (half_angle and half_angle_deg) are not both given",
        "objects do not interpenetrate (checked when the geometry is built)",
        "a mesh file exists and holds a solid (read when the scene is)",
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
                       "template": {"enum": list(TEMPLATE_OBJECTS)},
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
            "scale": {**size, "description": "mesh objects: metres per unit of the file"},
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
             "else": {"not": {"anyOf": [{"required": ["mesh"]}, {"required": ["scale"]}]}}},
        ],
    }


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
        },
        "additionalProperties": False,
    }
