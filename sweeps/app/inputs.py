"""Scenes and settings from the command line, with no JAX: ``--set NAME=VALUE``
arguments and a scene file precomputed under them (``shacc precompute`` needs only
this and the CPU half)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from geometry_precompute import InputError, PrecomputeResult, load_scene, precompute
from geometry_precompute.settings import parse_cli_value


def parse_sets(pairs: Sequence[str]) -> dict:
    """``--set NAME=VALUE`` arguments as a dict of settings (validated later)."""
    out = {}
    for item in pairs:
        if "=" not in item:
            raise InputError("<--set>", item, "must be NAME=VALUE")
        name, text = item.split("=", 1)
        out[name.strip()] = parse_cli_value(name.strip(), text.strip())
    return out


def load_and_precompute(path: str | Path, sets: Sequence[str]) -> PrecomputeResult:
    """One scene file with ``--set`` overrides (the settings' precedence)."""
    scene = load_scene(path)
    return precompute(scene, scene.settings(overrides=parse_sets(sets)))
