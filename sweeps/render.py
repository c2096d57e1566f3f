"""``shacc export-mjcf`` and ``shacc render``: a scene as MJCF, and a picture of it.

The picture is MuJoCo's offscreen render of the exported MJCF (spaces translucent:
initial red, optimised blue) beside the top-down matplotlib view, composed to exactly
``--width`` x ``--height`` pixels. MuJoCo renders through EGL; the command sets
``MUJOCO_GL=egl`` when it is unset, which works on CPU machines with Mesa's EGL.
``--path START TASK`` draws one rollout of ``--mode`` in both views: the straight
segment from the start to where it activated (or stopped), and the gripper's three
capsules (those the collision check uses) at the start pose and at the end pose, in
the orientation the rollout ended with (turned by the meta skill in ``shacc``).
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import NamedTuple

# MuJoCo picks its GL backend when it is first imported: choose EGL before that.
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from geometry_precompute import InputError
from geometry_precompute.mjcf import scene_to_mjcf

from .inputs import load_and_precompute
from .output import check_output_file, write_atomic
from .pipeline import evaluate_results

SPACES_FOR_MODE = {"baseline": "init", "shrinking": "both", "shacc": "both"}


def render_array(result, width: int, height: int, spaces: str = "both",
                 path: RolloutPath | None = None) -> np.ndarray:
    """(height, width, 3) uint8 image of the scene from the front-left, above."""
    import mujoco

    model = mujoco.MjModel.from_xml_string(scene_to_mjcf(result, spaces=spaces))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pos = np.array([o.position for o in result.scene.objects])
    cam = mujoco.MjvCamera()
    cam.lookat[:] = pos.mean(axis=0) + np.array([-0.15, 0.0, 0.05])
    cam.distance = 1.5
    cam.azimuth = 25.0
    cam.elevation = -32.0
    option = mujoco.MjvOption()
    option.geomgroup[:3] = 1
    # The offscreen framebuffer must hold the picture (the MJCF asks for 1920 x 1080).
    model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
    model.vis.global_.offheight = max(model.vis.global_.offheight, height)
    with mujoco.Renderer(model, height, width) as renderer:
        renderer.update_scene(data, cam, option)
        if path is not None:
            scn = renderer.scene
            g = scn.geoms[scn.ngeom]
            mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3),
                                np.eye(3).ravel(), np.array([0.1, 0.8, 0.1, 1.0], np.float32))
            mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, 0.006,
                                 np.asarray(path.points[0], float),
                                 np.asarray(path.points[1], float))
            scn.ngeom += 1
            for i, pose in enumerate(path.capsules):  # start translucent, end solid
                rgba = [0.1, 0.8, 0.1, 0.35 if i == 0 else 0.9]
                for centre, mat, size in zip(*pose, strict=True):
                    mujoco.mjv_initGeom(scn.geoms[scn.ngeom], mujoco.mjtGeom.mjGEOM_CAPSULE,
                                        np.array([size[0], size[1], 0.0]), centre,
                                        mat.ravel(), np.array(rgba, np.float32))
                    scn.ngeom += 1
        return renderer.render().copy()


def top_view_array(result, width: int, height: int, path=None) -> np.ndarray:
    import matplotlib.pyplot as plt

    from .plots import scene_top_view

    dpi = 100
    fig, ax = plt.subplots(figsize=(width / dpi, height / dpi), dpi=dpi)
    scene_top_view(result, ax=ax)
    if path is not None:
        (x0, y0, _), (x1, y1, _) = path.points
        ax.plot([x0, x1], [y0, y1], color="green", lw=2)
        for centres, mats, sizes in path.capsules:  # the capsules' axes, from above
            for c, m, (_, half) in zip(centres, mats, sizes, strict=True):
                a, b = c - half * m[:, 2], c + half * m[:, 2]
                ax.plot([a[0], b[0]], [a[1], b[1]], color="green", lw=1.5, alpha=0.8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    buf.seek(0)
    img = plt.imread(buf)[..., :3]
    out = np.ones((height, width, 3))
    h, w = min(height, img.shape[0]), min(width, img.shape[1])
    out[:h, :w] = img[:h, :w]
    return (out * 255).astype(np.uint8)


class RolloutPath(NamedTuple):
    points: np.ndarray  # (2, 3): start and end
    quats: np.ndarray  # (2, 4): the orientation there (w, x, y, z)
    capsules: list  # per pose: the gripper's centres (3, 3), matrices (3, 3, 3), sizes (3, 2)


def rollout_path(result, mode: str, start: int, task: int) -> RolloutPath:
    """One rollout of ``mode``: where it started and ended, and the gripper's capsules
    there (``collision.gripper_geoms``, sized by the scene's ``gripper.*`` settings)."""
    from shacc_jax.collision import gripper_geoms

    ev = evaluate_results([result], (mode,))
    n_starts = ev.baked.n_starts
    if not (0 <= start < n_starts and 0 <= task < len(result.spaces)):
        raise InputError("<--path>", "START TASK", f"need 0 <= START < {n_starts} and "
                         f"0 <= TASK < {len(result.spaces)}")
    b, ro = ev.baked, ev.evaluation.rollouts
    points = np.stack([b.starts[0, start, :3], ro.point[0, 0, start, task]]).astype(float)
    quats = np.stack([b.starts[0, start, 3:], ro.orientation[0, 0, start, task]]).astype(float)
    dims = np.array([b.gripper_finger_length[0], b.gripper_finger_radius[0],
                     b.gripper_opening[0], b.gripper_palm_radius[0]], np.float32)
    capsules = [tuple(np.asarray(a, float) for a in gripper_geoms(p, q, dims))
                for p, q in zip(points.astype(np.float32), quats.astype(np.float32),
                                strict=True)]
    return RolloutPath(points, quats, capsules)


def render_scene(result, out: Path, width: int = 1280, height: int = 560,
                 mode: str = "shacc", path_spec: tuple[int, int] | None = None) -> None:
    path = rollout_path(result, mode, *path_spec) if path_spec else None
    left = render_array(result, width // 2, height, SPACES_FOR_MODE[mode], path)
    right = top_view_array(result, width - width // 2, height, path)
    image = np.concatenate([left, right], axis=1)
    import matplotlib.image as mpimg

    buf = io.BytesIO()
    mpimg.imsave(buf, image, format="png")
    write_atomic(out, buf.getvalue())


def cmd_export(args) -> int:
    check_output_file(args.out, "OUT")
    r = load_and_precompute(args.scene, args.set)
    write_atomic(args.out, scene_to_mjcf(r).encode())
    print(f"wrote {args.out}")
    return 0


def cmd_render(args) -> int:
    check_output_file(args.out, "--out")
    r = load_and_precompute(args.scene, args.set)
    render_scene(r, Path(args.out), args.width, args.height, args.mode,
                 tuple(args.path) if args.path else None)
    print(f"wrote {args.out}")
    return 0
