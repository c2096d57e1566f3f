"""Skill templates as data: template files, their expressions and their checks.

A template file is TOML with one table per template under ``[templates]``
(docs/reference/templates.md has the format in full). A template names the object kinds
it fits, the shape of its position space (``cylinder``, ``disk``, ``cone``, ``box``),
its shrinkable parameters with their bounds [min, init], fixed dimensions, the space's
centre, rotation and dimensions, its orientation space and the point a user who aims at
the object steers to. Every number may be an expression:

- numbers, ``+ - * /``, parentheses, ``pi`` and ``sqrt sin cos tan radians``;
- the object's measures ``object.radius``, ``object.height`` (every kind) and
  ``object.half_x``, ``object.half_y``, ``object.half_z`` (boxes only);
- geometry settings by their names, ``settings.side_grasp.radius_margin``;
- in the centre, dimensions and aim point: the template's fixed dimensions by name,
  and (centre and dimensions only) its shrinkable parameters, on which they must
  depend affinely (the optimized mode moves spaces along straight lines).

The four templates of the paper are the entries of ``builtin_templates.toml`` beside
this module; users add theirs in their own files, named from a scene (``templates =
["mine.toml"]``) or a sweep config. Expressions are evaluated by Python in the order
they are written, so the built-in file gives the same floats as the code it replaced.
Every rule broken is a one-line :class:`~geometry_precompute.errors.InputError` naming
the file, the field and the rule, raised when the file is read.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import InputError, shown, unknown_field
from .fileio import read_toml

BUILTIN_FILE = Path(__file__).with_name("builtin_templates.toml")
OBJECT_KINDS = ("mug", "cup", "box", "mesh")
# A shape's dimensions as the file writes them (the third of a cylinder, disk or cone
# is 0); the kind's rules on them are checked where a task is resolved.
SHAPE_DIMS = {"cylinder": ("radius", "height"), "disk": ("radius", "thickness"),
              "cone": ("length", "half_angle"), "box": ("half_x", "half_y", "half_z")}
OBJECT_MEASURES = ("radius", "height", "half_x", "half_y", "half_z")
BOX_ONLY = ("half_x", "half_y", "half_z")
FUNCTIONS = {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan,
             "radians": math.radians}
CONSTANTS = {"pi": math.pi}
UNITS = ("m", "rad")
MAX_PARAMS = 2  # shrinkable parameters of one template (the bake's arrays hold two)
MAX_TEMPLATES = 64  # in one file
EXPR_LIMIT = 200  # characters of one expression
_TEMPLATE_KEYS = {"description", "fits", "shape", "params", "fixed", "center", "rotation",
                  "dims", "orientation", "aim"}
_PARAM_KEYS = {"min", "init", "unit"}
_NAME_OK = set("abcdefghijklmnopqrstuvwxyz0123456789_")


@dataclass(frozen=True)
class Expr:
    """One number of a template: its text, the names it reads and its degree in the
    shrinkable parameters (0 or 1)."""

    text: str
    tree: ast.expr = field(compare=False)  # checked, names mangled (:func:`mangle`)
    names: frozenset[str] = frozenset()  # object__radius, settings__a__b, fixed or params

    def __hash__(self) -> int:  # cheap: the compiled code is cached by expression
        return hash(self.text)

    @property
    def tree_code(self):
        """The expression compiled alone (bounds and fixed dimensions)."""
        return _expr_code(self)


@functools.cache
def _expr_code(e: Expr):
    return compile(ast.fix_missing_locations(ast.Expression(e.tree)), "<template>", "eval")


@dataclass(frozen=True)
class Param:
    name: str
    unit: str  # "m" (a length, > 0) or "rad" (an angle in (0, pi/2))
    min: Expr
    init: Expr


@dataclass(frozen=True)
class Template:
    """One template of a template file, checked (:func:`load_file`): the object kinds it
    ``fits``, its ``shape`` kind, its shrinkable ``params`` (each with ``min`` and
    ``init`` expressions and a ``unit``, m or rad), its ``fixed`` dimensions, the
    shape's ``center`` (3 expressions, m, in the object's frame), ``rotation``
    ("world", "object" or an axis in the object's frame), ``dims`` (the shape kind's
    dimensions), ``orientation`` ("point_to_axis" or an approach direction) and
    ``aim`` point; ``source`` is the file that defines it."""

    name: str
    source: str  # the file that defines it
    description: str
    fits: tuple[str, ...]
    shape: str
    params: tuple[Param, ...]
    fixed: tuple[tuple[str, Expr], ...]
    center: tuple[Expr, Expr, Expr]
    rotation: str | tuple[float, float, float]  # "world", "object" or an axis
    dims: tuple[Expr, ...]
    orientation: str | tuple[float, float, float]  # "point_to_axis" or an approach
    aim: tuple[Expr, Expr, Expr]
    definition: Mapping[str, Any] = field(repr=False, compare=False, hash=False)

    def __hash__(self) -> int:  # cheap: compiled code and name sets are cached by template
        return hash((self.name, self.source))

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)

    @property
    def fixed_names(self) -> tuple[str, ...]:
        return tuple(n for n, _ in self.fixed)

    @property
    def units(self) -> dict[str, str]:
        return {p.name: p.unit for p in self.params}

    @property
    def builtin(self) -> bool:
        return self.source == str(BUILTIN_FILE)

    @property
    def center_moves(self) -> bool:
        """Whether the parameters move the space's centre (the drawer's far face)."""
        return _center_moves(self)

    @property
    def settings_read(self) -> tuple[str, ...]:
        """The settings its expressions read, mangled (``settings__a__b``)."""
        return _settings_read(self)

    @property
    def shape_code(self):
        """Compiled: evaluated in a namespace (:func:`namespace`) it gives a function of
        the shrinkable parameters that returns the centre's three numbers in the
        object's frame, then the dimensions (padded to three with 0.0)."""
        return _compiled(self, "shape")

    @property
    def aim_code(self):
        """Compiled: the aim point's three numbers (no parameters)."""
        return _compiled(self, "aim")


