"""Seeded random scenes (the experiments' random set).

Each scene has ``n_tasks`` objects (uniform in [min_tasks, max_tasks]), one
task each: a mug with a side grasp or a cup with a handle grasp, with equal
probability (the paper's two representative tasks). Positions are ``uniform``
over a square table area centred at the origin or ``gaussian`` around its centre;
handle yaws are uniform in [-pi, pi). Objects are placed one at a time by rejection
sampling so that every pair of bodies is at least ``gap`` (0.01 m) apart; a scene
whose objects cannot be placed in ``max_attempts`` draws is started again.
Everything comes from ``numpy.random.default_rng(seed)``.

The table area and the gaussian's spread are a named *preset* (:data:`PRESETS`):

- ``compact``: a 0.6 m x 0.6 m area and sigma 0.10 m, the project's first reading of
  the paper. Its uniform scenes are far more cluttered than the paper's (C_init near
  0.32 where the paper's had at most 0.11), so the paper's "no gain on uniform scenes"
  cannot be checked on them.
- ``paper``: the area and sigma chosen so that C_init of 1 000 scenes of each sampling
  matches what the paper reports of its own (uniform: mean at most 0.11; gaussian:
  0.30 +- 0.05); the measurements are in benchmarks/RESULTS.md and the README.
"""

from __future__ import annotations

import functools
import math
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .errors import InputError, shown, unknown_field
from .fileio import read_toml
from .mesh_objects import PLACEMENT_KEYS, check_height, load, parse_placement
from .scene import Scene, SceneObject, Task
from .settings import LENGTH_LIMIT, OBJECT_DEFAULTS
from .template_files import BUILTIN_SET, TemplateSet, template_set


class Preset(NamedTuple):
    table_half: float  # m: uniform positions in [-table_half, table_half]^2
    sigma: float       # m: gaussian positions N(0, sigma^2) per coordinate
    doc: str


PRESETS = {
    "compact": Preset(0.30, 0.10, "0.6 m x 0.6 m table, sigma 0.10 m (the first reading)"),
    "paper": Preset(0.65, 0.18, "1.3 m x 1.3 m table, sigma 0.18 m: mean C_init 0.095 (uniform) "
                    "and 0.309 (gaussian) over 1 000 scenes each"),
}
# The most objects the generator places: 30 fill the 0.6 m table to about half of the
# random-packing limit, and rejection sampling still succeeds at once (measured: 0.1 s
# for 30 uniform objects); much beyond, it restarts without end.
MAX_TASKS = 30
MAX_RESTARTS = 100
# The version of what random_scene returns for given arguments. The precompute cache
# keys a random scene by its arguments and this number (building a scene costs about
# as much as reading its cached result), so any change to the scenes a seed gives must
# raise it; tests/test_precompute_fast.py holds a digest of a few seeds' scenes.
GENERATOR_VERSION = 1


