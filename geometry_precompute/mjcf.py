"""A precomputed scene as MJCF (reference/mujoco): a table, the objects as collidable
geoms (cylinders, boxes), and the position spaces as visual-only translucent geoms,
initial in red and optimised in blue. MuJoCo has no cone geom, so cones become meshes
(the manifold3d meshes of :mod:`geometry_precompute.meshes`, vertices in world
coordinates; MuJoCo recentres a mesh and moves its geom frame to match, so it stays
in place); a mesh object's geom stands at its origin, its vertices about it. Object
bodies collide (contype 1); spaces never do (contype 0, group 1 for
initial, group 2 for optimised spaces, so viewers can toggle them).
"""

from __future__ import annotations

from dataclasses import replace
from xml.sax.saxutils import quoteattr

import numpy as np

from .bodies import object_body, object_solid
from .frames import quat_of_rotation, yaw_matrix
from .meshes import shape_trimesh
from .precomputing import PrecomputeResult
from .shapes import Shape

INIT_RGBA = "0.9 0.1 0.1 0.22"
OPT_RGBA = "0.1 0.3 0.95 0.35"
TABLE_HALF = 0.6


def _fmt(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in np.ravel(v))


def _geom(shape: Shape, name: str, rgba: str, collide: bool, group: int,
          mesh: str | None = None, at=None) -> str:
    flags = "" if collide else ' contype="0" conaffinity="0"'
    a, b, c = shape.dims
    if mesh is not None:
        pos = "" if at is None else f' pos="{_fmt(at)}"'
        return f'<geom name={quoteattr(name)} type="mesh" mesh="{mesh}"{pos} rgba="{rgba}" ' \
               f'group="{group}"{flags}/>'
    size: tuple[float, ...]
    if shape.kind in ("cylinder", "disk"):
        kind, size = "cylinder", (a, b / 2)
    else:
        kind, size = "box", (a, b, c)
    return (f'<geom name={quoteattr(name)} type="{kind}" size="{_fmt(size)}" '
            f'pos="{_fmt(shape.center)}" quat="{_fmt(shape.quat)}" rgba="{rgba}" '
            f'group="{group}"{flags}/>')


def scene_to_mjcf(result: PrecomputeResult, sections: int = 32, spaces: str = "both",
                  opt_rgba: str | None = None) -> str:
    """MJCF text of a precomputed scene; ``spaces`` is "both", "init", "opt" or "none";
    ``opt_rgba`` the colour of the second spaces (default blue, Shrinking's)."""
    scene = result.scene
    assets, geoms = [], []
    pos = np.array([o.position for o in scene.objects])
    center = pos.mean(axis=0)
    geoms.append(f'<geom name="table" type="box" size="{TABLE_HALF} {TABLE_HALF} 0.01" '
                 f'pos="{_fmt(center[:2])} -0.01" rgba="0.75 0.7 0.62 1"/>')
    for o in scene.objects:
        body = object_body(o)
        if body.kind == "cylinder" and o.mesh is None:
            # Turned by the yaw (a cup's handle direction), which the round shape does not
            # show but ``shacc import-mjcf`` reads back.
            body = replace(body, quat=quat_of_rotation(yaw_matrix(o.yaw)))
        mesh = None
        if o.mesh is not None:  # its solid, about its origin (where ``import-mjcf`` puts it)
            tm = object_solid(o)
            mesh = f"object:{o.id}"
            local = tm.vertices - np.asarray(o.position)
            assets.append(f'<mesh name={quoteattr(mesh)} vertex="{_fmt(local)}" '
                          f'face="{" ".join(str(int(i)) for i in tm.faces.ravel())}"/>')
        geoms.append(_geom(body, f"object:{o.id}", "0.25 0.25 0.28 1", True, 0, mesh,
                           o.position if mesh else None))
    which = {"both": ("init", "opt"), "init": ("init",), "opt": ("opt",), "none": ()}[spaces]
    for w in which:
        shapes = result.shapes_init if w == "init" else result.shapes_opt
        rgba, group = (INIT_RGBA, 1) if w == "init" else (opt_rgba or OPT_RGBA, 2)
        for task, shape in zip(result.task_ids, shapes, strict=True):
            name = f"space:{w}:{task}"
            mesh = None
            if shape.kind == "cone":
                tm = shape_trimesh(shape, sections)
                mesh = f"mesh:{w}:{task}"
                assets.append(f'<mesh name={quoteattr(mesh)} vertex="{_fmt(tm.vertices)}" '
                              f'face="{" ".join(str(int(i)) for i in tm.faces.ravel())}"/>')
            geoms.append(_geom(shape, name, rgba, False, group, mesh))
    eye = center + np.array([-1.1, -0.7, 0.8])
    return "\n".join([
        f"<mujoco model={quoteattr(scene.name)}>",
        '  <visual><global offwidth="1920" offheight="1080"/></visual>',
        "  <asset>", *(f"    {a}" for a in assets), "  </asset>",
        # The object kinds, which the geoms do not show (a cup is a cylinder): read back by
        # ``shacc import-mjcf``.
        "  <custom>", *(f'    <text name={quoteattr(f"shacc:kind:{o.id}")} data="{o.kind}"/>'
                        for o in scene.objects), "  </custom>",
        "  <worldbody>",
        f'    <light pos="{_fmt(center[:2])} 2.0" dir="0 0 -1" diffuse="0.8 0.8 0.8"/>',
        f'    <camera name="overview" mode="targetbody" target="world" pos="{_fmt(eye)}"/>',
        *(f"    {g}" for g in geoms),
        "  </worldbody>",
        "</mujoco>", ""])