@functools.cache
def _center_moves(t: Template) -> bool:
    return any(n in t.param_names for e in t.center for n in e.names)


@functools.cache
def _settings_read(t: Template) -> tuple[str, ...]:
    exprs = [e for p in t.params for e in (p.min, p.init)] + [e for _, e in t.fixed]
    exprs += [*t.center, *t.dims, *t.aim]
    return tuple(sorted({n for e in exprs for n in e.names if n.startswith("settings__")}))


@functools.cache
def _compiled(t: Template, which: str):
    """Code objects do not pickle, so templates travel to worker processes without
    theirs and compile them again there, once per process."""
    exprs = list(t.center) + list(t.dims) if which == "shape" else list(t.aim)
    elts = [e.tree for e in exprs]
    body: ast.expr
    if which == "shape":
        elts += [ast.Constant(0.0)] * (3 - len(t.dims))
        args = ast.arguments(posonlyargs=[], args=[ast.arg(n) for n in t.param_names],
                             kwonlyargs=[], kw_defaults=[], defaults=[])
        body = ast.Lambda(args, ast.Tuple(elts=elts, ctx=ast.Load()))
    else:
        body = ast.Tuple(elts=elts, ctx=ast.Load())
    tree = ast.Expression(body)
    return compile(ast.fix_missing_locations(tree), f"<template {t.name}>", "eval")


def namespace(values: Mapping[str, float]) -> dict[str, Any]:
    """The globals an expression is evaluated in: ``values`` (mangled names) with the
    functions and constants, and no builtins."""
    return {"__builtins__": {}, **FUNCTIONS, **CONSTANTS, **values}


def mangle(parts: Sequence[str]) -> str:
    return "__".join(parts)


def object_measures(obj) -> dict[str, float]:
    """The mangled object measures an expression may read: ``object__radius`` etc."""
    out = {"object__radius": obj.body_radius, "object__height": obj.body_height}
    if obj.kind == "box":
        ex, ey, ez = obj.box_half_extents
        out.update(object__half_x=ex, object__half_y=ey, object__half_z=ez)
    return out


def _settings_specs():
    from .settings import SPECS  # deferred: 13 ms to import

    return SPECS


