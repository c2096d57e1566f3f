"""Objects made of a triangle mesh (reference/scenes, "Mesh objects"): the file read
with trimesh, checked, measured and placed.

A mesh object is ``kind = "mesh"`` with ``mesh = "FILE"`` (OBJ, STL, PLY or GLB; a path
relative to the scene file), an optional ``scale`` (the factor from the file's units to
metres, default 1), placed by ``position`` (where the mesh's origin goes) and ``yaw``
(about the vertical axis through the origin).

- Its solid is the mesh where the mesh is watertight (every edge on exactly two
  triangles); a mesh that is not (holes, or non-manifold edges on three triangles or
  more, as many scanned and CAD meshes are) stands for its convex hull, with a warning
  line that says why. An empty mesh, an unreadable file and a mesh without volume are
  refused with a one-line error.
- Its "radius" and "height", which the templates size their spaces by, are those of its
  bounding upright cylinder about the vertical axis through the origin: the largest
  horizontal distance of a vertex from that axis, and the vertices' height range. The
  object's base is the lowest vertex's height (``SceneObject.base``).

Reading a scene measures its meshes (trimesh, no collision library); the solids are made
where the geometry is built (interpenetration, pictures, MJCF).
"""

from __future__ import annotations

import functools
import io
import math
import os
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError, SceneWarning

FORMATS = (".obj", ".stl", ".ply", ".glb")
MAX_MESH_BYTES = 256 * 2**20  # a mesh file larger than this is refused
MIN_VOLUME = 1e-9             # m^3: a solid smaller than a cubic millimetre has no volume
LARGE = 2.0                   # m: a mesh larger than this looks like millimetres


@dataclass(frozen=True)
class MeshInfo:
    """A mesh object's file and measures: ``digest`` (CRC-32 of the file's bytes, which
    names the mesh wherever the file lies), ``scale``, ``radius`` and ``z_min``,
    ``z_max`` (m, in the object's frame, scaled), whether its convex hull stands for
    it (``hull``), its triangles, and where the file is (``path``, not part of its
    identity) and how the scene wrote it (``written``)."""

    digest: int
    scale: float
    radius: float
    z_min: float
    z_max: float
    hull: bool
    faces: int
    vertices: np.ndarray | None = field(default=None, compare=False, repr=False)
    triangles: np.ndarray | None = field(default=None, compare=False, repr=False)
    path: str = field(default="", compare=False, repr=False)
    written: str = field(default="", compare=False, repr=False)


def resolve(written: str, source: str) -> Path:
    """A mesh path as written in a scene: relative to the scene file's folder (to the
    working folder for a scene that is not a file)."""
    p = Path(written).expanduser()
    if p.is_absolute() or source.startswith("<"):
        return p
    return Path(source).parent / p


@functools.lru_cache(maxsize=128)
def _read(path: str, stamp: tuple[int, int]):
    """(digest, trimesh.Trimesh) of a mesh file, as read (cached per file and stamp)."""

    import trimesh  # deferred: 1.1 s to import

    data = Path(path).read_bytes()
    kind = Path(path).suffix.lower().lstrip(".")
    mesh = trimesh.load(io.BytesIO(data), file_type=kind, force="mesh", process=True)
    return zlib.crc32(data), mesh


