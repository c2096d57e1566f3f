"""Scenes from MuJoCo (reference/mujoco, "Scenes from MuJoCo"): the geoms of an MJCF file
that the user names become the objects of a scene file, with the tasks the user gives.

MuJoCo reads the file (includes, defaults, meshes and all) and places every geom
(``mj_forward``). A name in the mapping is a geom's or a body's, or a glob pattern
(``mug_*``) over the bodies' names, one object per body it matches. A body stands for
its collision geoms (contype or conaffinity set), or, where it has none, for its visual
ones, as robot-learning packages ship their objects:

- one cylinder becomes a mug (a cup where the mapping says ``kind = "cup"``, where the
  file records it, as ``shacc export-mjcf`` does, or where a task on it is a handle
  grasp): radius and height from its size, position at the centre of its base, yaw
  from its frame;
- one box becomes a box: half extents, base centre, yaw;
- a tilt of a cylinder or a box below ``max_tilt`` (1 degree) is levelled, with a
  warning; a larger one is refused;
- one mesh becomes a mesh object placed at its geom frame as the file writes it (not
  at its centre of mass, where MuJoCo moves a mesh's frame): its vertices turned into
  the world's orientation, written as an STL file beside the scene;
- several geoms become one mesh object, the union of their solids (meshes and
  primitives; an open mesh stands for its convex hull, with a warning), placed at the
  body's frame.

An id is the geom's (or body's) name, less the ``object:`` prefix that ``shacc
export-mjcf`` writes, so a scene exported and imported again keeps its ids. Other geoms
(a table, the lights, the spaces ``export-mjcf`` draws) are left out unless named as
``obstacles``.
"""

from __future__ import annotations

import fnmatch
import math
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, SceneWarning, shown

EXPORT_PREFIX = "object:"
UPRIGHT_TOL = 1e-6  # |1 - z.z| of a geom's frame that still counts as upright
MAX_TILT_DEG = 1.0  # a primitive tilted less than this is levelled, with a warning
PATTERN = set("*?[")
SECTIONS = 64       # sides of a round primitive's polygon inside a union


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


def _collides(model, i: int) -> bool:
    return bool(model.geom_contype[i] or model.geom_conaffinity[i])


def _geoms_of(mujoco, model, name: str, src: str, fld: str) -> list[int]:
    """The geoms that ``name`` stands for: a geom of that name, or the collision geoms
    of the body of that name (its visual ones where it has none; planes never)."""
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
    if g >= 0:
        return [g]
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if b < 0:
        raise InputError(src, fld, f"no geom or body named {name!r} in the MJCF")
    own = [i for i in range(model.ngeom) if model.geom_bodyid[i] == b
           and model.geom_type[i] != mujoco.mjtGeom.mjGEOM_PLANE]
    colliding = [i for i in own if _collides(model, i)]
    if not (colliding or own):
        raise InputError(src, fld, f"body {name!r} has no geoms of its own")
    return colliding or own


def _expand(mujoco, model, name: str, src: str, fld: str) -> list[str]:
    """The body names a glob pattern matches (a plain name: itself)."""
    if not PATTERN & set(name):
        return [name]
    bodies = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
              for b in range(model.nbody)]
    found = [b for b in bodies if b and fnmatch.fnmatchcase(b, name)]
    if not found:
        raise InputError(src, fld, f"no body matches the pattern {name!r}")
    return found


def _upright(rot: np.ndarray, src: str, fld: str, name: str, max_tilt: float) -> float:
    """The yaw of a geom frame ``rot`` (3 x 3) that stands upright, or is tilted less
    than ``max_tilt`` degrees (levelled, with a warning)."""
    if abs(1.0 - rot[2, 2]) > UPRIGHT_TOL:
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, rot[2, 2]))))
        if tilt >= max_tilt:
            raise InputError(src, fld, f"geom {name!r} is tilted {tilt:.3g} degrees, more than "
                             f"--max-tilt ({max_tilt:g}); cylinders and boxes stand upright "
                             "(only meshes may be turned any way)")
        warnings.warn(SceneWarning(f"{src}: {fld}: geom {name!r} is tilted {tilt:.3g} degrees "
                                   "(below --max-tilt); levelled"), stacklevel=3)
    return math.atan2(rot[1, 0], rot[0, 0])


