"""Gripper-object collisions through MJX's collision pipeline (SPEC sections 9, 12b).

The gripper is three capsules posed by the EE pose (p, R): two fingers parallel to
the approach axis (EE z), at EE y = +-opening/2, from the palm (z = -finger_length)
to the tool centre point p (z = 0), and a palm across them along EE y. Its
dimensions are per-scene settings (``gripper.*``), so a sweep varies them without
recompiling.

One small MJX model serves a whole batch: the world body holds ``O`` cylinder
slots and (when any scene has a box) ``O`` box slots, the gripper is a free body.
MJX's own pair filter (contype 1 on the gripper, conaffinity 1 on the objects)
keeps exactly the gripper-object pairs. Per query, the object slots get the
scene's poses and sizes (``Model.geom_size`` and ``Data.geom_xpos/xmat`` are
plain arrays, so they are vmapped like any other input), unused slots are parked
far below the table, and ``mjx.collision`` returns one signed distance per
contact. MJX has no box-cylinder pair and approximates capsule-cylinder by a few
gradient steps on the SDFs (its ``collision_sdf``), so the gripper is capsules
only and a penetration counts when the deepest contact is below
``-PENETRATION_EPS``; tests compare with CPU MuJoCo's ``mj_geomDistance``.

The table is not an obstacle: start poses a few centimetres above it in random
orientations would otherwise collide before moving (docs/DECISIONS.md).
"""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from geometry_precompute.schema import BOX, CYLINDER

from . import automaton as am
from . import quaternion as quat

PENETRATION_EPS = 1e-4  # m: deeper than rounding and MJX's SDF approximation at grazing
# Where unused object slots wait. A tuple, not a jax array: importing this module must not
# start a JAX backend (a process may import the package and never evaluate).
PARKED = (0.0, 0.0, -100.0)
N_GRIPPER = 3


