"""Every setting of the settings (reference/settings), with its default, type, rule and stage.

This module is the one place that holds defaults. A setting is read by its
flat name (``settings["dt"]``, ``settings["side_grasp.radius_init"]``), and a
:class:`Settings` is immutable: overrides make a new one, validated where it
is built (``with_overrides``).

Each setting has a *stage*, which tells a sweep what must be recomputed when
it changes:

- ``precompute``: the CPU geometry (spaces, C, clusters, Shrinking);
- ``starts``: the start poses (cheap NumPy, part of the bake);
- ``rollout``: numeric inputs of the jitted evaluation (never recompiles);
- ``optimize``: the search of the ``optimized`` mode (reference/model; its starts are
  part of the bake, its sizes are static shapes of the search's program);
- ``analysis``: statistics only.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

from . import population
from .errors import InputError, SceneWarning, did_you_mean, shown
from .fileio import check_depth
from .population import POPULATED, Population


@dataclass(frozen=True)
class Param:
    """How a rollout setting crosses to the JAX half: the bake's field (one number per
    scene: a leaf of ``shacc_jax.Params``, so a sweep over it never recompiles), its
    dtype, the value it is given for a setting's value, and whether a value other than
    zero needs the stepped users' program (``schema.USER``)."""

    field: str
    dtype: str  # "float", "int" or "bool"
    encode: Callable[[Any], Any] = lambda v: v
    stepped: bool = False


@dataclass(frozen=True)
class SettingSpec:
    """One setting, declared once: its name, default, type, unit, valid range (rule,
    check and JSON Schema), stage, meaning and, for what the rollouts read, its bake
    encoding (:class:`Param`). ``shacc settings``, the JSON Schemas, the reference's
    table, the bake's Params fields (``schema.PARAMS``) and what the bake writes into
    them are all derived from these declarations."""

    name: str
    default: Any
    kind: str  # "float", "int", "choice", "int_pair", "float_pair"
    stage: str
    rule: str
    check: Callable[[Any], bool]
    choices: tuple[str, ...] = ()
    doc: str = ""  # one line of meaning, shown by `shacc settings`
    schema: Mapping[str, Any] = field(default_factory=dict)  # the rule, as JSON Schema
    unit: str = ""  # SI unit of a number ("" for a count, a probability or a choice)
    param: Param | None = None


# Ranges (issue: inputs past the numeric ranges). Every number has a finite range, so
# that nothing downstream overflows or divides by a rounding error: integers the JAX side
# stores as int32 stay below 2^31, lengths stay within LENGTH_LIMIT (coordinates within
# COORD_LIMIT of the origin, in scene.py), and a start grid within MAX_STARTS poses.
INT32_MAX = 2**31 - 1
LENGTH_LIMIT = 10.0       # m: any size of an object, a space, a margin or the gripper
COORD_LIMIT = 100.0       # m: positions and the start plane, from the origin
MAX_STARTS = 1 << 24      # start poses of one grid (16.7 M)
MAX_GRID_SIDE = 1 << 16


def _range(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False):
    """(rule text, check, JSON Schema) for a number in [lo, hi] (open ends where asked)."""
    def fmt(v: float) -> str:
        return str(int(v)) if float(v).is_integer() else f"{v:g}"
    rule = f"must be in {'(' if lo_open else '['}{fmt(lo)}, {fmt(hi)}{')' if hi_open else ']'}"

    def check(x: float) -> bool:
        return (lo < x if lo_open else lo <= x) and (x < hi if hi_open else x <= hi)
    schema = {"exclusiveMinimum" if lo_open else "minimum": lo,
              "exclusiveMaximum" if hi_open else "maximum": hi}
    return rule, check, schema


_TYPES: dict[str, dict[str, Any]] = {"float": {"type": "number"}, "int": {"type": "integer"},
          "choice": {"type": "string"},
          "int_pair": {"type": "array", "items": {"type": "integer"}, "minItems": 2,
                       "maxItems": 2},
          "float_pair": {"type": "array", "items": {"type": "number"}, "minItems": 2,
                         "maxItems": 2}}