def import_mjcf(xml: str | Path, mapping: Mapping[str, Any], mesh_dir: str | Path,
                mapping_source: str = "<mapping>", max_tilt: float = MAX_TILT_DEG,
                stand: bool = False) -> dict:
    """A scene table (the scene file's format) of the MJCF file ``xml``: the objects the
    ``mapping`` names (``tasks``: a list of ``{id, object, template}`` and optional
    ``bounds``, ``fixed``; ``obstacles``: names of objects without a task; ``objects``:
    per object id ``{kind = "cup"}``; ``name``; a name may be a glob pattern over
    bodies, a task on one made one task per body, its id ``ID-BODY``) and its tasks.
    Cylinders and boxes tilted less than ``max_tilt`` degrees are levelled; ``stand``
    moves every object up or down until its lowest point is on the table (z = 0), as
    an object file that packages centre on its origin needs. Meshes are written as
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
        written = t["object"]
        if not isinstance(written, str):
            raise InputError(src, f"tasks[{i}].object", f"must be a name, got "
                             f"{shown(written)}")
        found = _expand(mujoco, model, written, src, f"tasks[{i}].object")
        for name in found:
            oid = name.removeprefix(EXPORT_PREFIX)
            names.setdefault(oid, name)
            tid = t["id"] if found == [written] else f"{t['id']}-{oid}"
            out_tasks.append({**t, "id": tid, "object": oid})
    obstacles = mapping.get("obstacles", [])
    if not isinstance(obstacles, list) or not all(isinstance(n, str) for n in obstacles):
        raise InputError(src, "obstacles", "must be a list of geom or body names")
    for i, written in enumerate(obstacles):
        for name in _expand(mujoco, model, written, src, f"obstacles[{i}]"):
            names.setdefault(name.removeprefix(EXPORT_PREFIX), name)
    handles = {t["object"] for t in out_tasks if t["template"] == "handle_grasp"}
    recorded = {}  # the kinds ``shacc export-mjcf`` records
    for i in range(model.ntext):
        key = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_TEXT, i) or ""
        if key.startswith("shacc:kind:"):
            adr, n = model.text_adr[i], model.text_size[i]
            recorded[key.removeprefix("shacc:kind:")] = bytes(model.text_data[adr:adr + n - 1]
                                                              ).decode()
    objects: list[dict[str, Any]] = []
    for oid, name in names.items():
        fld = f"objects[{oid}]"
        geoms = _geoms_of(mujoco, model, name, src, fld)
        if len(geoms) > 1:
            b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            origin = np.asarray(data.xpos[b], float)
            file, low = _write_union(mujoco, model, data, geoms, origin, Path(mesh_dir), oid,
                                     str(xml), fld)
            objects.append({"id": oid, "kind": "mesh", "mesh": file,
                            "position": _stood(origin, low, stand)})
            continue
        g = geoms[0]
        obj: dict[str, Any]
        rot = data.geom_xmat[g].reshape(3, 3)
        pos = np.asarray(data.geom_xpos[g], float)
        size = np.asarray(model.geom_size[g], float)
        kind = model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            yaw = _upright(rot, str(xml), fld, name, max_tilt)
            asked = kinds.get(oid)
            want = asked.get("kind") if isinstance(asked, Mapping) else None
            if want is not None and want not in ("mug", "cup"):
                raise InputError(src, f"objects.{oid}.kind", f"a cylinder is a mug or a cup, "
                                 f"got {shown(want)}")
            if want is None and recorded.get(oid) in ("mug", "cup"):
                want = recorded[oid]
            obj = {"id": oid, "kind": want or ("cup" if oid in handles else "mug"),
                   "position": _stood(pos - [0.0, 0.0, size[1]], 0.0, stand),
                   "radius": size[0], "height": 2 * size[1], "yaw": yaw}
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            yaw = _upright(rot, str(xml), fld, name, max_tilt)
            obj = {"id": oid, "kind": "box",
                   "position": _stood(pos - [0.0, 0.0, size[2]], 0.0, stand),
                   "half_extents": size.tolist(), "yaw": yaw}
        elif kind == mujoco.mjtGeom.mjGEOM_MESH:
            frame = _mesh_frame(mujoco, model, data, g)
            vertices, faces = _world_mesh(model, data, g)
            file, low = _write_stl(vertices - frame, faces, Path(mesh_dir), oid)
            obj = {"id": oid, "kind": "mesh", "position": _stood(frame, low, stand),
                   "mesh": file}
        else:
            raise InputError(xml, fld, f"geom {name!r} is a {mujoco.mjtGeom(kind).name[7:].lower()}"
                             "; objects are cylinders, boxes or meshes")
        objects.append({k: (float(v) if isinstance(v, np.floating) else v)
                        for k, v in obj.items() if not (k == "yaw" and v == 0.0)})
    return {"name": mapping.get("name", model.names[:model.names.index(b"\0")].decode()
                                or xml.stem),
            "objects": objects, "tasks": out_tasks}


def _stood(position, low: float, stand: bool) -> list[float]:
    """An object's position; with ``stand``, moved along z until its lowest point (at
    ``low`` above its origin) is on the table."""
    x, y, z = (float(v) for v in position)
    return [x, y, -low if stand else z]


def _mesh_frame(mujoco, model, data, g: int) -> np.ndarray:
    """Where mesh geom ``g``'s frame is, as the file writes it: MuJoCo moves a mesh's
    vertices by ``mesh_pos`` (to its centre of mass) and the geom's frame with them."""
    m = model.geom_dataid[g]
    turn = np.zeros(9)
    mujoco.mju_quat2Mat(turn, model.mesh_quat[m])
    frame_rot = data.geom_xmat[g].reshape(3, 3) @ turn.reshape(3, 3).T
    return np.asarray(data.geom_xpos[g], float) - frame_rot @ model.mesh_pos[m]