def random_scene(seed: int, kind: str = "uniform", min_tasks: int = 5, max_tasks: int = 10,
                 preset: str = "compact", generator: Mapping[str, Any] | None = None, *,
                 gap: float = 0.01, max_attempts: int = 2000,
                 name: str | None = None) -> Scene:
    """A seeded random scene (module docstring; docs/reference/experiments.md).

    :param seed: the generator's seed (``numpy.random.default_rng``).
    :param kind: "uniform" (positions uniform over the table area) or "gaussian"
        (around its centre).
    :param min_tasks, max_tasks: the number of objects, one task each, is uniform in
        this range (1 to 30).
    :param preset: the table area and gaussian spread, a name of :data:`PRESETS`:
        "compact" (0.6 m table, sigma 0.10 m) or "paper" (1.3 m, 0.18 m: the paper's
        C_init distribution).
    :param generator: a configured generator (:func:`check_generator`'s table: object
        kinds with weights and sizes, mesh folders, templates with weights, the table
        area, the gaussian's spread, the gap); None: the paper's mugs and cups.
    :param gap: the smallest distance between two bodies, m.
    :returns: a :class:`Scene` named ``random-[PRESET-]KIND-SEED``; the same arguments
        give the same scene on every machine.

    Example::

        scenes = [random_scene(seed, "gaussian", 5, 10, "paper") for seed in range(100)]
    """
    if preset not in PRESETS:
        raise ValueError(f"generator preset must be one of {', '.join(PRESETS)}, got "
                         f"{preset!r}")
    half, sigma = PRESETS[preset].table_half, PRESETS[preset].sigma
    if kind not in ("uniform", "gaussian"):
        raise ValueError(f"sampling kind must be uniform or gaussian, got {kind!r}")
    if not 1 <= min_tasks <= max_tasks <= MAX_TASKS:
        raise ValueError(f"need 1 <= min_tasks <= max_tasks <= {MAX_TASKS}, got {min_tasks}, "
                         f"{max_tasks}")
    rng = np.random.default_rng(seed)
    n = int(rng.integers(min_tasks, max_tasks + 1))
    if generator is not None:
        spec = dict(generator) if generator.get("checked") else \
            check_generator(generator, "<generator>", "generator")
        return _configured(rng, spec, kind, n, seed, preset, max_attempts, name)
    for _restart in range(MAX_RESTARTS):
        placed: list[tuple[float, float, float]] = []  # (x, y, radius)
        objects, tasks = [], []
        for i in range(n):
            is_mug = bool(rng.random() < 0.5)
            kind_i = "mug" if is_mug else "cup"
            radius = OBJECT_DEFAULTS[kind_i]["radius"]
            for _ in range(max_attempts):
                if kind == "uniform":
                    xy = rng.uniform(-half, half, size=2)
                else:
                    xy = rng.normal(0.0, sigma, size=2)
                if all(np.hypot(xy[0] - x, xy[1] - y) - radius - r >= gap for x, y, r in placed):
                    break
            else:
                break
            placed.append((float(xy[0]), float(xy[1]), radius))
            yaw = 0.0 if is_mug else float(rng.uniform(-np.pi, np.pi))
            oid = f"{kind_i}{i}"
            objects.append(SceneObject(oid, kind_i, (float(xy[0]), float(xy[1]), 0.0), yaw,
                                       radius=radius, height=OBJECT_DEFAULTS[kind_i]["height"]))
            template = "side_grasp" if is_mug else "handle_grasp"
            tasks.append(Task(f"{template.split('_')[0]}-{oid}", oid, template))
        if len(objects) == n:
            break
    else:
        raise ValueError(f"could not place {n} objects {gap} m apart in {MAX_RESTARTS} tries")
    label = kind if preset == "compact" else f"{preset} {kind}"
    return Scene(name or f"random-{label.replace(' ', '-')}-{seed}", tuple(objects),
                 tuple(tasks), {}, f"random {label} scene, seed {seed}, {n} tasks",
                 f"<random {label} {seed}>")


# A configured generator (a sweep's [source.generator]; docs/reference/experiments.md).
GENERATOR_KINDS = ("mug", "cup", "box", "mesh")
DEFAULT_TEMPLATES = {"mug": "side_grasp", "cup": "handle_grasp", "box": "drawer_pull",
                     "mesh": "side_grasp"}
_GENERATOR_KEYS = {"table", "sigma", "gap", "objects", "template_files"}
_ENTRY_KEYS = {"kind", "weight", "radius", "height", "half_extents", "folder", "templates",
               *PLACEMENT_KEYS}
MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb")
# Beside a folder's meshes: per file name, the placement keys that differ from the folder's.
MANIFEST = "meshes.toml"


