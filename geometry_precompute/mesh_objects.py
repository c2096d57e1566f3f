"""Objects made of a triangle mesh (reference/scenes, "Mesh objects"): the file read
with trimesh, checked, measured and placed.

A mesh object is ``kind = "mesh"`` with ``mesh = "FILE"`` (OBJ, STL, PLY or GLB; a path
relative to the scene file). The file's coordinates become the object's upright frame by
its :class:`Placement`: the file's up axis (``up = "z" | "y"``), its length unit
(``unit = "m" | "cm" | "mm"`` or a ``scale``), a tilt (the roll and pitch of ``rpy`` or
``quat``) and its origin (``origin = "file" | "base"``). The object then stands at
``position`` turned by its yaw about the vertical axis through its origin.

- Coinciding vertices are merged first (texture seams split them in most scans). The
  solid is the mesh where it is then watertight (every edge on exactly two triangles); a
  mesh that is not (holes, or non-manifold edges on three triangles or more, as many
  scanned and CAD meshes are) stands for its convex hull, with a warning line that says
  why. An empty mesh, an unreadable file and a mesh without volume are refused with a
  one-line error.
- Its "radius" and "height", which the templates size their spaces by, are those of its
  bounding upright cylinder about the vertical axis through the origin, after placement:
  the largest horizontal distance of a vertex from that axis, and the vertices' height
  range. The object's base is the lowest vertex's height (``SceneObject.base``).
- Placed, a mesh reaching more than 1 mm below the table is refused and one floating
  more than 5 mm above it gets a warning (:func:`check_height`), each naming the likely
  cause.

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
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, SceneWarning, shown

FORMATS = (".obj", ".stl", ".ply", ".glb")
MAX_MESH_BYTES = 256 * 2**20  # a mesh file larger than this is refused
MIN_VOLUME = 1e-9             # m^3: a solid smaller than a cubic millimetre has no volume
LARGE = 2.0                   # m: a mesh larger than this looks like millimetres


# --- Placement -------------------------------------------------------------------------

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
UPS = ("z", "y")
ORIGINS = ("file", "base")
PLACEMENT_KEYS = ("up", "unit", "scale", "rpy", "quat", "origin")
BELOW_TABLE = 1e-3  # m: a placed mesh reaching further below the table is refused
FLOATING = 5e-3     # m: one whose lowest point is higher above the table gets a warning
TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Placement:
    """How a mesh file's coordinates become the object's upright frame: ``up`` (the
    file's up axis, ``"z"`` or ``"y"``), ``scale`` (metres per unit of the file, from
    ``unit`` or ``scale``), the tilt ``roll`` and ``pitch`` (rad; the yaw stays the
    object's own, turned about the vertical axis) and ``origin`` (``"file"``: the file's
    origin is the object's; ``"base"``: the centre of the lowest face of the mesh's
    bounding box is)."""

    scale: float = 1.0
    up: str = "z"
    roll: float = 0.0
    pitch: float = 0.0
    origin: str = "file"
    turned_by: str = field(default="yaw", compare=False)  # the key that gave the yaw

    def matrix(self) -> np.ndarray:
        """The 3 x 3 map from the file's coordinates to the object's upright frame,
        scale included (the origin's shift follows it)."""
        up = np.eye(3) if self.up == "z" else np.array([[1.0, 0, 0], [0, 0, -1.0],
                                                         [0, 1.0, 0]])
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
        ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
        return self.scale * (ry @ rx @ up)

    def written(self, yaw: float) -> dict[str, Any]:
        """The scene file's keys that give this placement and ``yaw`` (defaults left
        out): ``scale``, ``up``, ``origin`` and ``rpy`` or ``yaw``."""
        out: dict[str, Any] = {}
        if self.scale != 1.0:
            out["scale"] = self.scale
        if self.up != "z":
            out["up"] = self.up
        if self.origin != "file":
            out["origin"] = self.origin
        if self.roll or self.pitch:
            out["rpy"] = [self.roll, self.pitch, yaw]
        elif yaw:
            out["yaw"] = yaw
        return out


def yaw_and_tilt(rot: np.ndarray) -> tuple[float, float, float]:
    """(yaw, roll, pitch) of a rotation matrix, ``rot = Rz(yaw) Ry(pitch) Rx(roll)``
    exactly; where the pitch is +-90 degrees the yaw is 0 and the roll takes the turn."""
    if math.hypot(rot[0, 0], rot[1, 0]) < 1e-12:
        pitch = math.copysign(math.pi / 2, -rot[2, 0])
        return 0.0, math.atan2(-rot[1, 2], rot[1, 1]), pitch
    yaw = math.atan2(rot[1, 0], rot[0, 0])
    pitch = math.atan2(-rot[2, 0], math.hypot(rot[2, 1], rot[2, 2]))
    return yaw, math.atan2(rot[2, 1], rot[2, 2]), pitch


def quat_matrix(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion ``[w, x, y, z]``."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _numbers(value: Any, n: int, source: str, fld: str) -> list[float]:
    if (not isinstance(value, list | tuple) or len(value) != n
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)):
        raise InputError(source, fld, f"must be a list of {n} numbers, got {shown(value)}")
    if not all(math.isfinite(v) and abs(v) <= ANGLE_LIMIT for v in value):
        raise InputError(source, fld, f"must be finite numbers within +-{ANGLE_LIMIT:g}, got "
                         f"{shown(value)}")
    return [float(v) for v in value]


ANGLE_LIMIT = 1000.0  # as a yaw's: any angle, but not one whose cosine is rounding noise


def parse_placement(raw: Mapping[str, Any], yaw: float | None, source: str,
                    where: str) -> tuple[Placement, float]:
    """The :class:`Placement` and the yaw that the keys of ``raw`` give (``up``, ``unit``
    or ``scale``, ``rpy`` or ``quat``, ``origin``; ``yaw`` as the caller read it, None
    where it is not given), or a one-line InputError naming ``source`` and the field."""
    up = raw.get("up", "z")
    if up not in UPS:
        raise InputError(source, where + "up", f"must be \"z\" or \"y\" (the file's up axis; "
                         f"most scans and glTF files are Y-up), got {shown(up)}")
    if "unit" in raw and "scale" in raw:
        raise InputError(source, where + "unit", "give unit or scale, not both")
    if "unit" in raw:
        if raw["unit"] not in UNITS:
            raise InputError(source, where + "unit", f"must be one of {', '.join(UNITS)} (the "
                             f"file's length unit), got {shown(raw['unit'])}")
        scale = UNITS[raw["unit"]]
    else:
        scale = raw.get("scale", 1.0)
        if (isinstance(scale, bool) or not isinstance(scale, int | float)
                or not (math.isfinite(scale) and 0 < scale <= 1e3)):
            raise InputError(source, where + "scale", f"must be > 0 and at most 1000 (metres "
                             f"per unit of the file), got {shown(scale)}")
    origin = raw.get("origin", "file")
    if origin not in ORIGINS:
        raise InputError(source, where + "origin", f"must be \"file\" (the file's origin at "
                         f"position) or \"base\" (the centre of its bounding box's lowest "
                         f"face at position), got {shown(origin)}")
    given = [k for k in ("yaw", "rpy", "quat") if k in raw or (k == "yaw" and yaw is not None)]
    if len(given) > 1:
        raise InputError(source, where + given[1], f"give one orientation: {given[0]} or "
                         f"{given[1]}, not both")
    roll = pitch = 0.0
    if "rpy" in raw:
        roll, pitch, yaw = _numbers(raw["rpy"], 3, source, where + "rpy")
        if any(abs(v) > TWO_PI for v in (roll, pitch, yaw)):
            warnings.warn(SceneWarning(
                f"{source}: {where}rpy: {shown(raw['rpy'])} has an angle beyond 2 pi: rpy is "
                "in radians (degrees by mistake?)"), stacklevel=3)
    elif "quat" in raw:
        q = np.asarray(_numbers(raw["quat"], 4, source, where + "quat"))
        norm = float(np.linalg.norm(q))
        if norm < 1e-9:
            raise InputError(source, where + "quat", "a quaternion of zero norm is no rotation "
                             "([w, x, y, z]; [1, 0, 0, 0] is none)")
        yaw, roll, pitch = yaw_and_tilt(quat_matrix(q / norm))
    turned_by = "rpy" if "rpy" in raw else "quat" if "quat" in raw else "yaw"
    return Placement(float(scale), up, roll, pitch, origin, turned_by), float(yaw or 0.0)


@dataclass(frozen=True)
class MeshInfo:
    """A mesh object's file and measures: ``digest`` (CRC-32 of the file's bytes, which
    names the mesh wherever the file lies), its ``placement``, ``radius`` and ``z_min``,
    ``z_max`` (m, in the object's upright frame), whether its convex hull stands for it
    (``hull``), its triangles, and where the file is (``path``, not part of its identity)
    and how the scene wrote it (``written``)."""

    digest: int
    placement: Placement
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
    """(digest, trimesh.Trimesh) of a mesh file, its coinciding vertices merged (cached
    per file and stamp). The triangles are taken without the file's texture coordinates
    and normals, which keep a seam's vertices apart in trimesh's own merge."""

    import trimesh  # deferred: 1.1 s to import

    data = Path(path).read_bytes()
    kind = Path(path).suffix.lower().lstrip(".")
    mesh = trimesh.load(io.BytesIO(data), file_type=kind, force="mesh", process=False)
    mesh = trimesh.Trimesh(np.asarray(mesh.vertices, float),  # type: ignore[attr-defined]
                           np.asarray(mesh.faces), process=True)  # type: ignore[attr-defined]
    return zlib.crc32(data), mesh


def load(written: str, placement: Placement | float, source: str, where: str) -> MeshInfo:
    """The :class:`MeshInfo` of a mesh object's file placed by ``placement`` (a bare
    number: a scale), or a one-line InputError naming the scene file and the field
    (``where``: ``objects[ID].``)."""
    if not isinstance(placement, Placement):
        placement = Placement(scale=float(placement))
    scale = placement.scale
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
    turn = placement.matrix()
    v = np.asarray(mesh.vertices, float) @ turn.T
    shift = np.zeros(3)
    if placement.origin == "base":
        lo, hi = v.min(axis=0), v.max(axis=0)
        shift = -np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    v = v + shift
    radius = float(np.max(np.hypot(v[:, 0], v[:, 1])))
    info = MeshInfo(digest, placement, radius, float(v[:, 2].min()), float(v[:, 2].max()),
                    hull, len(mesh.faces), np.asarray(body.vertices, float) @ turn.T + shift,
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
_HULLS: dict[tuple[int, Placement], tuple[np.ndarray, np.ndarray]] = {}


def hull(info: MeshInfo) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of the mesh's solid, in the object's upright frame (placed, m), as
    the collision check takes it (MuJoCo too collides with a mesh's convex hull):
    triangles (F, 3, 3), counter-clockwise seen from outside, and their outward unit
    normals (F, 3). Computed once per mesh file and placement (qhull, through trimesh)."""
    key = (info.digest, info.placement)
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
    placed, turned by ``yaw`` about the vertical axis through its origin, moved to
    ``position``."""
    import trimesh  # deferred: 1.1 s to import

    return trimesh.Trimesh(placed(info, position, yaw), info.triangles, process=False)


def placed(info: MeshInfo, position, yaw: float) -> np.ndarray:
    """The solid's vertices in the world frame, (n, 3)."""
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert info.vertices is not None  # load() keeps them
    return info.vertices @ turn.T + np.asarray(position, float)


def check_height(info: MeshInfo, z: float, source: str, where: str) -> None:
    """A placed mesh's lowest point against the table (z = 0) when its origin is at
    height ``z``: more than 1 mm below it is refused, more than 5 mm above it warned of,
    each in one line naming the object, the distance and the likely causes."""
    low = z + info.z_min
    if -BELOW_TABLE <= low <= FLOATING:
        return
    p = info.placement
    causes = []
    extent = info.z_max - info.z_min
    if p.up == "z" and info.vertices is not None:
        xy = np.ptp(info.vertices[:, :2], axis=0)
        if xy.max() > 1.2 * extent:
            causes.append('a Y-up file (up = "y")')
    if p.origin == "file":
        causes.append('the file\'s origin not at its base (origin = "base" stands it on '
                      'position)')
    if p.scale == 1.0 and extent > 0.5:
        causes.append('centimetres or millimetres (unit = "cm" or "mm")')
    cause = "; likely " + " or ".join(causes) if causes else ""
    fld = where + "position"
    if low < -BELOW_TABLE:
        raise InputError(source, fld, f"the mesh {info.written!r} reaches {-low * 1000:.1f} mm "
                         f"below the table (z = 0) as placed{cause}")
    warnings.warn(SceneWarning(f"{source}: {fld}: the mesh {info.written!r} floats "
                               f"{low * 1000:.1f} mm above the table as placed{cause}"),
                  stacklevel=3)