def _world_mesh(model, data, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Mesh geom ``g``'s vertices (as MuJoCo holds them, float32) in the world, and its
    triangles."""
    m = model.geom_dataid[g]
    v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
    f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
    rot = data.geom_xmat[g].reshape(3, 3)
    vertices = np.asarray(model.mesh_vert[v0:v0 + nv], float) @ rot.T + data.geom_xpos[g]
    return vertices, np.asarray(model.mesh_face[f0:f0 + nf], np.int64)


def _primitive(mujoco, model, data, g: int):
    """Geom ``g``, a primitive, as a trimesh in the world."""
    import trimesh  # deferred: 1.1 s to import

    t, size = model.geom_type[g], np.asarray(model.geom_size[g], float)
    G = mujoco.mjtGeom
    if t == G.mjGEOM_BOX:
        mesh = trimesh.creation.box(2 * size)
    elif t == G.mjGEOM_CYLINDER:
        mesh = trimesh.creation.cylinder(size[0], 2 * size[1], sections=SECTIONS)
    elif t == G.mjGEOM_CAPSULE:
        mesh = trimesh.creation.capsule(2 * size[1], size[0], count=[SECTIONS, SECTIONS // 2])
    elif t in (G.mjGEOM_SPHERE, G.mjGEOM_ELLIPSOID):
        mesh = trimesh.creation.icosphere(4)
        mesh.apply_scale(size if t == G.mjGEOM_ELLIPSOID else size[0])
    else:
        return None
    pose = np.eye(4)
    pose[:3, :3] = data.geom_xmat[g].reshape(3, 3)
    pose[:3, 3] = data.geom_xpos[g]
    mesh.apply_transform(pose)
    return mesh


def _write_union(mujoco, model, data, geoms: list[int], origin: np.ndarray, folder: Path,
                 oid: str, src: str, fld: str) -> tuple[str, float]:
    """The union of a body's geoms (manifold3d) about ``origin``, as an STL file (its
    name, and its lowest point's height above ``origin``). An open mesh geom takes part
    by its convex hull, with a warning."""
    import manifold3d  # deferred: 18 ms to import
    import trimesh  # deferred: 1.1 s to import

    parts = []
    for g in geoms:
        gname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            v, f = _world_mesh(model, data, g)
            mesh = trimesh.Trimesh(v, f, process=True)
            if not mesh.is_watertight:
                warnings.warn(SceneWarning(f"{src}: {fld}: mesh geom {gname!r} is not "
                                           "watertight; its convex hull takes part in the "
                                           "union"), stacklevel=3)
                mesh = mesh.convex_hull
        else:
            mesh = _primitive(mujoco, model, data, g)
            if mesh is None:
                kind = mujoco.mjtGeom(model.geom_type[g]).name[7:].lower()
                raise InputError(src, fld, f"geom {gname!r} is a {kind}; an object's geoms are "
                                 "boxes, cylinders, capsules, spheres, ellipsoids or meshes")
        parts.append(manifold3d.Manifold(manifold3d.Mesh(
            vert_properties=np.asarray(mesh.vertices - origin, np.float32),
            tri_verts=np.asarray(mesh.faces, np.uint32))))
    union = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add)
    out = union.to_mesh64()
    return _write_stl(np.asarray(out.vert_properties)[:, :3], np.asarray(out.tri_verts),
                      folder, oid)


def _write_stl(vertices: np.ndarray, faces: np.ndarray, folder: Path,
               oid: str) -> tuple[str, float]:
    """Vertices (m, in the world's orientation about the object's origin) and triangles
    as an STL file named by the object: its name, and the lowest vertex's height."""
    import trimesh  # deferred: 1.1 s to import

    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in oid)
    name = f"{safe}.stl"
    trimesh.Trimesh(vertices, faces, process=False).export(folder / name)
    return name, float(vertices[:, 2].min())
