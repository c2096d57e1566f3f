"""Scenes from MuJoCo (reference/mujoco, "Scenes from MuJoCo"): the geoms of an MJCF file
that the user names become the objects of a scene file, with the tasks the user gives.

MuJoCo reads the file (includes, defaults, meshes and all) and places every geom
(``mj_forward``); each named object is then one collidable geom, named directly or as
the only collidable geom of a named body:

- a cylinder becomes a mug (a cup where the mapping says ``kind = "cup"``, where the
  file records it, as ``shacc export-mjcf`` does, or where a task on it is a handle
  grasp): radius and height from its size, position at the
  centre of its base, yaw from its frame (an upright geom is required);
- a box becomes a box: half extents, base centre, yaw;
- a mesh becomes a mesh object: its vertices (as MuJoCo holds them, float32) turned into
  the world's orientation and written as an STL file beside the scene, placed at the
  geom's position with yaw 0 (MuJoCo moves a mesh's frame to its centre of mass, so
  that is the object's origin, and the axis of its side grasp).

An id is the geom's (or body's) name, less the ``object:`` prefix that ``shacc
export-mjcf`` writes, so a scene exported and imported again keeps its ids. Other geoms
(a table, the lights, the spaces ``export-mjcf`` draws) are left out unless named as
``obstacles``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, shown

EXPORT_PREFIX = "object:"
UPRIGHT_TOL = 1e-6  # |1 - z.z| of a geom's frame that still counts as upright


def _model(xml: Path):
    import mujoco  # deferred: 334 ms to import

    try:
        model = mujoco.MjModel.from_xml_path(str(xml))
    except Exception as e:  # MuJoCo's parser raises ValueError with its own message
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(xml, "<mjcf>", f"MuJoCo cannot load it: {first}") from None
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return mujoco, model, data


def _geom_of(mujoco, model, name: str, src: str, fld: str) -> int:
    """The geom that ``name`` stands for: a geom of that name, or the only collidable
    geom of the body of that name."""
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    if g >= 0:
        return g
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if b < 0:
        raise InputError(src, fld, f"no geom or body named {name!r} in the MJCF")
    geoms = [i for i in range(model.ngeom) if model.geom_bodyid[i] == b
             and (model.geom_contype[i] or model.geom_conaffinity[i])
             and model.geom_type[i] != mujoco.mjtGeom.mjGEOM_PLANE]
    if len(geoms) != 1:
        raise InputError(src, fld, f"body {name!r} has {len(geoms)} collidable geoms; an "
                         "object is one geom: name the geom")
    return geoms[0]


def _upright(rot: np.ndarray, src: str, fld: str, name: str) -> float:
    """The yaw of an upright geom frame ``rot`` (3 x 3)."""
    if abs(1.0 - rot[2, 2]) > UPRIGHT_TOL:
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, rot[2, 2]))))
        raise InputError(src, fld, f"geom {name!r} is tilted {tilt:.3g} degrees; objects stand "
                         "upright (only meshes may be turned any way)")
    return math.atan2(rot[1, 0], rot[0, 0])


def import_mjcf(xml: str | Path, mapping: Mapping[str, Any], mesh_dir: str | Path,
                mapping_source: str = "<mapping>") -> dict:
    """A scene table (the scene file's format) of the MJCF file ``xml``: the objects the
    ``mapping`` names (``tasks``: a list of ``{id, object, template}`` and optional
    ``bounds``, ``fixed``; ``obstacles``: names of objects without a task; ``objects``:
    per object id ``{kind = "cup"}``; ``name``) and its tasks. Mesh geoms are written as
    STL files into ``mesh_dir``, named by their objects; the scene refers to them by
    file name (write the scene into ``mesh_dir``). Errors name the MJCF file or the
    mapping, and the field."""
    xml = Path(xml)
    src = mapping_source
    mujoco, model, data = _model(xml)
    tasks = mapping.get("tasks")
    if not isinstance(tasks, list) or not tasks:
        raise InputError(src, "tasks", "must be a non-empty list of {id, object, template}")
    kinds = mapping.get("objects", {})
    if not isinstance(kinds, Mapping):
        raise InputError(src, "objects", "must be a table of object id = {kind = ...}")
    names: dict[str, str] = {}  # object id -> its name in the MJCF, in order of first use
    out_tasks = []
    for i, t in enumerate(tasks):
        if not isinstance(t, Mapping) or not {"id", "object", "template"} <= set(t):
            raise InputError(src, f"tasks[{i}]", f"must be a table with id, object and "
                             f"template, got {shown(t)}")
        name = t["object"]
        if not isinstance(name, str):
            raise InputError(src, f"tasks[{i}].object", f"must be a name, got {shown(name)}")
        oid = name.removeprefix(EXPORT_PREFIX)
        names.setdefault(oid, name)
        out_tasks.append({**t, "object": oid})
    obstacles = mapping.get("obstacles", [])
    if not isinstance(obstacles, list) or not all(isinstance(n, str) for n in obstacles):
        raise InputError(src, "obstacles", "must be a list of geom or body names")
    for name in obstacles:
        names.setdefault(name.removeprefix(EXPORT_PREFIX), name)
    handles = {t["object"] for t in out_tasks if t["template"] == "handle_grasp"}
    recorded = {}  # the kinds ``shacc export-mjcf`` records
    for i in range(model.ntext):
        key = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TEXT, i) or ""
        if key.startswith("shacc:kind:"):
            adr, n = model.text_adr[i], model.text_size[i]
            recorded[key.removeprefix("shacc:kind:")] = bytes(model.text_data[adr:adr + n - 1]
                                                              ).decode()
    objects = []
    for oid, name in names.items():
        fld = f"objects[{oid}]"
        g = _geom_of(mujoco, model, name, src, fld)
        rot = data.geom_xmat[g].reshape(3, 3)
        pos = np.asarray(data.geom_xpos[g], float)
        size = np.asarray(model.geom_size[g], float)
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            yaw = _upright(rot, str(xml), fld, name)
            asked = kinds.get(oid)
            want = asked.get("kind") if isinstance(asked, Mapping) else None
            if want is not None and want not in ("mug", "cup"):
                raise InputError(src, f"objects.{oid}.kind", f"a cylinder is a mug or a cup, "
                                 f"got {shown(want)}")
            if want is None and recorded.get(oid) in ("mug", "cup"):
                want = recorded[oid]
            obj = {"id": oid, "kind": want or ("cup" if oid in handles else "mug"),
                   "position": (pos - [0.0, 0.0, size[1]]).tolist(), "radius": size[0],
                   "height": 2 * size[1], "yaw": yaw}
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            yaw = _upright(rot, str(xml), fld, name)
            obj = {"id": oid, "kind": "box", "position": (pos - [0.0, 0.0, size[2]]).tolist(),
                   "half_extents": size.tolist(), "yaw": yaw}
        elif kind == mujoco.mjtGeom.mjGEOM_MESH:
            obj = {"id": oid, "kind": "mesh", "position": pos.tolist(),
                   "mesh": _write_mesh(model, g, rot, Path(mesh_dir), oid)}
        else:
            raise InputError(xml, fld, f"geom {name!r} is a {mujoco.mjtGeom(kind).name[7:].lower()}"
                             "; objects are cylinders, boxes or meshes")
        objects.append({k: (float(v) if isinstance(v, np.floating) else v)
                        for k, v in obj.items() if not (k == "yaw" and v == 0.0)})
    return {"name": mapping.get("name", model.names[:model.names.index(b"\0")].decode()
                                or xml.stem),
            "objects": objects, "tasks": out_tasks}


def _write_mesh(model, g: int, rot: np.ndarray, folder: Path, oid: str) -> str:
    """Mesh geom ``g``'s vertices turned into the world's orientation, as an STL file."""
    import trimesh  # deferred: 1.1 s to import

    m = model.geom_dataid[g]
    v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
    f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
    vertices = np.asarray(model.mesh_vert[v0:v0 + nv], float) @ rot.T
    faces = np.asarray(model.mesh_face[f0:f0 + nf], np.int64)
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in oid)
    name = f"{safe}.stl"
    trimesh.Trimesh(vertices, faces, process=False).export(folder / name)
    return name