def gripper_geoms(p: Float[Array, "3"], q: Float[Array, "4"],
                  dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """Centres (3, 3), rotation matrices (3, 3, 3) and MuJoCo capsule sizes (3, 2)
    [radius, half length] of the fingers and the palm. ``dims`` is
    [finger_length, finger_radius, opening, palm_radius]."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    R = quat.to_matrix(q)
    x, y, z = R[:, 0], R[:, 1], R[:, 2]
    centres = jnp.stack([p + 0.5 * opening * y - 0.5 * length * z,
                         p - 0.5 * opening * y - 0.5 * length * z,
                         p - length * z])
    palm = jnp.stack([x, -z, y], axis=1)  # local z along the EE's y axis
    mats = jnp.stack([R, R, palm])
    sizes = jnp.stack([jnp.stack([r_f, 0.5 * length]), jnp.stack([r_f, 0.5 * length]),
                       jnp.stack([r_p, 0.5 * opening])])
    return centres, mats, sizes


def gripper_reach(dims: Float[Array, "4"]) -> Array:
    """Radius of a sphere about p that contains the whole gripper."""
    length, r_f, opening, r_p = dims[0], dims[1], dims[2], dims[3]
    return jnp.sqrt(length ** 2 + (0.5 * opening) ** 2) + jnp.maximum(r_f, r_p)


def _mjcf(n_objects: int, boxes: bool) -> str:
    slots = [f'<geom name="cyl{i}" type="cylinder" size="0.05 0.05" pos="0 0 -100" '
             f'contype="0" conaffinity="1"/>' for i in range(n_objects)]
    if boxes:
        slots += [f'<geom name="box{i}" type="box" size="0.05 0.05 0.05" pos="0 0 -100" '
                  f'contype="0" conaffinity="1"/>' for i in range(n_objects)]
    capsule = 'type="capsule" size="0.01 0.02" contype="1" conaffinity="0"'
    return "\n".join([
        '<mujoco model="shacc_gripper_collisions">',
        "  <worldbody>", *(f"    {s}" for s in slots),
        '    <body name="gripper"><freejoint/>',
        f'      <geom name="finger_a" {capsule}/>', f'      <geom name="finger_b" {capsule}/>',
        f'      <geom name="palm" {capsule}/>',
        "    </body>", "  </worldbody>", "</mujoco>", ""])


@lru_cache(maxsize=16)
def collision_model(n_objects: int, boxes: bool):
    """(MjModel, mjx.Model, mjx.Data) with ``n_objects`` cylinder slots (and as many box
    slots if ``boxes``), cached per layout: the layout is static, sizes and poses are
    inputs."""
    import mujoco
    from mujoco import mjx

    mj = mujoco.MjModel.from_xml_string(_mjcf(n_objects, boxes))
    # Concrete arrays even when first called while tracing: the cache outlives the trace.
    with jax.ensure_compile_time_eval():
        m = mjx.put_model(mj)
        return mj, m, mjx.make_data(m)


def object_geoms(obj_kind, obj_center, obj_quat, obj_size, obj_mask, boxes: bool):
    """Slot poses and sizes for one scene's objects: (G, 3), (G, 3, 3), (G, 3)."""
    mats = jax.vmap(quat.to_matrix)(obj_quat)
    cyl = obj_mask & (obj_kind == CYLINDER)
    parked = jnp.asarray(PARKED, obj_center.dtype)
    pos = [jnp.where(cyl[:, None], obj_center, parked)]
    size = [obj_size]
    rot = [mats]
    if boxes:
        box = obj_mask & (obj_kind == BOX)
        pos.append(jnp.where(box[:, None], obj_center, parked))
        size.append(obj_size)
        rot.append(mats)
    return jnp.concatenate(pos), jnp.concatenate(rot), jnp.concatenate(size)


def deepest(model, data, objects, p: Float[Array, "3"], q: Float[Array, "4"],
            dims: Float[Array, "4"]) -> Array:
    """Smallest signed distance between the gripper at (p, q) and any object: MJX's
    ``collision`` on the batch model. ``objects`` is ``object_geoms``' output."""
    from mujoco import mjx

    o_pos, o_mat, o_size = objects
    g_pos, g_mat, g_size = gripper_geoms(p, q, dims)
    dtype = p.dtype
    g_size3 = jnp.concatenate([g_size, jnp.zeros((N_GRIPPER, 1), dtype)], axis=1)
    m = model.replace(geom_size=jnp.concatenate([o_size, g_size3]).astype(dtype))
    d = data.replace(geom_xpos=jnp.concatenate([o_pos, g_pos]).astype(dtype),
                     geom_xmat=jnp.concatenate([o_mat, g_mat]).astype(dtype))
    d = mjx.collision(m, d)
    return jnp.min(d._impl.contact.dist)


def penetrates(model, data, objects, p, q, dims) -> Bool[Array, ""]:
    return deepest(model, data, objects, p, q, dims) < -PENETRATION_EPS


def window_start(obj_kind, obj_center, obj_size, obj_mask, gripper: Float[Array, "4"],
                 path: am.Path, max_steps: Array) -> Array:
    """First sample at which the gripper's bounding sphere (about p) reaches an object's
    bounding sphere; inf if none. A penetration needs that, so the samples before it
    are skipped without loss. One scene's objects, one path."""
    size = obj_size
    r_obj = jnp.where(obj_kind == BOX, jnp.linalg.norm(size, axis=-1),
                      jnp.hypot(size[:, 0], size[:, 1]))
    reach = gripper_reach(gripper) + r_obj + 1e-3
    rel = obj_center - path.p0
    b = rel @ path.u
    disc = b * b - (jnp.sum(rel * rel, axis=-1) - reach * reach)
    root = jnp.sqrt(jnp.maximum(disc, 0.0))
    inf = jnp.asarray(jnp.inf, b.dtype)
    ok = obj_mask & (disc >= 0)
    lo, hi = jnp.where(ok, b - root, inf), jnp.where(ok, b + root, -inf)
    return jnp.min(am.first_sample(lo, hi, jnp.zeros((), b.dtype), path, max_steps))