def _spec(name: str, default: Any, kind: str, stage: str, rng: tuple, choices=(),
          unit: str = "", param: Param | None = None):
    schema = {**_TYPES[kind], **(rng[2] if len(rng) > 2 else {})}
    if choices:
        schema["enum"] = list(choices)
    return SettingSpec(name, default, kind, stage, rng[0], rng[1], tuple(choices),
                       schema=schema, unit=unit, param=param)


def _choice(*options: str) -> tuple:
    return f"must be one of {', '.join(options)}", lambda x: True


_POS_LEN = _range(0, LENGTH_LIMIT, lo_open=True)
_NONNEG_LEN = _range(0, LENGTH_LIMIT)
_HALF_ANGLE = ("must be in (0, pi/2)", lambda x: 0 < x < math.pi / 2,
               {"exclusiveMinimum": 0, "exclusiveMaximum": math.pi / 2})
# The product and the order of two items are rules a JSON Schema cannot state (listed in
# the schema's description by geometry_precompute.file_schema).
_GRID = (f"must be two integers in [1, {MAX_GRID_SIDE}] with n_y * n_z <= {MAX_STARTS}",
         lambda x: 1 <= x[0] <= MAX_GRID_SIDE and 1 <= x[1] <= MAX_GRID_SIDE
         and x[0] * x[1] <= MAX_STARTS,
         {"items": {"type": "integer", "minimum": 1, "maximum": MAX_GRID_SIDE}})
_Z_RANGE = (f"must be two numbers [low, high] in [-{COORD_LIMIT:g}, {COORD_LIMIT:g}] with "
            "low <= high", lambda x: -COORD_LIMIT <= x[0] <= x[1] <= COORD_LIMIT,
            {"items": {"type": "number", "minimum": -COORD_LIMIT, "maximum": COORD_LIMIT}})