def check_generator(table: Any, src: str, where: str = "source.generator",
                    base_dir: Path | None = None) -> dict:
    """A generator table checked and completed (one-line InputErrors naming ``src`` and
    the field): ``table`` [x, y] extents of the area (m), ``sigma`` (m), ``gap`` (m) and
    ``objects``, a list of ``{kind, weight, ...}``: mugs and cups with ``radius`` and
    ``height`` ranges [low, high] (default the kind's size), boxes with ``half_extents``
    ranges ([[low, high]] x 3), meshes with a ``folder`` of mesh files (relative to
    ``base_dir``), placed by the mesh keys ``up``, ``unit`` or ``scale``, ``rpy`` or
    ``quat`` and ``origin`` (for the folder, and per file in a ``meshes.toml`` beside
    them; an ``rpy``'s or ``quat``'s yaw is added to the drawn one); each entry's
    ``templates`` a table of template = weight (default the kind's usual one). Returns
    plain data (folders made absolute, each mesh file's CRC-32 and placement keys beside
    it), marked ``checked``: what ``random_scene`` takes.

    >>> check_generator({"objects": [{"kind": "box"}]}, "cfg")["objects"][0]["templates"]
    {'drawer_pull': 1.0}
    """
    def bad(fld: str, rule: str) -> InputError:
        return InputError(src, f"{where}.{fld}" if fld else where, rule)

    def number(v, fld, lo=0.0, hi=LENGTH_LIMIT, open_lo=True) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                or not (lo < v if open_lo else lo <= v) or v > hi:
            raise bad(fld, f"must be a number in {'(' if open_lo else '['}{lo:g}, {hi:g}], "
                      f"got {shown(v)}")
        return float(v)

    def span(v, fld) -> list[float]:
        if isinstance(v, int | float) and not isinstance(v, bool):
            v = [v, v]
        if not isinstance(v, list) or len(v) != 2:
            raise bad(fld, f"must be a number or [low, high], got {shown(v)}")
        lo, hi = number(v[0], f"{fld}[0]"), number(v[1], f"{fld}[1]")
        if lo > hi:
            raise bad(fld, f"must be [low, high] with low <= high, got {shown(v)}")
        return [lo, hi]

    if not isinstance(table, Mapping):
        raise bad("", "must be a table (table, sigma, gap, [[objects]])")
    if table.get("checked"):  # already this function's result
        return dict(table)
    for key in table:
        if key not in _GENERATOR_KEYS:
            raise bad(key, unknown_field(_GENERATOR_KEYS, key))
    area = table.get("table", [1.3, 1.3])
    if not isinstance(area, list) or len(area) != 2:
        raise bad("table", f"must be [x, y] extents in m, got {shown(area)}")
    out: dict[str, Any] = {"checked": True, "table": [number(area[0], "table[0]", hi=20.0),
                                     number(area[1], "table[1]", hi=20.0)],
                           "sigma": number(table.get("sigma", 0.18), "sigma", hi=10.0),
                           "gap": number(table.get("gap", 0.01), "gap", open_lo=False, hi=1.0)}
    tset = BUILTIN_SET
    if "template_files" in table:
        tset = template_set(table["template_files"], src, f"{where}.template_files", base_dir)
        # Their definitions name them in cache keys and the sweep's hash.
        out["template_files"] = list(tset.files)
        out["template_digest"] = tset.digest()
    entries = table.get("objects", [{"kind": "mug"}, {"kind": "cup"}])
    if not isinstance(entries, list) or not entries:
        raise bad("objects", "must be a non-empty list of {kind, weight, ...}")
    out["objects"] = []
    for i, e in enumerate(entries):
        w = f"objects[{i}]"
        if not isinstance(e, Mapping) or e.get("kind") not in GENERATOR_KINDS:
            raise bad(f"{w}.kind", f"must be one of {', '.join(GENERATOR_KINDS)}, got "
                      f"{shown(e.get('kind') if isinstance(e, Mapping) else e)}")
        kind = e["kind"]
        for key in e:
            if key not in _ENTRY_KEYS:
                raise bad(f"{w}.{key}", unknown_field(_ENTRY_KEYS, key))
        allowed = {"mug": {"radius", "height"}, "cup": {"radius", "height"},
                   "box": {"half_extents"}, "mesh": {"folder", *PLACEMENT_KEYS}}[kind]
        for key in ("radius", "height", "half_extents", "folder", *PLACEMENT_KEYS):
            if key in e and key not in allowed:
                raise bad(f"{w}.{key}", f"not a field of a {kind} entry")
        entry: dict[str, Any] = {"kind": kind, "weight": number(e.get("weight", 1.0),
                                                                 f"{w}.weight", hi=1e6)}
        if kind in ("mug", "cup"):
            for key in ("radius", "height"):
                entry[key] = span(e.get(key, OBJECT_DEFAULTS[kind][key]), f"{w}.{key}")
        elif kind == "box":
            he = e.get("half_extents", [[0.1, 0.15], [0.15, 0.2], [0.1, 0.15]])
            if not isinstance(he, list) or len(he) != 3:
                raise bad(f"{w}.half_extents", f"must be three [low, high] ranges, got "
                          f"{shown(he)}")
            entry["half_extents"] = [span(v, f"{w}.half_extents[{k}]") for k, v in enumerate(he)]
        else:
            folder = e.get("folder")
            if not isinstance(folder, str) or not folder or not folder.isprintable():
                raise bad(f"{w}.folder", "must name a folder of mesh files")
            path = Path(folder) if base_dir is None else base_dir / folder
            files = sorted(str(p.resolve()) for p in path.glob("*")
                           if p.suffix.lower() in MESH_SUFFIXES) if path.is_dir() else []
            if not files:
                raise bad(f"{w}.folder", f"no mesh files ({', '.join(MESH_SUFFIXES)}) in "
                          f"{shown(folder)}")

            entry["files"] = files
            # Their content names them in cache keys and the sweep's hash: a file changed
            # in place is a new mesh.
            entry["digests"] = [zlib.crc32(Path(f).read_bytes()) for f in files]
            entry["placements"] = _placements(e, files, path, src, f"{where}.{w}.")
        templates = e.get("templates", {DEFAULT_TEMPLATES[kind]: 1})
        if not isinstance(templates, Mapping) or not templates:
            raise bad(f"{w}.templates", "must be a table of template = weight")
        entry["templates"] = {}
        for t, weight in templates.items():
            if t not in tset or kind not in tset[t].fits:
                fits = [n for n in tset.names() if kind in tset[n].fits]
                raise bad(f"{w}.templates.{t}", f"does not fit a {kind} (fits: "
                          f"{', '.join(fits)})")
            entry["templates"][t] = number(weight, f"{w}.templates.{t}", hi=1e6)
        out["objects"].append(entry)
    return out


