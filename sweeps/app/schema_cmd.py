"""``shacc schema scene|sweep|templates``: the JSON Schema of a scene file, a sweep
config or a template file, built from the loaders' own definitions
(``geometry_precompute.file_schema`` for scenes, settings and templates; the sweep
config's keys and limits from ``sweeps.config``)."""

from __future__ import annotations

import json

from geometry_precompute.file_schema import (
    DRAFT,
    _vector,
    placement_properties,
    placement_rules,
    scene_schema,
    settings_schema,
    templates_schema,
)
from geometry_precompute.generate import GENERATOR_KINDS, MAX_TASKS, PRESETS
from geometry_precompute.schema import ALL_MODES
from geometry_precompute.settings import INT32_MAX
from sweeps.config import MAX_CHUNK, MAX_COUNT

LOADER_ONLY = [
    "source.path names a folder holding *.toml scene files",
    "source.tasks: min <= max; source.seed + source.count stays a 32-bit integer",
    "the axes and [[points]] give at most 100 000 points",
    "every template of the settings fits the scenes' objects",
    "source.generator: ranges low <= high, templates that fit their entry's kind, fields "
    "of the entry's kind only, a mesh folder that holds mesh files (each placed on the "
    "table, its meshes.toml naming files of the folder), template files that exist and "
    "are valid",
    "the rules of a scene's [settings] that a schema cannot state, for every value",
]


def _generator_schema() -> dict:
    """A random source's [source.generator] (``geometry_precompute.generate``)."""
    def span(hi: float = 10.0) -> dict:
        number = {"type": "number", "exclusiveMinimum": 0, "maximum": hi}
        return {"anyOf": [number, _vector(2, number)]}

    entry = {
        "type": "object", "required": ["kind"],
        "properties": {
            "kind": {"enum": list(GENERATOR_KINDS)},
            "weight": {"type": "number", "exclusiveMinimum": 0, "maximum": 1e6},
            "radius": span(), "height": span(), "half_extents": _vector(3, span()),
            "folder": {"type": "string", "minLength": 1},
            **placement_properties(),
            "templates": {"type": "object", "minProperties": 1,
                          "additionalProperties": {"type": "number", "exclusiveMinimum": 0,
                                                   "maximum": 1e6}}},
        "additionalProperties": False, "allOf": placement_rules()}
    return {"type": "object", "properties": {
        "table": _vector(2, {"type": "number", "exclusiveMinimum": 0, "maximum": 20}),
        "sigma": {"type": "number", "exclusiveMinimum": 0, "maximum": 10},
        "gap": {"type": "number", "minimum": 0, "maximum": 1},
        "template_files": {"type": "array", "items": {"type": "string", "minLength": 1},
                           "description": "template files (relative to the config) whose "
                           "templates the entries may name beside the built-in ones"},
        "objects": {"type": "array", "minItems": 1, "items": entry}},
        "additionalProperties": False}


def sweep_schema() -> dict:
    """The JSON Schema of a sweep config (``sweeps.config``)."""
    random_source = {
        "type": "object", "required": ["kind", "count"],
        "properties": {"kind": {"const": "random"},
                       "count": {"type": "integer", "minimum": 1, "maximum": MAX_COUNT},
                       "tasks": _vector(2, {"type": "integer", "minimum": 1,
                                            "maximum": MAX_TASKS}),
                       "sampling": {"enum": ["uniform", "gaussian", "both"]},
                       "seed": {"type": "integer", "minimum": 0, "maximum": INT32_MAX},
                       "preset": {"enum": list(PRESETS)},
                       "generator": _generator_schema()},
        "additionalProperties": False}
    files_source = {
        "type": "object", "required": ["kind", "path"],
        "properties": {"kind": {"const": "files"}, "path": {"type": "string"}},
        "additionalProperties": False}
    return {
        "$schema": DRAFT,
        "title": "ShaCC sweep config",
        "description": "A sweep config (README, Sweeps). Checked by the loader only: "
                       + "; ".join(LOADER_ONLY) + ".",
        "type": "object",
        "required": ["source"],
        "properties": {
            "name": {"type": "string", "minLength": 1},
            "modes": {"type": "array", "minItems": 1, "uniqueItems": True,
                      "items": {"enum": list(ALL_MODES)}},
            "chunk": {"type": "integer", "minimum": 1, "maximum": MAX_CHUNK},
            "source": {"oneOf": [random_source, files_source]},
            "settings": settings_schema(),
            "axes": settings_schema(values_as_lists=True),
            "points": {"type": "array", "items": settings_schema()},
            "scheduler": {"type": "string", "pattern": r"\S"},
        },
        "additionalProperties": False,
    }


def cmd_schema(args) -> int:

    schema = {"scene": scene_schema, "sweep": sweep_schema,
              "templates": templates_schema}[args.kind]()
    print(json.dumps(schema, indent=1))
    return 0