_SPECS: list[SettingSpec] = [
    # At most ceil(1 / sigma) passes: the lower bound keeps that to a thousand.
    _spec("shrink_step", 0.05, "float", "precompute", _range(1e-3, 1)),
    _spec("shrink_max_iter", 1000, "int", "precompute", _range(1, 10**6)),
    _spec("dt", 0.02, "float", "rollout", _range(0, 10, lo_open=True), unit="s",
          param=Param("dt", "float")),
    _spec("v_max", 0.15, "float", "rollout", _range(0, 100, lo_open=True), unit="m/s",
          param=Param("v_max", "float")),
    _spec("omega_max", 3.0, "float", "rollout", _range(0, 1000, lo_open=True), unit="rad/s",
          param=Param("omega_max", "float")),
    _spec("max_steps", 600, "int", "rollout", _range(1, 10**9), param=Param("max_steps", "int")),
    _spec("activation_tol", 1e-4, "float", "rollout", _range(0, 1), unit="m",
          param=Param("activation_tol", "float")),
    _spec("ambiguity", "fail", "choice", "rollout", _choice("fail", "nearest"),
          ("fail", "nearest"), param=Param("ambiguity_nearest", "bool", lambda v: v == "nearest")),
    _spec("start_grid", (6, 6), "int_pair", "starts", _GRID),
    _spec("start_plane_offset", 0.45, "float", "starts", _range(0, COORD_LIMIT, lo_open=True),
          unit="m"),
    _spec("start_y_halfwidth", 0.45, "float", "starts", _range(0, COORD_LIMIT), unit="m"),
    _spec("start_z_range", (0.02, 0.30), "float_pair", "starts", _Z_RANGE, unit="m"),
    _spec("start_orientation", "random", "choice", "starts", _choice("random", "forward"),
          ("random", "forward")),
    # Also the seed of the simulated users' random numbers: the rollouts read it.
    _spec("seed", 0, "int", "starts", _range(0, INT32_MAX), param=Param("user_seed", "int")),
    _spec("collision", "off", "choice", "rollout", _choice("off", "on"), ("off", "on"),
          param=Param("collision", "bool", lambda v: v == "on")),
    # The simulated user (reference/model, "Simulated users"): all zero is the paper's
    # perfect user. Angles in rad, lengths in m; the ranges catch degrees and centimetres.
    _spec("user_noise", 0.0, "float", "rollout", _range(0, math.pi / 2), unit="rad",
          param=Param("user_noise", "float", stepped=True)),
    _spec("user_noise_tau", 0.0, "float", "rollout", _range(0, 100), unit="s",
          param=Param("user_noise_tau", "float")),
    _spec("user_tremor", 0.0, "float", "rollout", _range(0, 0.05), unit="m",
          param=Param("user_tremor", "float", stepped=True)),
    _spec("user_tremor_hz", 5.0, "float", "rollout", _range(0, 50, lo_open=True), unit="Hz",
          param=Param("user_tremor_hz", "float")),
    _spec("user_input", "3d", "choice", "rollout", _choice("3d", "modes"), ("3d", "modes"),
          param=Param("user_input_modes", "bool", lambda v: v == "modes", stepped=True)),
    _spec("user_mode_switch_s", 0.5, "float", "rollout", _range(0, 60), unit="s",
          param=Param("user_mode_switch_s", "float")),
    _spec("user_switch", 0.0, "float", "rollout", _range(0, 1),
          param=Param("user_switch", "float", stepped=True)),
    _spec("user_switch_at", 0.5, "float", "rollout", _range(0, 1, lo_open=True, hi_open=True),
          param=Param("user_switch_at", "float")),
    _spec("user_aim", "space", "choice", "rollout", _choice("space", "object"),
          ("space", "object"),
          param=Param("user_aim_object", "bool", lambda v: v == "object", stepped=True)),
    _spec("activation_check", "steps", "choice", "rollout", _choice("steps", "swept"),
          ("steps", "swept"),
          param=Param("activation_swept", "bool", lambda v: v == "swept", stepped=True)),
    # Assistance that infers intent (reference/model, "Intent inference"): the modes
    # blend, ho and shacc_ho read these; the paper's modes do not.
    _spec("intent_beta", 0.05, "float", "rollout", _range(0, 100, lo_open=True), unit="m",
          param=Param("intent_beta", "float")),
    _spec("blend_threshold", 0.4, "float", "rollout", _range(0, 1),
          param=Param("blend_threshold", "float")),
    _spec("ho_gain", 0.5, "float", "rollout", _range(0, 10),
          param=Param("ho_gain", "float")),
    # The gripper of collision = "on" (reference/mujoco): two finger capsules along the
    # approach axis, ``opening`` apart (axis to axis), and a palm capsule across them.
    _spec("gripper.finger_length", 0.05, "float", "rollout", _range(0, 1, lo_open=True), unit="m",
          param=Param("gripper_finger_length", "float")),
    _spec("gripper.finger_radius", 0.008, "float", "rollout", _range(0, 1, lo_open=True), unit="m",
          param=Param("gripper_finger_radius", "float")),
    _spec("gripper.opening", 0.10, "float", "rollout", _range(0, 1, lo_open=True), unit="m",
          param=Param("gripper_opening", "float")),
    _spec("gripper.palm_radius", 0.015, "float", "rollout", _range(0, 1, lo_open=True), unit="m",
          param=Param("gripper_palm_radius", "float")),
    _spec("mesh_sections", 32, "int", "precompute", _range(8, 1024)),
    _spec("entropy_variant", "formula", "choice", "precompute",
          _choice("formula", "reference_code"), ("formula", "reference_code")),
    _spec("bootstrap_resamples", 10000, "int", "analysis", _range(100, 10**7)),
    # The optimized mode's search (reference/model). A population of at least 4 is what
    # CMA-ES needs to adapt; the products of these sizes bound the search's work.
    _spec("optimize_starts", 64, "int", "optimize", _range(1, 1 << 16)),
    _spec("optimize_seed", 1, "int", "optimize", _range(0, INT32_MAX)),
    _spec("optimize_population", 64, "int", "optimize", _range(4, 4096)),
    _spec("optimize_generations", 30, "int", "optimize", _range(1, 10000)),
    # Selection by validation (reference/model, revised): a third set of starts, its own
    # seed, the search's best few distinct candidates (a static size of its program).
    _spec("optimize_validation_starts", 256, "int", "optimize", _range(1, 1 << 16)),
    _spec("optimize_validation_seed", 2, "int", "optimize", _range(0, INT32_MAX)),
    _spec("optimize_candidates", 8, "int", "optimize", _range(1, 64)),
    _spec("optimize_selection", "validation", "choice", "optimize",
          _choice("validation", "search"), ("validation", "search")),
    # Template defaults (the scene format's table).
    _spec("side_grasp.radius_init", 0.20, "float", "precompute", _POS_LEN, unit="m"),
    _spec("side_grasp.radius_margin", 0.05, "float", "precompute", _NONNEG_LEN, unit="m"),
    _spec("side_grasp.height_margin", 0.05, "float", "precompute", _NONNEG_LEN, unit="m"),
    _spec("handle_grasp.length_init", 0.30, "float", "precompute", _POS_LEN, unit="m"),
    _spec("handle_grasp.length_min", 0.10, "float", "precompute", _POS_LEN, unit="m"),
    # 30 and 10 degrees exactly; not the rounded 0.5236 and 0.1745.
    _spec("handle_grasp.half_angle_init", math.radians(30.0), "float", "precompute",
          _HALF_ANGLE, unit="rad"),
    _spec("handle_grasp.half_angle_min", math.radians(10.0), "float", "precompute",
          _HALF_ANGLE, unit="rad"),
    _spec("handle_grasp.handle_offset", 0.03, "float", "precompute", _NONNEG_LEN, unit="m"),
    _spec("top_grasp.radius_init", 0.15, "float", "precompute", _POS_LEN, unit="m"),
    _spec("top_grasp.radius_margin", 0.02, "float", "precompute", _NONNEG_LEN, unit="m"),
    _spec("top_grasp.offset", 0.10, "float", "precompute", _NONNEG_LEN, unit="m"),
    _spec("top_grasp.thickness", 0.04, "float", "precompute", _POS_LEN, unit="m"),
    _spec("drawer_pull.depth_init", 0.25, "float", "precompute", _POS_LEN, unit="m"),
    _spec("drawer_pull.depth_min", 0.08, "float", "precompute", _POS_LEN, unit="m"),
]

