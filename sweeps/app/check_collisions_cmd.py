"""``shacc check-collisions``: the gripper collision check of a scene against CPU MuJoCo,
with MJX's collision pipeline beside it, on random gripper poses near the scene's
objects (docs/reference/mujoco.md).

A researcher who brings meshes of their own can see on their own scene that the check
decides every penetration as MuJoCo does, and what MJX's pipeline would have decided
instead (the reason the check does not use it). The three see the same geoms: the
scene's exported MJCF (a mesh object as its solid, which MuJoCo and MJX take as its
convex hull) and the gripper's three capsules, posed as
``shacc_jax.gripper.gripper_geoms`` poses them.

- **shacc**: ``shacc_jax.collision.deepest``, every pair measured exactly.
- **MuJoCo** (the reference): ``mj_geomDistance`` of every (object, capsule) pair whose
  bounding spheres come within 1 cm.
- **MJX**: ``mujoco.mjx.collision`` on the same model, vmapped over the poses; a pair
  penetrates where its deepest contact is deeper than the threshold.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import warnings
from typing import Any

import numpy as np

from geometry_precompute.errors import InputError

DEEP = 1e-3  # m: a missed penetration deeper than this is reported apart


def _models(mjcf: str, dims: np.ndarray):
    """The scene's objects and the gripper's capsules as one MuJoCo model (the table and
    the spaces take no part), and the geoms of each."""
    import mujoco  # deferred: 304 ms to import

    spec = mujoco.MjSpec.from_string(mjcf)
    hand = spec.worldbody.add_body(name="gripper", mocap=True)
    length, r_f, opening, r_p = (float(v) for v in dims)
    for radius, half in ((r_f, length / 2), (r_f, length / 2), (r_p, opening / 2)):
        hand.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[radius, half, 0])
    model = spec.compile()
    objects = [g for g in range(model.ngeom) if model.geom(g).name.startswith("object:")]
    capsules = list(range(model.ngeom - 3, model.ngeom))
    for g in range(model.ngeom):
        if g not in objects and g not in capsules:
            model.geom_contype[g] = model.geom_conaffinity[g] = 0
    return model, np.array(objects), np.array(capsules)


def check(result, poses: int = 2000, seed: int = 0, spread: float = 0.06) -> dict[str, Any]:
    """The comparison on one precomputed scene (its ``collision`` setting is taken as on).

    :param result: a :class:`~geometry_precompute.PrecomputeResult`.
    :param poses: gripper poses, positions normal about random objects' centres with
        standard deviation ``spread`` (m), orientations uniform.
    :param seed: their seed.
    :returns: ``{"poses", "penetrating", "shacc": {...}, "mjx": {...}}``, each method's
        agreement with MuJoCo (share of poses decided alike), penetrations missed (and
        how many of them deeper than 1 mm), penetrations invented, and (shacc) the
        largest distance error where MuJoCo finds the gripper clear by under 1 cm.

    Example::

        >>> from geometry_precompute import load_scene, precompute, shipped_scene_paths
        >>> r = precompute(load_scene(shipped_scene_paths()[2]))
        >>> out = check(r, poses=50)
        >>> out["shacc"]["missed"], out["shacc"]["invented"]
        (0, 0)
    """
    import jax  # deferred: 1.4 s to import
    import jax.numpy as jnp  # deferred: 1.6 s to import
    import mujoco  # deferred: 304 ms to import
    from scipy.spatial.transform import Rotation  # deferred: 753 ms to import

    with contextlib.redirect_stdout(io.StringIO()):  # it prints that MuJoCo Warp is absent
        from mujoco import mjx  # deferred: 304 ms to import

    import shacc_jax.collision as col  # deferred: 1.2 s to import
    from geometry_precompute import bake  # deferred: 142 ms to import
    from geometry_precompute.mjcf import scene_to_mjcf  # deferred: 127 ms to import
    from shacc_jax.gripper import gripper_geoms  # deferred: 1.2 s to import
    from shacc_jax.hulls import Hulls  # deferred: 1.5 s to import
    from shacc_jax.types import Geometry, Params  # deferred: 1.8 s to import

    if not result.scene.objects:
        raise InputError(result.scene.source, "objects", "the scene has no object to check")
    r = dataclasses.replace(result, settings=result.settings.with_overrides({"collision": "on"}))
    baked = bake([r])
    g = Geometry.from_bake(baked)
    dims = np.asarray(Params.from_bake(baked).gripper()[0])
    model, objects, capsules = _models(scene_to_mjcf(r, spaces="none"), dims)
    rng = np.random.default_rng(seed)
    real = np.flatnonzero(baked.obj_mask[0])
    P = baked.obj_center[0, rng.choice(real, poses)] + rng.normal(scale=spread, size=(poses, 3))
    Q = np.roll(Rotation.random(poses, random_state=rng).as_quat(), 1, axis=1)
    P32, Q32 = jnp.asarray(P, jnp.float32), jnp.asarray(Q, jnp.float32)
    scene_objects = col.scene_objects(g.obj_kind[0], g.obj_center[0], g.obj_quat[0],
                                      g.obj_size[0], g.obj_mask[0])
    hulls = Hulls.of(g)
    grip = jnp.asarray(dims, jnp.float32)
    ours = np.asarray(jax.jit(jax.vmap(lambda p, q: col.deepest(
        scene_objects, p, q, grip, hulls, 0, jnp.inf)))(P32, Q32))
    geoms = jax.vmap(gripper_geoms, (0, 0, None))(P32, Q32, grip)
    centres, mats = np.asarray(geoms[0], float), np.asarray(geoms[1], float)

    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    xpos, rbound = data.geom_xpos, model.geom_rbound
    want = np.empty(poses)
    for i in range(poses):
        for k, c in enumerate(capsules):
            xpos[c] = centres[i, k]
            data.geom_xmat[c] = mats[i, k].ravel()
        apart = np.linalg.norm(xpos[objects, None] - xpos[None, capsules], axis=-1)
        near = np.argwhere(apart < rbound[objects, None] + rbound[None, capsules] + 0.01)
        want[i] = min((mujoco.mj_geomDistance(model, data, objects[o], capsules[k], 1.0, None)
                       for o, k in near), default=1.0)

    with warnings.catch_warnings():  # MJX's advice on large coplanar faces
        warnings.simplefilter("ignore", UserWarning)
        mx = mjx.put_model(model)
    # The objects where MuJoCo placed them (MJX's kinematics needs a degree of freedom).
    base = mjx.make_data(mx).replace(
        geom_xpos=jnp.asarray(data.geom_xpos, jnp.float32),
        geom_xmat=jnp.asarray(data.geom_xmat.reshape(-1, 3, 3), jnp.float32))
    cap = jnp.asarray(capsules)

    def mjx_deepest(c, m):
        d = base.replace(geom_xpos=base.geom_xpos.at[cap].set(c),
                         geom_xmat=base.geom_xmat.at[cap].set(m))
        dist = mjx.collision(mx, d)._impl.contact.dist  # one per (pair, contact) slot
        return jnp.min(jnp.where(jnp.isfinite(dist), dist, 1.0), initial=1.0)

    # MJX is written for JAX's standard promotion rules (a strict test configuration
    # would refuse its mixed dtypes).
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        theirs = np.asarray(jax.jit(jax.vmap(mjx_deepest))(
            jnp.asarray(centres, jnp.float32), jnp.asarray(mats, jnp.float32)))
    pen = want < -col.PENETRATION_EPS
    close = (want > 0) & (want < 0.01)

    def versus(got) -> dict[str, Any]:
        mine = got < -col.PENETRATION_EPS
        return {"agreement": float((mine == pen).mean()),
                "missed": int((pen & ~mine).sum()),
                "missed_deeper_than_1mm": int((pen & ~mine & (want < -DEEP)).sum()),
                "invented": int((mine & ~pen).sum())}

    out = {"scene": r.scene.name, "poses": poses, "penetrating": int(pen.sum()),
           "shacc": versus(ours), "mjx": versus(theirs)}
    out["shacc"]["max_distance_error_within_1cm"] = \
        float(np.abs(ours[close] - want[close]).max()) if close.any() else None
    return out


def cmd_check_collisions(args) -> int:
    from sweeps.app.inputs import load_and_precompute  # deferred: 106 ms to import

    out = check(load_and_precompute(args.scene, args.set), args.poses, args.seed)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{out['scene']}: {out['poses']} gripper poses near its objects, "
          f"{out['penetrating']} penetrating by CPU MuJoCo (mj_geomDistance)")
    print(f"{'':8}{'agree':>9}{'missed':>8}{'> 1 mm':>8}{'invented':>10}")
    for who in ("shacc", "mjx"):
        v = out[who]
        print(f"{who:8}{100 * v['agreement']:8.2f}%{v['missed']:8d}"
              f"{v['missed_deeper_than_1mm']:8d}{v['invented']:10d}")
    err = out["shacc"]["max_distance_error_within_1cm"]
    if err is not None:
        print(f"shacc's largest distance error where the gripper is clear by under 1 cm: "
              f"{err:.2e} m")
    return 0
