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

from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from geometry_precompute import InputError
from geometry_precompute.mjcf import scene_to_mjcf
from geometry_precompute.schema import OUTCOMES
from shacc_jax.gripper import gripper_geoms
from sweeps.output import write_atomic
from sweeps.pipeline import evaluate_results

OPTIMIZED_RGBA = "0.58 0.40 0.74 0.35"  # the top view's purple
SPACES_FOR_MODE = {"baseline": "init", "shrinking": "both", "shacc": "both",
                   "optimized": "both", "blend": "init", "ho": "init", "shacc_ho": "both"}


def render_array(result, width: int, height: int, spaces: str = "both",
                 path: RolloutPath | None = None, optimized: bool = False) -> np.ndarray:
    """(height, width, 3) uint8 image of the scene from the front-left, above.
    ``optimized``: the result's second spaces are the optimized mode's (drawn in its
    colour, as the top view's legend says)."""
    import mujoco  # deferred: 495 ms to import

    model = mujoco.MjModel.from_xml_string(scene_to_mjcf(
        result, spaces=spaces, opt_rgba=OPTIMIZED_RGBA if optimized else None))
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


def top_view_array(result, width: int, height: int, **view) -> np.ndarray:
    """(height, width, 3) uint8: :func:`sweeps.analysis.plots.scene_top_view` of the result with
    ``view``'s options, the legend right of the axes."""
    import matplotlib.pyplot as plt  # deferred: 1.4 s to import

    from sweeps.analysis.plots import scene_top_view  # deferred: 2.7 s to import

    dpi = 100
    fig, ax = plt.subplots(figsize=(width / dpi, height / dpi), dpi=dpi)
    # Fixed margins before the labels are placed (a later layout would move them).
    fig.subplots_adjust(left=0.11, right=0.6, bottom=0.1, top=0.84)
    scene_top_view(result, ax=ax, **view)
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
    outcome: str = ""  # success, wrong, ambiguous, timeout or collision
    description: str = ""  # one line: start, task, mode, outcome, where it ended


def task_index(result, task: str) -> int:
    """A task given by its id or by its index in the scene."""
    ids = result.task_ids
    if task in ids:
        return ids.index(task)
    try:
        t = int(task)
    except ValueError:
        raise InputError("<--path>", "TASK", f"no task {task!r} in {result.scene.name}; its "
                         f"tasks: {', '.join(ids)} (or an index 0-{len(ids) - 1})") from None
    if not 0 <= t < len(ids):
        raise InputError("<--path>", "TASK", f"need an index in [0, {len(ids) - 1}] or a task "
                         f"id ({', '.join(ids)}), got {t}")
    return t


def rollout_path(ev, mode: str, start: int, task: str | int, s: int = 0) -> RolloutPath:
    """One rollout of ``mode`` from an evaluated batch ``ev``
    (:func:`sweeps.pipeline.evaluate_results`, ``mode`` among its modes): where it
    started and ended, its outcome, and the gripper's capsules there
    (``shacc_jax.gripper.gripper_geoms``, sized by the scene's ``gripper.*`` settings)."""


    result = ev.results[s]
    t = task_index(result, str(task))
    n_starts = ev.baked.n_starts
    if not 0 <= start < n_starts:
        raise InputError("<--path>", "START", f"need 0 <= START < {n_starts} (the scene's "
                         f"start poses), got {start}")
    m = ev.modes.index(mode)
    b, ro = ev.baked, ev.evaluation.rollouts
    points = np.stack([b.starts[s, start, :3], ro.point[s, m, start, t]]).astype(float)
    quats = np.stack([b.starts[s, start, 3:], ro.orientation[s, m, start, t]]).astype(float)
    dims = jnp.array([b.gripper_finger_length[s], b.gripper_finger_radius[s],
                      b.gripper_opening[s], b.gripper_palm_radius[s]], np.float32)
    capsules = [tuple(np.asarray(a, float) for a in gripper_geoms(p, q, dims))
                for p, q in zip(points.astype(np.float32), quats.astype(np.float32),
                                strict=True)]
    outcome = OUTCOMES[int(ro.outcome[s, m, start, t])]
    steps = int(ro.step[s, m, start, t])
    text = (f"start {start} -> task {result.task_ids[t]} ({mode}): {outcome} after {steps} "
            f"steps, ended at ({', '.join(f'{v:.3f}' for v in points[1])}) m")
    if outcome == "success":
        text += f", delta_R {float(ro.delta_R[s, m, start, t]):.3f} rad"
    a = int(ro.activated[s, m, start, t])
    if outcome in ("wrong", "ambiguous") and 0 <= a < len(result.task_ids):
        text += f", activated {result.task_ids[a]}"
    return RolloutPath(points, quats, capsules, outcome, text)


def optimized_shapes(ev, s: int = 0) -> list:
    """The optimized mode's spaces of scene ``s`` (its search's sizes, task order)."""
    r = ev.results[s]
    return [sp.shape(np.asarray(ev.search.q[s, t, :len(sp.param_names)], float))
            for t, sp in enumerate(r.spaces)]


def render_scene(result, out: Path, width: int = 1280, height: int = 560,
                 mode: str = "shacc", path_spec: tuple[int, str] | None = None
                 ) -> RolloutPath | None:
    """The 3-D picture (the spaces ``mode`` uses: initial for the baseline, initial and
    shrunk for shrinking and shacc, initial and optimized for optimized) beside the
    labelled top view; the title gives every mode's success rate. Returns the rollout
    drawn, if ``path_spec`` asked for one."""

    if path_spec:
        task_index(result, str(path_spec[1]))  # a bad task id is refused before any work
    modes = ("baseline", "shrinking", "shacc") + (("optimized",) if mode == "optimized"
                                                 else ())
    ev = evaluate_results([result], modes)
    success = {m: float(ev.evaluation.metrics.u_scene[0, i]) for i, m in enumerate(modes)}
    path = rollout_path(ev, mode, *path_spec) if path_spec else None
    opt = optimized_shapes(ev) if mode == "optimized" else None
    shown = replace(result, shapes_opt=opt) if opt is not None else result
    left = render_array(shown, width // 2, height, SPACES_FOR_MODE[mode], path,
                        optimized=opt is not None)
    rollout = None if path is None else (path.points[0], path.points[1], path.outcome,
                                         f"rollout: {path.outcome}")
    right = top_view_array(result, width - width // 2, height, optimized=opt,
                           rollout=rollout, success=success)
    image = np.concatenate([left, right], axis=1)
    import matplotlib.image as mpimg  # deferred: 980 ms to import

    buf = io.BytesIO()
    mpimg.imsave(buf, image, format="png")
    write_atomic(out, buf.getvalue())
    return path
