"""Every setting of SPEC section 16, with its default, type, rule and stage.

This module is the one place that holds defaults. A setting is read by its
flat name (``settings["dt"]``, ``settings["side_grasp.radius_init"]``), and a
:class:`Settings` is immutable: overrides make a new one, validated where it
is built (``with_overrides``).

Each setting has a *stage*, which tells a sweep what must be recomputed when
it changes:

- ``precompute``: the CPU geometry (spaces, C, clusters, Shrinking);
- ``starts``: the start poses (cheap NumPy, part of the bake);
- ``rollout``: numeric inputs of the jitted evaluation (never recompiles);
- ``analysis``: statistics only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from .errors import InputError


@dataclass(frozen=True)
class SettingSpec:
    name: str
    default: Any
    kind: str  # "float", "int", "choice", "int_pair", "float_pair"
    stage: str
    rule: str
    check: Callable[[Any], bool]
    choices: tuple[str, ...] = ()


def _pos(x: float) -> bool:
    return x > 0


def _nonneg(x: float) -> bool:
    return x >= 0


_SPECS: list[SettingSpec] = [
    SettingSpec("shrink_step", 0.05, "float", "precompute", "must be in (0, 1]",
                lambda x: 0 < x <= 1),
    SettingSpec("shrink_max_iter", 1000, "int", "precompute", "must be >= 1", lambda x: x >= 1),
    SettingSpec("dt", 0.02, "float", "rollout", "must be > 0", _pos),
    SettingSpec("v_max", 0.15, "float", "rollout", "must be > 0", _pos),
    SettingSpec("omega_max", 3.0, "float", "rollout", "must be > 0", _pos),
    SettingSpec("max_steps", 600, "int", "rollout", "must be >= 1", lambda x: x >= 1),
    SettingSpec("activation_tol", 1e-4, "float", "rollout", "must be >= 0", _nonneg),
    SettingSpec("ambiguity", "fail", "choice", "rollout", "must be one of fail, nearest",
                lambda x: True, ("fail", "nearest")),
    SettingSpec("start_grid", (6, 6), "int_pair", "starts", "must be two integers >= 1",
                lambda x: x[0] >= 1 and x[1] >= 1),
    SettingSpec("start_plane_offset", 0.45, "float", "starts", "must be > 0", _pos),
    SettingSpec("start_y_halfwidth", 0.45, "float", "starts", "must be >= 0", _nonneg),
    SettingSpec("start_z_range", (0.02, 0.30), "float_pair", "starts",
                "must be two numbers [low, high] with low <= high", lambda x: x[0] <= x[1]),
    SettingSpec("start_orientation", "random", "choice", "starts",
                "must be one of random, forward", lambda x: True, ("random", "forward")),
    SettingSpec("seed", 0, "int", "starts", "must be >= 0", _nonneg),
    SettingSpec("collision", "off", "choice", "rollout", "must be one of off, mjx",
                lambda x: True, ("off", "mjx")),
    # The gripper of collision = "mjx" (SPEC section 12b): two finger capsules along the
    # approach axis, ``opening`` apart (axis to axis), and a palm capsule across them.
    SettingSpec("gripper.finger_length", 0.05, "float", "rollout", "must be > 0", _pos),
    SettingSpec("gripper.finger_radius", 0.008, "float", "rollout", "must be > 0", _pos),
    SettingSpec("gripper.opening", 0.10, "float", "rollout", "must be > 0", _pos),
    SettingSpec("gripper.palm_radius", 0.015, "float", "rollout", "must be > 0", _pos),
    SettingSpec("mesh_sections", 32, "int", "precompute", "must be >= 8", lambda x: x >= 8),
    SettingSpec("entropy_variant", "formula", "choice", "precompute",
                "must be one of formula, reference_code", lambda x: True,
                ("formula", "reference_code")),
    SettingSpec("bootstrap_resamples", 10000, "int", "analysis", "must be >= 100",
                lambda x: x >= 100),
    # Template defaults (SPEC section 3's table).
    SettingSpec("side_grasp.radius_init", 0.20, "float", "precompute", "must be > 0", _pos),
    SettingSpec("side_grasp.radius_margin", 0.05, "float", "precompute", "must be >= 0", _nonneg),
    SettingSpec("side_grasp.height_margin", 0.05, "float", "precompute", "must be >= 0", _nonneg),
    SettingSpec("handle_grasp.length_init", 0.30, "float", "precompute", "must be > 0", _pos),
    SettingSpec("handle_grasp.length_min", 0.10, "float", "precompute", "must be > 0", _pos),
    # 30 and 10 degrees exactly; SPEC writes them rounded as 0.5236 and 0.1745.
    SettingSpec("handle_grasp.half_angle_init", math.radians(30.0), "float", "precompute",
                "must be in (0, pi/2)", lambda x: 0 < x < math.pi / 2),
    SettingSpec("handle_grasp.half_angle_min", math.radians(10.0), "float", "precompute",
                "must be in (0, pi/2)", lambda x: 0 < x < math.pi / 2),
    SettingSpec("handle_grasp.handle_offset", 0.03, "float", "precompute", "must be >= 0",
                _nonneg),
    SettingSpec("top_grasp.radius_init", 0.15, "float", "precompute", "must be > 0", _pos),
    SettingSpec("top_grasp.radius_margin", 0.02, "float", "precompute", "must be >= 0", _nonneg),
    SettingSpec("top_grasp.offset", 0.10, "float", "precompute", "must be >= 0", _nonneg),
    SettingSpec("top_grasp.thickness", 0.04, "float", "precompute", "must be > 0", _pos),
    SettingSpec("drawer_pull.depth_init", 0.25, "float", "precompute", "must be > 0", _pos),
    SettingSpec("drawer_pull.depth_min", 0.08, "float", "precompute", "must be > 0", _pos),
]

SPECS: Mapping[str, SettingSpec] = MappingProxyType({s.name: s for s in _SPECS})

# Object dimensions (SPEC section 3): per-object fields of a scene file, not settings,
# but defaults all the same, so they live here too.
OBJECT_DEFAULTS: Mapping[str, Mapping[str, float]] = MappingProxyType({
    "mug": MappingProxyType({"radius": 0.045, "height": 0.10}),
    "cup": MappingProxyType({"radius": 0.040, "height": 0.09}),
})


def _coerce(spec: SettingSpec, value: Any, source: str, field: str) -> Any:
    """Convert ``value`` to the setting's type or raise InputError."""

    def bad(rule: str) -> InputError:
        return InputError(source, field, rule)

    if spec.kind in ("float", "int"):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise bad(f"must be a number, got {value!r}")
        if not math.isfinite(value):
            raise bad("must be finite (no NaN or inf)")
        if spec.kind == "int":
            if float(value) != int(value):
                raise bad(f"must be an integer, got {value!r}")
            value = int(value)
        else:
            value = float(value)
    elif spec.kind == "choice":
        if not isinstance(value, str) or value not in spec.choices:
            raise bad(spec.rule + f", got {value!r}")
    elif spec.kind in ("int_pair", "float_pair"):
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise bad(f"must be a list of two numbers, got {value!r}")
        out = []
        for v in value:
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise bad(f"must hold two finite numbers, got {value!r}")
            if spec.kind == "int_pair":
                if float(v) != int(v):
                    raise bad(f"must hold two integers, got {value!r}")
                v = int(v)
            else:
                v = float(v)
            out.append(v)
        value = tuple(out)
    if not spec.check(value):
        raise bad(spec.rule + f", got {value!r}")
    return value