def load(written: str, scale: float, source: str, where: str) -> MeshInfo:
    """The :class:`MeshInfo` of a mesh object's file, or a one-line InputError naming the
    scene file and the field (``where``: ``objects[ID].``)."""
    path = resolve(written, source)
    fld = where + "mesh"
    if path.suffix.lower() not in FORMATS:
        raise InputError(source, fld, f"{written!r}: not a mesh file this tool reads "
                         f"({', '.join(FORMATS)})")
    try:
        st = os.stat(path)
    except OSError as e:
        raise InputError(source, fld, f"{written!r}: cannot be read ({e.strerror})") from None
    if not path.is_file():
        raise InputError(source, fld, f"{written!r}: is not a file")
    if st.st_size > MAX_MESH_BYTES:
        raise InputError(source, fld, f"{written!r}: larger than {MAX_MESH_BYTES >> 20} MiB")
    try:
        digest, mesh = _read(str(path.resolve()), (st.st_mtime_ns, st.st_size))
    except Exception as e:  # trimesh raises many kinds for a broken file
        raise InputError(source, fld, f"{written!r}: could not be read as a mesh "
                         f"({type(e).__name__}: {e})") from None
    if len(getattr(mesh, "faces", ())) == 0:
        raise InputError(source, fld, f"{written!r}: holds no triangles")
    counts = np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique))
    why = (f"{int((counts > 2).sum())} edges on more than two triangles" if (counts > 2).any()
           else f"{int((counts == 1).sum())} edges on one triangle")
    hull = not mesh.is_watertight
    try:
        volume = abs(float((mesh.convex_hull if hull else mesh).volume)) * scale ** 3
    except Exception:  # qhull refuses points on a plane or a line: no volume either
        volume = 0.0
    if not volume >= MIN_VOLUME:
        raise InputError(source, fld, f"{written!r}: has no volume ({volume:.3g} m^3 at scale "
                         f"{scale:g}); a solid object is needed")
    body = mesh.convex_hull if hull else mesh
    v = np.asarray(mesh.vertices, float) * scale
    radius = float(np.max(np.hypot(v[:, 0], v[:, 1])))
    info = MeshInfo(digest, float(scale), radius, float(v[:, 2].min()), float(v[:, 2].max()),
                    hull, len(mesh.faces), np.asarray(body.vertices, float) * scale,
                    np.asarray(body.faces, np.int64), str(path.resolve()), written)
    if hull:
        warnings.warn(SceneWarning(f"{source}: {fld}: {written!r} is not watertight ({why}); "
                                   "its convex hull stands for it"), stacklevel=4)
    size = float(np.max(np.ptp(v, axis=0)))
    if size > LARGE:
        warnings.warn(SceneWarning(
            f"{source}: {where}scale: the mesh is {size:g} m across at scale {scale:g}; if "
            f"its file is in millimetres, scale = {scale / 1000:g}"), stacklevel=4)
    return info


# Hull triangles smaller than this (m^2) are dropped: their plane is rounding noise, and
# their neighbours' edges and faces bound the hull where they were.
MIN_HULL_TRIANGLE = 1e-14
_HULLS: dict[tuple[int, float], tuple[np.ndarray, np.ndarray]] = {}


def hull(info: MeshInfo) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of the mesh's solid, in the mesh's frame (scaled, m), as the
    collision check takes it (MuJoCo too collides with a mesh's convex hull): triangles
    (F, 3, 3), counter-clockwise seen from outside, and their outward unit normals
    (F, 3). Computed once per mesh file and scale (qhull, through trimesh)."""
    key = (info.digest, info.scale)
    if key not in _HULLS:
        import trimesh  # deferred: 1.1 s to import

        assert info.vertices is not None  # load() keeps them
        h = trimesh.convex.convex_hull(info.vertices)
        tri = np.asarray(h.triangles, float)
        normals = np.asarray(h.face_normals, float)
        # trimesh winds a hull's faces outward; the check relies on it.
        turn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area = 0.5 * np.linalg.norm(turn, axis=1)
        assert np.all(np.einsum("fi,fi->f", turn, normals) >= 0)
        keep = area > MIN_HULL_TRIANGLE
        _HULLS[key] = (tri[keep], normals[keep])
    return _HULLS[key]


def solid(info: MeshInfo, position, yaw: float):
    """The object's solid (the mesh, or its convex hull) as a trimesh in the world frame:
    scaled, turned by ``yaw`` about the vertical axis through its origin, moved to
    ``position``."""
    import trimesh  # deferred: 1.1 s to import

    return trimesh.Trimesh(placed(info, position, yaw), info.triangles, process=False)


def placed(info: MeshInfo, position, yaw: float) -> np.ndarray:
    """The solid's vertices in the world frame, (n, 3)."""
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert info.vertices is not None  # load() keeps them
    return info.vertices @ turn.T + np.asarray(position, float)
