"""Gripper-object collisions (reference/model, mujoco), exact, on the accelerator: does
the gripper penetrate an object, and at which sample first?

The gripper is three capsules posed by the EE pose (``gripper``); the objects are the
scene's cylinders, boxes and meshes, posed and sized as in the exported MJCF. A
capsule penetrates a convex body by more than eps exactly when its axis segment comes
within (radius - eps) of the body, so the check is a segment-to-solid distance
(``body_distance`` for primitives, ``hulls`` for meshes' convex hulls). This replaced
MJX's collision pipeline, whose capsule-cylinder routine (a few gradient steps on the
SDFs) reported distances up to 8 mm too large near contact and cost 250-1 100x a
rollout (benchmarks/RESULTS.md). CPU
MuJoCo's ``mj_geomDistance`` on the same geoms is the reference in the tests.

Most of the work is skipped without changing an outcome: ``path_cull.path_window`` keeps
only the samples of a rollout at which the gripper can reach an object (closed form),
and :func:`first_penetration` runs the search only on the (pose, capsule, object)
pairs that a closed-form ``body_distance.lower_bound`` does not clear.

The table is not an obstacle: start poses a few centimetres above it in random
orientations would otherwise collide before moving (docs/DECISIONS.md).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute.schema import MESH

from . import quaternion as quat
from .body_distance import (
    in_frame_xyz,
    into_frames,
    lower_bound_xyz,
    point_distance,
    segment_distance,
)
from .gripper import capsule_axes, capsule_segments
from .hulls import Hulls, hull_clips, hull_distance

PENETRATION_EPS = 1e-4  # m: a penetration deeper than this is a collision


def scene_objects(obj_kind, obj_center, obj_quat, obj_size, obj_mask):
    """One scene's objects for :func:`deepest`: kinds (O,), centres (O, 3), rotation
    matrices (O, 3, 3), sizes (O, 3) (a cylinder's [radius, half height, -], a box's
    half extents) and the mask (O,)."""
    return obj_kind, obj_center, jax.vmap(quat.to_matrix)(obj_quat), obj_size, obj_mask


def pair_axes(objects, p: Float[Array, "3"], q: Float[Array, "4"],
              dims: Float[Array, "4"]) -> tuple[Array, Array, Array]:
    """The gripper's capsule axes at the EE pose (p, q) in each object's frame: starts
    (3, O, 3) and extents (3, O, 3), as segments a + t d, t in [0, 1]; and the
    capsules' radii (3,). ``objects``: :func:`scene_objects`' output."""
    _, centre, mat, _, _ = objects
    starts, extents, radii = capsule_segments(p, q, dims)
    a_loc = into_frames(mat[None], starts[:, None, :] - centre[None, :, :])
    d_loc = into_frames(mat[None], extents[:, None, :])
    return a_loc, d_loc, radii


def deepest(objects, p: Float[Array, "3"], q: Float[Array, "4"], dims: Float[Array, "4"],
            hulls: Hulls | None = None, scene=None, cutoff: float | None = None) -> Array:
    """Smallest (capsule axis to object distance - capsule radius) over the gripper's
    capsules and the scene's objects (``scene_objects``' output), at the EE pose (p, q).
    Where a capsule and an object are apart this is their distance, as CPU MuJoCo's
    ``mj_geomDistance`` reports it; where they overlap it is at most minus the depth
    of the overlap's smallest separating move short of the capsule radius, and it is
    below -eps exactly when MuJoCo's penetration depth exceeds eps (a capsule overlaps
    a convex body by more than eps iff its axis comes within radius - eps of it).

    A mesh object (``hulls``, the batch's, and ``scene``, this scene's index in it) is
    its convex hull. Its bounding cylinder's distance bounds the hull's from below, and
    only pairs whose bound lies below ``cutoff`` can count: with a ``cutoff`` given,
    each is measured exactly (:func:`hull_distance`), one pair per round of a loop that
    ends when no pair is left. Without one (the penetration decision, -eps), a first
    loop clips each such pair by the hull's planes (:func:`hull_clips`): a pair that
    meets the hull counts with -radius, one that misses the planes moved out by
    radius - eps with -eps (it cannot penetrate), and only the pairs left open are
    measured, in a second loop."""
    kind, _, _, size, mask = objects
    a_loc, d_loc, radius = pair_axes(objects, p, q, dims)
    dist = segment_distance(a_loc, d_loc, kind[None, :], size[None, :, :])
    gap = dist - radius[:, None]
    if hulls is not None:
        todo = ((kind == MESH) & mask)[None, :] & (
            gap < (-PENETRATION_EPS if cutoff is None else cutoff))
        if cutoff is None:
            gap, todo = _pair_loop(todo, gap, lambda c, o, g: _clipped(
                hulls.plane[scene, o], a_loc[c, o], d_loc[c, o], radius[c], g))
        gap = _pair_loop(todo, gap, lambda c, o, g: (hull_distance(
            hulls.tri[scene, o], hulls.plane[scene, o], a_loc[c, o], d_loc[c, o])
            - radius[c], False))[0]
    return jnp.min(jnp.where(mask[None, :], gap, jnp.inf))


def _clipped(plane, a, d, radius, gap):
    """A mesh pair's gap as the hull's planes settle it, and whether they leave it open
    (:func:`deepest`)."""
    meets, near = hull_clips(plane, a, d, radius - PENETRATION_EPS)
    return (jnp.where(meets, -radius, jnp.where(near, gap, -PENETRATION_EPS)),
            near & ~meets)


def _pair_loop(todo: Bool[Array, "C O"], gap: Float[Array, "C O"], measure):
    """``measure(c, o, gap) -> (gap, open)`` of each pair ``todo`` marks, one pair per
    round of a while loop (vmapped, it runs as many rounds as the lane with most pairs
    needs); the gaps, and the pairs left open."""
    O = gap.shape[1]
    order = jnp.argsort(~todo.reshape(-1), stable=True)
    count = jnp.sum(todo)

    def body(state):
        i, out, still = state
        c, o = order[i] // O, order[i] % O
        value, left = measure(c, o, out[c, o])
        return i + 1, out.at[c, o].set(value), still.at[c, o].set(left)

    _, gap, still = jax.lax.while_loop(lambda state: state[0] < count, body,
                                       (jnp.zeros((), count.dtype), gap,
                                        jnp.zeros_like(todo)))
    return gap, still


# Objects a rollout is checked against when it can touch no more than these (most can
# touch one to three); rollouts that can touch more are checked against all.
OBJECT_SLOTS = 4


# Share of the (sample, capsule, object) pairs a round of the exact search takes (on
# random 10-task scenes 1.6 % of the pairs pass the lower bound).
ROUND_SHARE = 32


def first_penetration(objects, p: Float[Array, "B W 3"], q: Float[Array, "B W 4"],
                      dims: Float[Array, "B 4"], live: Bool[Array, "B W"],
                      hulls: Hulls | None = None, ids=None) -> Int[Array, " B"]:
    """The first of W poses of each of B lanes at which the gripper penetrates an object
    by more than eps (W for none), as :func:`penetrates` decides pose by pose, among the
    poses where ``live`` (``objects``: each lane's scene, :func:`scene_objects`' output
    with a leading B axis; ``hulls`` and ``ids``, the lanes' scenes (B,) and objects'
    indices (B, O) in them, where some object is a mesh).

    Per (pose, capsule, object) pair, in one fused pass: the closed-form
    :func:`lower_bound` clears most pairs, and an upper bound (the distance of the axis'
    ends and middle to the object) settles the pairs that surely penetrate (not for a
    mesh, whose bound is its bounding cylinder's). Only the pairs between the two, at
    poses before the lane's first sure penetration, are searched exactly: numbered (a
    running count over the poses, then over each pose's pairs), gathered into rounds of
    1/ROUND_SHARE of all pairs, as many rounds as they need; a mesh's pairs get rounds
    of their own: first a clip by the hull's planes (:func:`hull_clips`), then
    :func:`hull_distance` for the pairs the planes leave open. (Looking each round's
    pairs up by a binary search of the running count instead of scattering them was
    slower on an H100: benchmarks/RESULTS.md.)"""
    kind, centre, mat, size, mask = objects
    B, W = live.shape
    O = kind.shape[1]
    # Poses (B, W, 1) against objects (B, 1, O), component by component: one fused kernel
    # from the poses to the flags, no (..., 3) intermediate written to memory.
    pose_axes = capsule_axes(p[:, :, None, :], q[:, :, None, :], dims[:, None, None, :])
    o_centre = tuple(centre[:, None, :, i] for i in range(3))
    o_mat, o_kind = mat[:, None], kind[:, None, :]
    o_size = tuple(size[:, None, :, i] for i in range(3))
    near = live[:, :, None] & mask[:, None, :]
    solid = o_kind != MESH  # the bounds are a mesh's bounding cylinder's
    maybe, sure = [], jnp.zeros((B, W), bool)
    for start, extent, radius in pose_axes:
        a = in_frame_xyz(o_mat, tuple(s - c for s, c in zip(start, o_centre, strict=True)))
        d = in_frame_xyz(o_mat, extent)
        thr = radius - PENETRATION_EPS
        # 1e-6 m of slack: the bound's rounding must not clear a pair the search finds.
        maybe.append(near & (lower_bound_xyz(a, d, o_kind, o_size) < thr + 1e-6))
        upper = point_distance(a, o_kind, o_size)
        for t in (0.5, 1.0):
            upper = jnp.minimum(upper, point_distance(
                tuple(ai + t * di for ai, di in zip(a, d, strict=True)), o_kind, o_size))
        sure = sure | jnp.any(near & solid & (upper < thr), axis=2)
    first_sure = jnp.where(jnp.any(sure, axis=1), jnp.argmax(sure, axis=1), W)
    # Only poses before the lane's first sure penetration can decide its first one.
    before_sure = jnp.arange(W)[None, :] < first_sure[:, None]
    flags = [f & before_sure[:, :, None] for f in maybe]
    flat_p, flat_q = p.reshape(B * W, 3), q.reshape(B * W, 4)

    def pair_axis(i):
        """Pair i's pose, capsule and object, and the capsule's axis in its frame."""
        pose, pair = i // (3 * O), i % (3 * O)
        lane, c, o = pose // W, pair // O, pair % O
        o_centre, o_mat = centre[lane, o], mat[lane, o]
        starts, extents, radii = capsule_segments(flat_p[pose], flat_q[pose], dims[lane])
        return (pose, lane, o, into_frames(o_mat, starts[c] - o_centre),
                into_frames(o_mat, extents[c]), radii[c])

    def solid_pair(i):
        pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
        dist = segment_distance(a_loc, d_loc, kind[lane, o], size[lane, o])
        return pose, dist < radius - PENETRATION_EPS

    def pairs(fs):  # (B W, 3 O): per pose, the pairs capsule by capsule
        return jnp.concatenate([f.reshape(B * W, O) for f in fs], axis=1)

    hit = _searched(pairs(flags if hulls is None else [f & solid for f in flags]),
                    solid_pair, B * W)[0]
    if hulls is not None:
        scene, obj = ids

        def mesh_clip(i):
            """The hull's planes settle most pairs: met (a penetration) or missed with
            the margin (none); the rest are left open."""
            pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
            meets, near = hull_clips(hulls.plane[scene[lane], obj[lane, o]], a_loc, d_loc,
                                     radius - PENETRATION_EPS)
            return pose, meets, near & ~meets

        def mesh_pair(i):
            pose, lane, o, a_loc, d_loc, radius = pair_axis(i)
            s, k = scene[lane], obj[lane, o]
            dist = hull_distance(hulls.tri[s, k], hulls.plane[s, k], a_loc, d_loc)
            return pose, dist < radius - PENETRATION_EPS

        met, open_pairs = _searched(pairs([f & ~solid for f in flags]), mesh_clip, B * W,
                                    leave_open=True)
        assert open_pairs is not None
        hit = hit | met | _searched(open_pairs, mesh_pair, B * W)[0]
    hit = hit.reshape(B, W) & before_sure
    return jnp.where(jnp.any(hit, axis=1), jnp.argmax(hit, axis=1), first_sure)


def _searched(candidate: Bool[Array, "n P"], one_pair, n_poses: int,
              leave_open: bool = False) -> tuple[Array, Array | None]:
    """Which of n_poses poses have a pair that ``one_pair`` finds penetrating, among the
    pairs ``candidate`` marks (per pose, its P pairs): numbered by a running count over
    the poses and each pose's pairs, and gathered into rounds of K pairs. With
    ``leave_open``, ``one_pair`` also says which pairs it left undecided, and they come
    back marked the same way (for a round of another ``one_pair``)."""
    P = candidate.shape[1]
    # The running count within each pose, written out over its pairs (no scan).
    within, total = [], jnp.zeros(n_poses, jnp.int32)
    for k in range(P):
        total = total + candidate[:, k].astype(jnp.int32)
        within.append(total)
    count = total
    before = jnp.cumsum(count) - count
    rank = (before[:, None] + jnp.stack(within, axis=1) - 1).reshape(-1)
    flat = candidate.reshape(-1)
    n = flat.shape[0]
    K = max(1, -(-n // ROUND_SHARE))
    rounds = (before[-1] + count[-1] + K - 1) // K

    def one_round(j, state):
        hit, still = state
        slot = rank - j * K
        take = flat & (slot >= 0) & (slot < K)
        idx = jnp.full(K, n, jnp.int32).at[jnp.where(take, slot, K)].set(
            jnp.arange(n, dtype=jnp.int32), mode="drop")
        out = jax.vmap(one_pair)(jnp.minimum(idx, n - 1))
        hit = hit.at[jnp.where(idx < n, out[0], n_poses)].max(out[1], mode="drop")
        if leave_open:
            still = still.at[idx].set(out[2], mode="drop")
        return hit, still

    still = jnp.zeros(n if leave_open else 0, bool)
    hit, still = jax.lax.fori_loop(0, rounds, one_round, (jnp.zeros(n_poses, bool), still))
    return hit, still.reshape(n_poses, P) if leave_open else None


class LaneObjects(NamedTuple):
    """What the lane pass's collision step reads (:func:`lane_objects`): every scene's
    objects (:func:`scene_objects`, leading axis S), the gripper's sizes (S, 4), each
    lane's touchable objects first, in object order and padded to whole groups of
    ``per_group`` (L, G per_group), how many each lane can touch (L,), and the mesh
    objects' hulls (None without any)."""

    objects: tuple
    gripper: Float[Array, "S 4"]
    order: Int[Array, "L GJ"]
    n_touch: Int[Array, " L"]
    per_group: int
    hulls: Hulls | None = None

    @property
    def groups(self) -> int:
        """G: how many groups of ``per_group`` objects a lane's objects form."""
        return self.order.shape[1] // self.per_group


def lane_objects(geometry, params, touch: Bool[Array, "L O"]) -> LaneObjects:
    """:class:`LaneObjects` of a batch whose lanes can touch the objects ``touch``
    (each lane's collision window, :func:`path_window`), with the batch's mesh hulls
    where it has any. Most lanes can touch at most
    OBJECT_SLOTS objects and are checked once; a lane that can touch more is checked
    once per group of them, and the group that collides first decides."""
    L, O = touch.shape
    J = min(O, OBJECT_SLOTS)
    G = -(-O // J)
    objects = jax.vmap(lambda g: scene_objects(
        g.obj_kind, g.obj_center, g.obj_quat, g.obj_size, g.obj_mask))(geometry)
    order = jnp.argsort(~touch, axis=1, stable=True)
    order = jnp.concatenate([order, jnp.zeros((L, G * J - O), order.dtype)], axis=1)
    return LaneObjects(objects, params.gripper(), order, jnp.sum(touch, axis=1), J,
                       Hulls.of(geometry))


def block_first_penetration(lane_obj: LaneObjects, scene: Int[Array, " B"],
                            idx: Int[Array, " B"], group, p: Float[Array, "B W 3"],
                            q: Float[Array, "B W 4"], valid: Bool[Array, "B W"]
                            ) -> Int[Array, " B"]:
    """:func:`first_penetration` of a block of lanes ``idx`` (their scenes ``scene``)
    against their touchable objects of group ``group``; objects a lane cannot touch
    in its window are left out exactly. (B,): the first sample of the block at which
    the gripper penetrates one (W for none)."""
    kind, centre, mat, size, mask = lane_obj.objects
    J = lane_obj.per_group
    take = jax.lax.dynamic_slice_in_dim(lane_obj.order[idx], group * J, J, axis=1)
    rank = group * J + jnp.arange(J)
    picked = [x[scene[:, None], take] for x in (kind, centre, mat, size)]
    reachable = mask[scene[:, None], take] & (rank[None, :] < lane_obj.n_touch[idx][:, None])
    return first_penetration((*picked, reachable), p, q, lane_obj.gripper[scene], valid,
                             lane_obj.hulls, (scene, take))


def penetrates(objects, p, q, dims, hulls: Hulls | None = None, scene=None) -> Bool[Array, ""]:
    """Whether the gripper at (p, q) penetrates an object by more than eps
    (:func:`deepest`)."""
    return deepest(objects, p, q, dims, hulls, scene) < -PENETRATION_EPS