def _placements(entry: Mapping[str, Any], files: list[str], folder: Path, src: str,
                where: str) -> list[dict[str, Any]]:
    """Each mesh file's placement keys: the entry's, over which its line in the folder's
    ``meshes.toml`` goes. Every file is read and placed here, once, so that a bad key, a
    mesh below the table or one floating is said in one line before any scene is drawn
    (a generator stands its meshes at z = 0)."""
    base = {k: entry[k] for k in PLACEMENT_KEYS if k in entry}
    manifest: dict[str, Any] = {}
    listed = folder / MANIFEST
    if listed.is_file():
        manifest = read_toml(listed, "a manifest of mesh placements (TOML)")
        names = {Path(f).name for f in files}
        for name, keys in manifest.items():
            if name not in names:
                raise InputError(listed, name, f"no mesh file of that name beside it "
                                 f"(files: {', '.join(sorted(names))})")
            if not isinstance(keys, Mapping):
                raise InputError(listed, name, "must be a table of placement keys")
            for key in keys:
                if key not in PLACEMENT_KEYS:
                    raise InputError(listed, f"{name}.{key}", unknown_field(
                        set(PLACEMENT_KEYS), key))
    out = []
    for f in files:
        name = Path(f).name
        own = manifest.get(name, {})
        keys = {**base, **own}
        if "unit" in own:
            keys.pop("scale", None)
        if "scale" in own:
            keys.pop("unit", None)
        if "quat" in own:
            keys.pop("rpy", None)
        if "rpy" in own:
            keys.pop("quat", None)
        file_src, fld = (listed, f"{name}.") if own else (src, where)
        placement, _ = parse_placement(keys, None, str(file_src), fld)
        check_height(load(f, placement, str(file_src), fld), 0.0, str(file_src), fld)
        out.append(keys)
    return out