# One line of meaning per setting (reference/scenes, model, statistics, mujoco, settings).
_DOCS = {
    "shrink_step": "Shrinking's step: the fraction of its range a space loses per pass (sigma)",
    "shrink_max_iter": "most Shrinking passes",
    "dt": "Automaton time step",
    "v_max": "the simulated user's speed towards its task's space",
    "omega_max": "the arm's rotation limit while the meta skill turns the gripper",
    "max_steps": "steps before a rollout ends as a timeout (T_max)",
    "activation_tol": "a skill activates when the gripper is within this of its space",
    "ambiguity": "several spaces at once: fail (ambiguous) or nearest (activate the closest)",
    "start_grid": "start poses on the start plane: [n_y, n_z]",
    "start_plane_offset": "start plane's distance in front of the frontmost object",
    "start_y_halfwidth": "start plane's half width around the objects' mean y",
    "start_z_range": "start plane's height band [low, high]",
    "start_orientation": "start orientations: random (seeded) or forward (approach +x)",
    "seed": "seed of the random start orientations and of the simulated user's random "
            "numbers",
    "collision": "gripper collision checking: off, or on (exact capsule checks against "
                 "cylinders and boxes, as MuJoCo's; \"mjx\", its old name, still works)",
    "user_noise": "simulated user, a wandering hand: each step's direction turned by the "
                  "part across it of a rotation vector of N(0, user_noise^2) components",
    "user_noise_tau": "simulated user: the wandering hand's correlation time (an "
                      "Ornstein-Uhlenbeck process; 0: white noise, a new vector every step)",
    "user_input": "simulated user's input device: 3d (the whole displacement at once) or "
                  "modes (a two-mode joystick: horizontal plane or vertical, one at a time)",
    "user_mode_switch_s": "simulated user, modes: the time a switch of mode costs, without "
                          "motion",
    "user_switch": "simulated user, a change of mind: the probability that a rollout first "
                   "heads for another task of the scene",
    "user_switch_at": "simulated user, a change of mind: the user turns to its task once the "
                      "distance to the first task's space has fallen to (1 - this) of its "
                      "value at the start",
    "user_tremor": "simulated user: amplitude of a tremor of the gripper about the "
                   "commanded position, along a random axis",
    "user_tremor_hz": "simulated user: the tremor's frequency",
    "user_aim": "simulated user: steers at the closest point of its task's space, or at "
                "the object (the template's aim point)",
    "intent_beta": "intent inference: the posterior's temperature, P(task) proportional to "
                   "exp(-(distance left to its space - that at the start) / this); larger "
                   "is less sure",
    "blend_threshold": "the blend mode: the confidence (best posterior minus the second) "
                       "from which the robot assists towards the most likely task",
    "ho_gain": "the ho and shacc_ho modes: the posterior-weighted pull towards the tasks' "
               "spaces, in units of the step length v_max dt",
    "activation_check": "where activation is checked: at the step positions (steps, the "
                        "paper's), or along each step's segment, at its first entry into a "
                        "space (swept)",
    "gripper.finger_length": "collision gripper: finger capsule length",
    "gripper.finger_radius": "collision gripper: finger capsule radius",
    "gripper.opening": "collision gripper: distance between the finger axes",
    "gripper.palm_radius": "collision gripper: palm capsule radius",
    "mesh_sections": "mesh sections of the clutteredness booleans (pairs with no fast path)",
    "entropy_variant": "entropic clutteredness h: formula (paper) or reference_code",
    "bootstrap_resamples": "resamples of the bootstrap confidence intervals",
    "optimize_starts": "optimized mode: start poses the search scores candidates on",
    "optimize_seed": "optimized mode: seed of the search's starts and of its random draws",
    "optimize_population": "optimized mode: candidates per generation of the search",
    "optimize_generations": "optimized mode: generations of the search",
    "optimize_validation_starts": "optimized mode: start poses that choose among the "
                                  "search's best candidates, Shrinking and the initial sizes",
    "optimize_validation_seed": "optimized mode: seed of the validation starts",
    "optimize_candidates": "optimized mode: the search's best distinct candidates validated",
    "optimize_selection": "optimized mode: validation (ties to lower C, then larger spaces; "
                          "chosen on the validation starts, ties to Shrinking) or search "
                          "(the search's best on its own starts, ties to larger spaces)",
    "side_grasp.radius_init": "side grasp cylinder's initial radius",
    "side_grasp.radius_margin": "side grasp's smallest radius is object radius + this",
    "side_grasp.height_margin": "side grasp cylinder reaches this far above the object",
    "handle_grasp.length_init": "handle grasp cone's initial length",
    "handle_grasp.length_min": "handle grasp cone's smallest length",
    "handle_grasp.half_angle_init": "handle grasp cone's initial half-angle",
    "handle_grasp.half_angle_min": "handle grasp cone's smallest half-angle",
    "handle_grasp.handle_offset": "handle grasp point's distance outside the cup's wall",
    "top_grasp.radius_init": "top grasp disk's initial radius",
    "top_grasp.radius_margin": "top grasp's smallest radius is object radius + this",
    "top_grasp.offset": "top grasp disk's centre height above the object's top",
    "top_grasp.thickness": "top grasp disk's thickness",
    "drawer_pull.depth_init": "drawer pull box's initial depth out from the face",
    "drawer_pull.depth_min": "drawer pull box's smallest depth",
}
_SPECS = [replace(s, doc=_DOCS[s.name]) for s in _SPECS]