class _Reader:
    """Checks of one template's table, with the file and field in every error."""

    def __init__(self, src: str, name: str):
        self.src = src
        self.where = f"templates.{name}."

    def bad(self, fld: str, rule: str) -> InputError:
        return InputError(self.src, self.where + fld, rule)

    def expr(self, value: Any, fld: str, params: Sequence[str] = (),
             fixed: Sequence[str] = (), fits: Sequence[str] = ()) -> Expr:
        """A number or an expression over the names this field may read."""
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise self.bad(fld, f"must be a number or an expression in a string, got "
                           f"{shown(value)}")
        if not isinstance(value, str):
            if not _finite(value):
                raise self.bad(fld, f"must be a finite number, got {shown(value)}")
            return Expr(repr(float(value)), ast.Constant(float(value)), frozenset())
        text = value.strip()
        if not text or len(text) > EXPR_LIMIT or not text.isprintable():
            raise self.bad(fld, f"an expression must be one line of 1 to {EXPR_LIMIT} "
                           f"characters, got {shown(value)}")
        try:
            tree = ast.parse(text, mode="eval").body
        except SyntaxError:
            raise self.bad(fld, f"{shown(text)} is not an expression (numbers, + - * /, "
                           "parentheses, names)") from None
        names: set[str] = set()
        out = self._node(tree, fld, text, params, fixed, fits, names)
        if self._degree(out, params, fld, text) > 1:
            raise self.bad(fld, f"{shown(text)} is not affine in the shrinkable parameters "
                           "(a product or quotient of them, or a function of one): the "
                           "optimized mode moves spaces along straight lines")
        return Expr(text, out, frozenset(names))

    def _node(self, node: ast.AST, fld: str, text: str, params, fixed, fits,
              names: set[str]) -> ast.expr:
        def refuse(what: str) -> InputError:
            return self.bad(fld, f"{shown(text)}: {what} (allowed: numbers, + - * /, "
                            "parentheses, pi, sqrt sin cos tan radians, object.<measure>, "
                            "settings.<name>" + (", the template's parameters and fixed "
                                                 "dimensions" if params or fixed else "")
                            + ")")

        rec = lambda n: self._node(n, fld, text, params, fixed, fits, names)  # noqa: E731
        if isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, int | float):
                raise refuse(f"{shown(node.value)} is not a number")
            if not _finite(node.value):
                raise refuse(f"{shown(node.value)} is not a finite number")
            return ast.Constant(float(node.value))
        if isinstance(node, ast.BinOp):
            if not isinstance(node.op, ast.Add | ast.Sub | ast.Mult | ast.Div):
                raise refuse(f"the operator {type(node.op).__name__} is not allowed")
            return ast.BinOp(rec(node.left), node.op, rec(node.right))
        if isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, ast.USub | ast.UAdd):
                raise refuse(f"the operator {type(node.op).__name__} is not allowed")
            return ast.UnaryOp(node.op, rec(node.operand))
        if isinstance(node, ast.Call):
            if not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS
                    and len(node.args) == 1 and not node.keywords):
                raise refuse("only sqrt, sin, cos, tan and radians of one argument may "
                             "be called")
            return ast.Call(ast.Name(node.func.id, ast.Load()), [rec(node.args[0])], [])
        if isinstance(node, ast.Name):
            if node.id in CONSTANTS:
                return ast.Name(node.id, ast.Load())
            if node.id in params or node.id in fixed:
                names.add(node.id)
                return ast.Name(node.id, ast.Load())
            raise refuse(f"unknown name {node.id!r}")
        if isinstance(node, ast.Attribute):
            parts: list[str] = []
            n: ast.AST = node
            while isinstance(n, ast.Attribute):
                parts.append(n.attr)
                n = n.value
            if not isinstance(n, ast.Name):
                raise refuse("a dotted name must start with object or settings")
            parts.append(n.id)
            parts.reverse()
            if parts[0] == "object":
                if len(parts) != 2 or parts[1] not in OBJECT_MEASURES:
                    raise refuse(f"unknown measure {'.'.join(parts)!r} (objects have "
                                 f"{', '.join(OBJECT_MEASURES)})")
                if parts[1] in BOX_ONLY and any(k != "box" for k in fits):
                    raise refuse(f"object.{parts[1]} is a box's measure, and the template "
                                 f"also fits {', '.join(k for k in fits if k != 'box')}")
            elif parts[0] == "settings":
                name = ".".join(parts[1:])
                spec = _settings_specs().get(name)
                if spec is None or spec.stage != "precompute" or spec.kind != "float":
                    raise refuse(f"{name!r} is not a geometry setting (a number of the "
                                 "precompute stage: `shacc settings` lists them)")
            else:
                raise refuse(f"unknown name {parts[0]!r}")
            mangled = mangle(parts)
            names.add(mangled)
            return ast.Name(mangled, ast.Load())
        raise refuse(f"{type(node).__name__} is not allowed")

    def _degree(self, node: ast.expr, params: Sequence[str], fld: str, text: str) -> int:
        """The expression's polynomial degree in the parameters, 2 meaning "not affine"
        (a function of a parameter, or a division by one, counts as 2)."""
        if isinstance(node, ast.Name):
            return 1 if node.id in params else 0
        if isinstance(node, ast.UnaryOp):
            return self._degree(node.operand, params, fld, text)
        if isinstance(node, ast.Call):
            return 2 * self._degree(node.args[0], params, fld, text)
        if isinstance(node, ast.BinOp):
            a = self._degree(node.left, params, fld, text)
            b = self._degree(node.right, params, fld, text)
            if isinstance(node.op, ast.Mult):
                return min(a + b, 2)
            if isinstance(node.op, ast.Div):
                return a if b == 0 else 2
            return max(a, b)
        return 0

    def vector(self, value: Any, fld: str) -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3 or not all(
                isinstance(v, int | float) and not isinstance(v, bool) and _finite(v)
                for v in value):
            raise self.bad(fld, f"must be a list of 3 finite numbers, got {shown(value)}")
        v = tuple(float(x) for x in value)
        if math.hypot(*v) < 1e-9:
            raise self.bad(fld, "a zero vector is not a direction")
        return v  # type: ignore[return-value]