def _pick(rng: np.random.Generator, weights) -> int:
    w = np.asarray(weights, float)
    return int(rng.choice(len(w), p=w / w.sum()))


def _configured(rng: np.random.Generator, spec: dict, kind: str, n: int, seed: int,
                preset: str, max_attempts: int, name: str | None) -> Scene:
    """A scene of the configured generator ``spec`` (``check_generator``'s)."""

    half_x, half_y = spec["table"][0] / 2, spec["table"][1] / 2
    entries = spec["objects"]
    for _restart in range(MAX_RESTARTS):
        placed: list[tuple[float, float, float]] = []
        objects, tasks = [], []
        for i in range(n):
            e = entries[_pick(rng, [x["weight"] for x in entries])]
            k = e["kind"]
            yaw = 0.0 if k == "mug" else float(rng.uniform(-np.pi, np.pi))
            size: dict[str, Any]
            if k in ("mug", "cup"):
                size = {"radius": float(rng.uniform(*e["radius"])),
                        "height": float(rng.uniform(*e["height"]))}
                reach, oid = size["radius"], f"{k}{i}"
            elif k == "box":
                he = tuple(float(rng.uniform(*r)) for r in e["half_extents"])
                size = {"half_extents": he}
                reach, oid = math.hypot(he[0], he[1]), f"box{i}"
            else:
                pick = int(rng.integers(len(e["files"])))
                file = e["files"][pick]
                placement, turn = parse_placement(e["placements"][pick], None, "<generator>",
                                                  f"objects[{i}].")
                mesh = load(file, placement, "<generator>", f"objects[{i}].")
                size = {"mesh": mesh}
                yaw += turn
                reach, oid = mesh.radius, f"{Path(file).stem}{i}"
            for _ in range(max_attempts):
                xy = (rng.uniform([-half_x, -half_y], [half_x, half_y]) if kind == "uniform"
                      else rng.normal(0.0, spec["sigma"], size=2))
                if all(np.hypot(xy[0] - x, xy[1] - y) - reach - r >= spec["gap"]
                       for x, y, r in placed):
                    break
            else:
                break
            placed.append((float(xy[0]), float(xy[1]), reach))
            objects.append(SceneObject(oid, k, (float(xy[0]), float(xy[1]), 0.0), yaw, **size))
            names = list(e["templates"])
            template = names[_pick(rng, list(e["templates"].values()))]
            tasks.append(Task(f"{template.split('_')[0]}-{oid}", oid, template))
        if len(objects) == n:
            break
    else:
        raise ValueError(f"could not place {n} objects {spec['gap']} m apart in "
                         f"{MAX_RESTARTS} tries")
    return Scene(name or f"random-configured-{kind}-{seed}", tuple(objects), tuple(tasks), {},
                 f"random configured {kind} scene, seed {seed}, {n} tasks",
                 f"<random configured {kind} {seed}>", generator_templates(spec))


def generator_templates(spec: Mapping[str, Any]) -> TemplateSet:
    """The templates a checked generator's scenes can use: the built-in ones and those of
    its ``template_files`` (read once per process and files' content)."""
    files = spec.get("template_files")
    if not files:
        return BUILTIN_SET
    return _template_files(tuple(files), spec.get("template_digest", ""))


@functools.lru_cache(maxsize=16)
def _template_files(files: tuple[str, ...], digest: str) -> TemplateSet:
    tset = template_set(list(files), "<generator>", "template_files")
    if tset.digest() != digest:
        raise InputError("<generator>", "template_files", "a template file changed while the "
                         "sweep ran; run it again")
    return tset