SPECS: Mapping[str, SettingSpec] = MappingProxyType({s.name: s for s in _SPECS})


def population_range(name: str) -> tuple[float, float]:
    """The closed range that draws of a population of ``name`` (of ``POPULATED``) keep
    to: the setting's range, an open end moved inside by a millionth of its width (a
    drawn ``user_switch_at`` stays inside (0, 1)). The truncated normal is truncated to it.

    >>> population_range("user_switch_at")
    (1e-06, 0.999999)
    """
    sch = SPECS[name].schema
    lo = sch.get("minimum", sch.get("exclusiveMinimum"))
    hi = sch.get("maximum", sch.get("exclusiveMaximum"))
    inset = 1e-6 * (hi - lo)
    return (lo + inset if "exclusiveMinimum" in sch else lo,
            hi - inset if "exclusiveMaximum" in sch else hi)


def describe() -> list[dict[str, str]]:
    """Every setting as a row (name, default, type, unit, rule, stage, meaning): what
    ``shacc settings`` prints."""
    kinds = {"float": "number", "int": "integer", "choice": "one of",
             "int_pair": "[int, int]", "float_pair": "[number, number]"}
    rows = []
    for s in _SPECS:
        default = list(s.default) if isinstance(s.default, tuple) else s.default
        kind = kinds[s.kind] + (" " + "|".join(s.choices) if s.choices else "")
        rows.append({"name": s.name, "default": str(default),
                     "type": kind + (" or population" if s.name in POPULATED else ""),
                     "unit": s.unit, "rule": s.rule, "stage": s.stage, "meaning": s.doc})
    return rows