def _finite(v: float) -> bool:
    """A finite number, within what a float holds (a 400-digit integer is not)."""
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _identifier(name: Any, src: str, fld: str) -> str:
    if not isinstance(name, str) or not name or not set(name) <= _NAME_OK \
            or name[0].isdigit() or len(name) > 64 or "__" in name:
        raise InputError(src, fld, f"a name must be 1 to 64 lower-case letters, digits and "
                         f"single underscores, not starting with a digit, got {shown(name)}")
    if name in CONSTANTS or name in FUNCTIONS or name in ("object", "settings"):
        raise InputError(src, fld, f"{name!r} is a reserved name in expressions")
    return name


def parse_template(name: str, raw: Any, src: str) -> Template:
    """One template table checked (the module's docstring has the rules)."""
    name = _identifier(name, src, f"templates.{shown(name)}")
    r = _Reader(src, name)
    if not isinstance(raw, Mapping):
        raise r.bad("", "must be a table")
    for key in raw:
        if key not in _TEMPLATE_KEYS:
            raise r.bad(key, unknown_field(_TEMPLATE_KEYS, key))
    for key in ("fits", "shape", "center", "dims", "orientation"):
        if key not in raw:
            raise r.bad(key, "missing required field")
    description = raw.get("description", "")
    if not isinstance(description, str) or not description.isprintable() \
            or len(description) > 300:
        raise r.bad("description", "must be one line of printable text (300 characters "
                    "at most)")
    fits = raw["fits"]
    if not isinstance(fits, list) or not fits or any(k not in OBJECT_KINDS for k in fits) \
            or len(set(map(str, fits))) != len(fits):
        raise r.bad("fits", f"must be a list of distinct object kinds from "
                    f"{', '.join(OBJECT_KINDS)}, got {shown(fits)}")
    shape = raw["shape"]
    if not isinstance(shape, str) or shape not in SHAPE_DIMS:
        raise r.bad("shape", f"unknown shape kind {shown(shape)} (known: "
                    f"{', '.join(SHAPE_DIMS)})")
    params_raw = raw.get("params", {})
    if not isinstance(params_raw, Mapping):
        raise r.bad("params", "must be a table of parameter = {min, init, unit}")
    if len(params_raw) > MAX_PARAMS:
        raise r.bad("params", f"at most {MAX_PARAMS} shrinkable parameters, got "
                    f"{len(params_raw)}")
    fixed_raw = raw.get("fixed", {})
    if not isinstance(fixed_raw, Mapping):
        raise r.bad("fixed", "must be a table of dimension = number or expression")
    for pname in params_raw:
        _identifier(pname, src, f"{r.where}params.{pname}")
    for fname in fixed_raw:
        _identifier(fname, src, f"{r.where}fixed.{fname}")
        if fname in params_raw:
            raise r.bad(f"fixed.{fname}", "is also a shrinkable parameter")
    params = []
    for pname, p in params_raw.items():
        w = f"params.{pname}"
        if not isinstance(p, Mapping):
            raise r.bad(w, "must be a table {min, init, unit}")
        for key in p:
            if key not in _PARAM_KEYS:
                raise r.bad(f"{w}.{key}", unknown_field(_PARAM_KEYS, key))
        for key in ("min", "init"):
            if key not in p:
                raise r.bad(f"{w}.{key}", "missing required field")
        unit = p.get("unit", "m")
        if unit not in UNITS:
            raise r.bad(f"{w}.unit", f"must be one of {', '.join(UNITS)}, got {shown(unit)}")
        params.append(Param(pname, unit, r.expr(p["min"], f"{w}.min", fits=fits),
                            r.expr(p["init"], f"{w}.init", fits=fits)))
    pnames = tuple(params_raw)
    fnames = tuple(fixed_raw)
    fixed = tuple((f, r.expr(v, f"fixed.{f}", fits=fits)) for f, v in fixed_raw.items())

    def exprs(key: str, n: int, with_params: bool) -> tuple[Expr, ...]:
        value = raw[key]
        if not isinstance(value, list) or len(value) != n:
            raise r.bad(key, f"must be a list of {n} numbers or expressions, got "
                        f"{shown(value)}")
        return tuple(r.expr(v, f"{key}[{i}]", pnames if with_params else (), fnames, fits)
                     for i, v in enumerate(value))

    center = exprs("center", 3, True)
    dims = exprs("dims", len(SHAPE_DIMS[shape]), True)
    aim = exprs("aim", 3, False) if "aim" in raw else center
    if "aim" not in raw and any(n in pnames for e in center for n in e.names):
        raise r.bad("aim", "required when the parameters move the centre (the point a user "
                    "aiming at the object steers to must stay put)")
    rotation = raw.get("rotation", "world")
    if not isinstance(rotation, str):
        rotation = r.vector(rotation, "rotation")
    elif rotation not in ("world", "object"):
        raise r.bad("rotation", f"must be \"world\", \"object\" or an axis [x, y, z] in the "
                    f"object's frame, got {shown(rotation)}")
    orientation = raw["orientation"]
    if not isinstance(orientation, str):
        orientation = r.vector(orientation, "orientation")
    elif orientation != "point_to_axis":
        raise r.bad("orientation", f"must be \"point_to_axis\" or an approach direction "
                    f"[x, y, z] in the object's frame, got {shown(orientation)}")
    unused = [p for p in pnames if not any(p in e.names for e in center + dims)]
    if unused:
        raise r.bad(f"params.{unused[0]}", "is not used by the centre or the dimensions")
    return Template(name, src, description, tuple(fits), shape, tuple(params), fixed,
                    center, rotation, dims, orientation, aim,  # type: ignore[arg-type]
                    json.loads(json.dumps(raw)))