def parse_cli_value(name: str, text: str) -> Any:
    """Parse the text of ``--set NAME=VALUE`` by the setting's kind."""
    spec = SPECS.get(name)
    if spec is None:
        raise InputError("<--set>", name, f"unknown setting; known: {', '.join(SPECS)}")
    if spec.kind == "choice":
        return text
    if spec.kind in ("int_pair", "float_pair"):
        parts = text.strip("[]() ").replace(",", " ").split()
        try:
            return [float(p) for p in parts]
        except ValueError:
            raise InputError("<--set>", name, f"must be two numbers, got {text!r}") from None
    try:
        return float(text)
    except ValueError:
        raise InputError("<--set>", name, f"must be a number, got {text!r}") from None


class Settings(Mapping[str, Any]):
    """An immutable, validated set of every setting of SPEC section 16."""

    __slots__ = ("_values",)

    def __init__(self, values: Mapping[str, Any] | None = None):
        merged = {name: spec.default for name, spec in SPECS.items()}
        if values:
            merged.update(values)
        self._values = MappingProxyType(merged)

    def with_overrides(self, overrides: Mapping[str, Any], source: str = "<settings>",
                       prefix: str = "") -> Settings:
        """A new Settings with ``overrides`` validated; errors name ``source`` and the key."""
        new = dict(self._values)
        for name, value in overrides.items():
            spec = SPECS.get(name)
            if spec is None:
                raise InputError(source, prefix + name, "unknown setting (SPEC section 16 names)")
            new[name] = _coerce(spec, value, source, prefix + name)
        out = Settings.__new__(Settings)
        out._values = MappingProxyType(new)
        return out

    def __getitem__(self, key: str) -> Any:
        return self._values[key]

    def __reduce__(self):  # picklable for worker processes (values are already valid)
        return (Settings, (dict(self._values),))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Settings) and dict(self._values) == dict(other._values)

    def __hash__(self) -> int:
        return hash(tuple(sorted((k, str(v)) for k, v in self._values.items())))

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def by_stage(self, stage: str) -> dict[str, Any]:
        return {k: v for k, v in self._values.items() if SPECS[k].stage == stage}

    def to_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self._values.items()}

    def __repr__(self) -> str:
        changed = {k: v for k, v in self._values.items() if v != SPECS[k].default}
        return f"Settings({changed})"


DEFAULTS = Settings()