def describe_user(settings: Mapping[str, Any]) -> str:
    """The simulated user a scene's settings give, in words (``shacc evaluate`` prints
    it): "perfect" for the paper's Automaton, else each imperfection, a population as
    its distribution.

    >>> describe_user(Settings())
    "perfect (the paper's Automaton: straight to the task's space)"
    >>> describe_user(Settings().with_overrides({"user_noise": 0.2, "user_noise_tau": 0.5}))
    'wandering hand 0.2 rad (correlation time 0.5 s)'
    """
    def text(name: str) -> str:
        v = settings[name]
        return v.text() if isinstance(v, Population) else f"{v:g}"

    def on(name: str) -> bool:
        v = settings[name]
        return isinstance(v, Population) or v > 0

    parts = []
    if on("user_noise"):
        tau = settings["user_noise_tau"]
        kind = "white noise" if not isinstance(tau, Population) and tau == 0 else \
            f"correlation time {text('user_noise_tau')} s"
        parts.append(f"wandering hand {text('user_noise')} rad ({kind})")
    if on("user_tremor"):
        parts.append(f"tremor {text('user_tremor')} m at {text('user_tremor_hz')} Hz")
    if settings["user_input"] == "modes":
        parts.append(f"two-mode joystick ({text('user_mode_switch_s')} s a switch)")
    if on("user_switch"):
        parts.append(f"change of mind with probability {text('user_switch')}, turning at "
                     f"{text('user_switch_at')} of the way")
    if settings["user_aim"] == "object":
        parts.append("aims at the object")
    if settings["activation_check"] == "swept":
        parts.append("swept activation check")
    return "; ".join(parts) or "perfect (the paper's Automaton: straight to the task's space)"


# Object dimensions (reference/scenes): per-object fields of a scene file, not settings,
# but defaults all the same, so they live here too.
OBJECT_DEFAULTS: Mapping[str, Mapping[str, float]] = MappingProxyType({
    "mug": MappingProxyType({"radius": 0.045, "height": 0.10}),
    "cup": MappingProxyType({"radius": 0.040, "height": 0.09}),
})