def parse_file(data: Any, src: str) -> dict[str, Template]:
    """The templates of a parsed template file, by name."""
    if not isinstance(data, Mapping):
        raise InputError(src, "<top>", "must be a table")
    for key in data:
        if key != "templates":
            raise InputError(src, key, "unknown field (a template file holds one table, "
                             "[templates.NAME] per template)")
    table = data.get("templates")
    if not isinstance(table, Mapping) or not table:
        raise InputError(src, "templates", "a template file needs at least one "
                         "[templates.NAME] table")
    if len(table) > MAX_TEMPLATES:
        raise InputError(src, "templates", f"at most {MAX_TEMPLATES} templates in one "
                         f"file, got {len(table)}")
    return {name: parse_template(name, raw, src) for name, raw in table.items()}


def load_file(path: str | Path, src: str | None = None, fld: str = "templates") -> dict[
        str, Template]:
    """The templates of a template file, checked (docs/reference/templates.md).

    :param path: the file (TOML, one ``[templates.NAME]`` table per template).
    :param src: the scene or config that names the file, for errors (default: the file).
    :param fld: the field of ``src`` that names it, for errors.
    :returns: ``{name: Template}`` in the file's order.
    :raises InputError: a missing file, a file that is not TOML, or any broken rule,
        in one line naming the file (or ``src``), the field and the rule.

    Example::

        >>> from geometry_precompute.template_files import BUILTIN_FILE, load_file
        >>> t = load_file(BUILTIN_FILE)["handle_grasp"]
        >>> t.shape, t.param_names, t.params[1].min.text
        ('cone', ('length', 'half_angle'), 'settings.handle_grasp.half_angle_min')
    """

    path = Path(path)
    if not path.is_file():
        raise InputError(src or path, fld, f"no template file at {shown(str(path))}")
    return parse_file(read_toml(path, "a template file"), str(path))