def _real(v: Any) -> bool:
    """A finite number (an integer of any size counts: it is range-checked as one)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    return isinstance(v, int) or math.isfinite(v)


def _coerce(spec: SettingSpec, value: Any, source: str, field: str) -> Any:
    """Convert ``value`` to the setting's type or raise InputError. Integers are checked
    against the range before any conversion (one beyond 64 bits has no float)."""

    def bad(rule: str) -> InputError:
        return InputError(source, field, rule)

    if spec.name == "collision" and value == OLD_COLLISION:
        _warn_once(f"{source}: {field}: \"{OLD_COLLISION}\" is the old name of \"on\" (the "
                   "checks are exact closed forms, not MJX's); write collision = \"on\"")
        value = "on"
    if spec.name in POPULATED and population.is_table(value):
        return population.parse(value, spec.check, spec.rule, source, field)
    if spec.kind in ("float", "int"):
        if isinstance(value, bool) or not isinstance(value, int | float):
            more = " or a population table" if spec.name in POPULATED else ""
            raise bad(f"must be a number{more}, got {shown(value)}")
        if not _real(value):
            raise bad("must be finite (no NaN or inf)")
        if not spec.check(value):
            raise bad(spec.rule + f", got {shown(value)}")
        if spec.kind == "int":
            if isinstance(value, float) and not value.is_integer():
                raise bad(f"must be an integer, got {shown(value)}")
            value = int(value)
        else:
            value = float(value)
    elif spec.kind == "choice":
        if not isinstance(value, str) or value not in spec.choices:
            raise bad(spec.rule + f", got {shown(value)}")
    elif spec.kind in ("int_pair", "float_pair"):
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise bad(f"must be a list of two numbers, got {shown(value)}")
        if not all(_real(v) for v in value):
            raise bad(f"must hold two finite numbers, got {shown(value)}")
        if not spec.check(value):
            raise bad(spec.rule + f", got {shown(value)}")
        if spec.kind == "int_pair":
            if any(isinstance(v, float) and not v.is_integer() for v in value):
                raise bad(f"must hold two integers, got {shown(value)}")
            value = tuple(int(v) for v in value)
        else:
            value = tuple(float(v) for v in value)
    if not spec.check(value):
        raise bad(spec.rule + f", got {shown(value)}")
    _warn_unit(spec, value, source, field)
    return value


# Legal settings that are almost certainly a unit mistake (a warning, not an error).
OMEGA_LIMIT = 20 * math.pi   # rad/s: ten turns a second; degrees per second were meant
TEMPLATE_LENGTH_LIMIT = 1.0  # m: a template size above this looks like centimetres


# The collision setting's value before it was renamed; read as "on", with a warning.
OLD_COLLISION = "mjx"


# Settings that no longer exist, with why and what replaces them: naming one anywhere (a
# scene, a sweep config, --set, a population) is a one-line error.
WITHDRAWN = {
    "user_lag": "withdrawn: repeating the previous step is the same step for a user who moves "
                "in a straight line, so it changed nothing; use user_noise with "
                "user_noise_tau (a wandering hand), user_input = \"modes\" (a two-mode "
                "joystick) or user_switch (a change of mind)",
}


def _unknown(name: str) -> str:
    """The rule for a name that is no setting."""
    return WITHDRAWN.get(name, f"unknown setting{did_you_mean(name, SPECS)} (`shacc "
                               "settings` lists them)")


def _warn_once(message: str) -> None:

    if message not in _WARNED:  # settings are validated again at every override
        _WARNED.add(message)
        warnings.warn(SceneWarning(message), stacklevel=5)


def _warn_unit(spec: SettingSpec, value: Any, source: str, field: str) -> None:

    text = None
    if spec.name == "omega_max" and value > OMEGA_LIMIT:
        text = (f"{value:g} rad/s is more than ten turns a second; if degrees per second "
                f"were meant, that is {math.radians(value):.4f} rad/s")
    elif (spec.name.split(".")[0] in ("side_grasp", "handle_grasp", "top_grasp",
                                       "drawer_pull") and "angle" not in spec.name
          and spec.kind == "float" and value > TEMPLATE_LENGTH_LIMIT):
        text = f"{value:g} m is a very large task space; centimetres? {value:g} cm is " \
               f"{value / 100:g} m"
    message = f"{source}: {field}: {text}"
    if text and message not in _WARNED:  # settings are validated again at every override
        _WARNED.add(message)
        warnings.warn(SceneWarning(message), stacklevel=4)


_WARNED: set[str] = set()


def _cli_number(name: str, text: str) -> int | float:
    """A number written on the command line: an integer stays one (of any size, for
    the range check to refuse), anything else is a float."""
    t = text.strip()
    try:
        return int(t)
    except ValueError:
        pass
    try:
        return float(t)
    except ValueError:
        raise InputError("<--set>", name, f"must be a number, got {shown(text)}") from None


def parse_cli_value(name: str, text: str) -> Any:
    """Parse the text of ``--set NAME=VALUE`` by the setting's kind."""
    spec = SPECS.get(name)
    if spec is None and name in WITHDRAWN:
        raise InputError("<--set>", name, WITHDRAWN[name])
    if spec is None:
        raise InputError("<--set>", name, _unknown(name))
    if spec.kind == "choice":
        return text
    if name in POPULATED and text.strip().startswith("{"):
        try:
            return tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError as e:
            raise InputError("<--set>", name, f"a population is an inline TOML table such as "
                             f"{{uniform = [0, 0.4]}}: {e}") from None
    if spec.kind in ("int_pair", "float_pair"):
        parts = text.strip("[]() ").replace(",", " ").split()
        if len(parts) != 2:
            raise InputError("<--set>", name, f"must be two numbers, got {shown(text)}")
        return [_cli_number(name, p) for p in parts]
    return _cli_number(name, text)


def flatten_settings(table: Mapping[str, Any], source: str = "<settings>",
                     prefix: str = "") -> dict[str, Any]:
    """A settings table with TOML's nested form of dotted names made flat.

    ``side_grasp.radius_init = 0.18`` written bare is read by TOML as the table
    ``{"side_grasp": {"radius_init": 0.18}}``; quoted, as the key
    ``"side_grasp.radius_init"``. Both mean one setting (reference/settings), so every
    reader of a settings table (scenes, sweep axes, points and fixed settings) calls
    this first. Both forms of one name in one table are an error, not a silent pick.
    Names are not checked here: the caller's validation sees the full dotted name, so
    an unknown name inside a nested table is reported as, e.g., ``side_grasp.foo``.
    """
    out: dict[str, Any] = {}

    def walk(t: Mapping[str, Any], stem: str) -> None:
        for key, value in t.items():
            name = f"{stem}{key}"
            if isinstance(value, Mapping) and name not in POPULATED and name not in WITHDRAWN:
                # a population stays whole (and a withdrawn name is reported as itself)
                walk(value, name + ".")
            elif name in out:
                raise InputError(source, prefix + name, "given twice (once quoted, once as a "
                                 "nested table); write it once")
            else:
                out[name] = value

    if not isinstance(table, Mapping):
        raise InputError(source, prefix.rstrip(".") or "<settings>",
                         "must be a table of setting = value")
    check_depth(table, source)
    walk(table, "")
    return out


class Settings(Mapping[str, Any]):
    """An immutable, validated set of every setting (reference/settings): a read-only
    mapping from a setting's name (``"v_max"``, ``"gripper.opening"``) to its value, in
    the units the reference gives (m, s, rad). Built from the defaults; a scene's
    ``[settings]``, a sweep point and ``--set`` override it through
    :meth:`with_overrides`, which checks each value's type and range.

    Example::

        >>> from geometry_precompute import Settings
        >>> s = Settings().with_overrides({"v_max": 0.5})
        >>> s["v_max"], s["dt"]
        (0.5, 0.02)
    """

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
        for name, value in flatten_settings(overrides, source, prefix).items():
            spec = SPECS.get(name)
            if spec is None:
                raise InputError(source, prefix + name, _unknown(name))
            new[name] = _coerce(spec, value, source, prefix + name)
        if new["collision"] != "off" and new["activation_check"] != "steps":
            # A swept step may enter a space part-way: which comes first, that entry or
            # a penetration somewhere on the step, is not defined by step-wise checks.
            raise InputError(source, prefix + "activation_check",
                             "the swept activation check is not checked for collisions: set "
                             "collision = off, or activation_check = \"steps\"")
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
        """The values as plain JSON values (pairs as lists, populations as tables)."""
        return {k: (list(v) if isinstance(v, tuple) else v.to_json()
                    if isinstance(v, Population) else v) for k, v in self._values.items()}

    def __repr__(self) -> str:
        changed = {k: v for k, v in self._values.items() if v != SPECS[k].default}
        return f"Settings({changed})"


DEFAULTS = Settings()