@functools.cache
def builtin() -> dict[str, Template]:
    """The built-in templates: the paper's four, read once from ``builtin_templates.toml``
    beside this module.

    :returns: ``{name: Template}``: side_grasp, handle_grasp, top_grasp, drawer_pull.

    Example::

        >>> from geometry_precompute.template_files import builtin
        >>> {n: t.fits for n, t in builtin().items()}["drawer_pull"]
        ('box',)
    """
    return parse_file(tomllib.loads(BUILTIN_FILE.read_text()), str(BUILTIN_FILE))


@dataclass(frozen=True)
class TemplateSet:
    """The templates a scene can use: the built-in ones and those of its template files
    (``Scene.templates``; built by :func:`template_set`). Indexed by name like a
    mapping (``tset["side_grasp"]``, ``"mine" in tset``); ``files`` are the resolved
    paths of its files, ``extra`` their templates, and :meth:`digest` a hash of their
    definitions, which cache keys and a sweep's hash include."""

    files: tuple[str, ...] = ()  # as resolved, in order
    extra: tuple[Template, ...] = ()

    @property
    def by_name(self) -> dict[str, Template]:
        return {**builtin(), **{t.name: t for t in self.extra}}

    def __contains__(self, name: object) -> bool:
        return name in self.by_name

    def __getitem__(self, name: str) -> Template:
        return self.by_name[name]

    def names(self) -> list[str]:
        return list(self.by_name)

    def digest(self) -> str:
        """The user templates' definitions, hashed: part of every cache key."""
        blob = [[t.name, t.definition] for t in self.extra]
        return hashlib.sha256(json.dumps(blob, sort_keys=True).encode()).hexdigest()[:16]


BUILTIN_SET = TemplateSet()


def template_set(paths: Sequence[Any], src: str, fld: str = "templates",
                 base_dir: Path | None = None) -> TemplateSet:
    """The templates a scene (or generator) can use: the built-in ones and those of its
    template files.

    :param paths: the template files as written (a list of strings).
    :param src: the scene or config that names them, for errors.
    :param fld: its field that names them, for errors.
    :param base_dir: the folder relative paths start from (the scene's folder).
    :returns: a :class:`TemplateSet`; its ``files`` are the resolved paths.
    :raises InputError: a bad list or file, or a template name defined twice.

    Example::

        >>> import pathlib, tempfile
        >>> from geometry_precompute.template_files import template_set
        >>> folder = pathlib.Path(tempfile.mkdtemp())
        >>> _ = (folder / "mine.toml").write_text('''
        ... [templates.above]
        ... fits = ["box"]
        ... shape = "box"
        ... center = [0, 0, "2 * object.half_z + height / 2"]
        ... dims = ["object.half_x", "object.half_y", "height / 2"]
        ... orientation = [0, 0, -1]
        ... aim = [0, 0, "2 * object.half_z"]
        ... params.height = {min = 0.04, init = 0.2}
        ... ''')
        >>> tset = template_set(["mine.toml"], "scene.toml", base_dir=folder)
        >>> tset.names()[-1], tset["above"].param_names
        ('above', ('height',))
    """
    if not isinstance(paths, list):
        raise InputError(src, fld, f"must be a list of template files, got {shown(paths)}")
    seen = dict(builtin())
    files, extra = [], []
    for i, p in enumerate(paths):
        if not isinstance(p, str) or not p.strip():
            raise InputError(src, f"{fld}[{i}]", f"must be a file name, got {shown(p)}")
        path = Path(p).expanduser()
        if base_dir is not None and not path.is_absolute():
            path = base_dir / path
        path = path.resolve()  # a scene written back names it from anywhere
        for name, t in load_file(path, src, f"{fld}[{i}]").items():
            if name in seen:
                where = "the built-in file" if seen[name].builtin else seen[name].source
                raise InputError(t.source, f"templates.{name}", f"already defined by "
                                 f"{where}; give it another name")
            seen[name] = t
            extra.append(t)
        files.append(str(path))
    return TemplateSet(tuple(files), tuple(extra))
