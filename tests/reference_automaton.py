"""A plain NumPy Automaton: the reference's step rule (reference/model), written as literally as
possible, in float64, with scipy for every rotation. It shares no code with
``shacc_jax``; the tests compare the two rollout by rollout.

Obvious over fast: one rollout at a time, one step at a time, every SDF
recomputed every step.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from geometry_precompute.frames import frame_from_approach
from geometry_precompute.schema import KINDS, MESH, POINT_TO_AXIS

OUTCOME_NAMES = ("success", "wrong", "ambiguous", "timeout", "collision")
PENETRATION = 1e-4  # m: deeper than this counts as a collision (as in shacc_jax.collision)


TIE = 1e-6  # sdf values within a micrometre are a tie (lower task index wins)


def _rot(q):  # (w, x, y, z) -> scipy Rotation
    q = np.asarray(q, float)
    return Rotation.from_quat([q[1], q[2], q[3], q[0]])


# --- shapes: closest point (solid) and signed distance, the obvious way -------------
# Scalar Python maths on purpose: it is the reference, and for single points it is
# several times faster than small NumPy arrays.


def _closest_on_segment(px, pz, ax, az, bx, bz):
    abx, abz = bx - ax, bz - az
    t = ((px - ax) * abx + (pz - az) * abz) / (abx * abx + abz * abz)
    t = min(1.0, max(0.0, t))
    return ax + t * abx, az + t * abz


def local_sdf_project(kind, dims, x, y, z):
    """Signed distance and closest point (x, y, z) in the shape's local frame."""
    a, b, c = dims
    rho = math.hypot(x, y)

    def from_meridian(r_new, z_new):
        if rho == 0.0:
            return (r_new, 0.0, z_new)
        return (x / rho * r_new, y / rho * r_new, z_new)

    if kind in (0, 1):  # cylinder / disk: the meridian rectangle [0, r] x [-h/2, h/2]
        if rho <= a and abs(z) <= b / 2:
            return -min(a - rho, b / 2 - abs(z)), (x, y, z)
        q = from_meridian(min(rho, a), min(b / 2, max(-b / 2, z)))
        return math.dist((x, y, z), q), q
    if kind == 2:  # cone: meridian triangle apex (0,0), rim (R, L), base centre (0, L)
        length, alpha = a, b
        radius = length * math.tan(alpha)
        lat = _closest_on_segment(rho, z, 0.0, 0.0, radius, length)
        base = _closest_on_segment(rho, z, 0.0, length, radius, length)
        d_lat = math.hypot(rho - lat[0], z - lat[1])
        d_base = math.hypot(rho - base[0], z - base[1])
        if 0.0 <= z <= length and rho <= z * math.tan(alpha):
            return -min(d_lat, d_base), (x, y, z)
        near = lat if d_lat <= d_base else base
        return min(d_lat, d_base), from_meridian(*near)
    q = (min(a, max(-a, x)), min(b, max(-b, y)), min(c, max(-c, z)))  # box
    if abs(x) <= a and abs(y) <= b and abs(z) <= c:
        return -min(a - abs(x), b - abs(y), c - abs(z)), (x, y, z)
    return math.dist((x, y, z), q), q


class Space:
    """A task space at its pose; points in and out as NumPy arrays, the maths on Python
    floats (the comment above: R^T (p - c) into the local frame, R q + c back)."""

    def __init__(self, kind, center, quat, dims):
        self.kind = int(kind)
        self.center = tuple(float(v) for v in center)
        self.rot = tuple(tuple(float(v) for v in row) for row in _rot(quat).as_matrix())
        self.dims = tuple(float(v) for v in dims)

    def _local(self, p):
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = self.rot
        (px, py, pz), (cx, cy, cz) = np.asarray(p, float).tolist(), self.center
        dx, dy, dz = px - cx, py - cy, pz - cz
        return (r00 * dx + r10 * dy + r20 * dz, r01 * dx + r11 * dy + r21 * dz,
                r02 * dx + r12 * dy + r22 * dz)

    def sdf(self, p):
        return local_sdf_project(self.kind, self.dims, *self._local(p))[0]

    def project(self, p):
        x, y, z = local_sdf_project(self.kind, self.dims, *self._local(p))[1]
        return np.array([r0 * x + r1 * y + r2 * z + c
                         for (r0, r1, r2), c in zip(self.rot, self.center, strict=True)])


# --- orientation -----------------------------------------------------------------------


def _wxyz(r: Rotation) -> np.ndarray:
    return np.roll(r.as_quat(), 1)


def task_rotation(orient_kind, orient_quat, axis, p) -> Rotation:
    if orient_kind == POINT_TO_AXIS:
        v = np.array([axis[0] - p[0], axis[1] - p[1], 0.0])
        if np.hypot(v[0], v[1]) > 1e-9:
            return Rotation.from_matrix(frame_from_approach(v), assume_valid=True)
    return _rot(orient_quat)


def task_rotations(orients, p) -> Rotation:
    """``task_rotation`` of each (orient_kind, orient_quat, axis) at p, as one Rotation.
    Where every task points to its axis (mugs), the frames are converted in one call,
    which gives the same quaternions as one call each (checked on 3 000 random sets)
    in a quarter of the time. The frames are orthonormal as built, so scipy is told
    so (``assume_valid``: no check for a matrix to orthogonalise; the same quaternions
    on 20 000 random sets, in an eighth of the time)."""
    approach = [np.array([a[0] - p[0], a[1] - p[1], 0.0]) for _, _, a in orients]
    if all(k == POINT_TO_AXIS for k, _, _ in orients) and \
            all(np.hypot(v[0], v[1]) > 1e-9 for v in approach):
        return Rotation.from_matrix(np.stack([frame_from_approach(v) for v in approach]),
                                    assume_valid=True)
    return Rotation.concatenate([task_rotation(*o, p) for o in orients])


def rotate_towards(r: Rotation, target: Rotation, max_angle: float) -> Rotation:
    rel = r.inv() * target  # in the EE frame
    rotvec = rel.as_rotvec()
    angle = np.linalg.norm(rotvec)
    if angle <= max_angle:
        return target
    axis = rotvec / angle
    if abs(angle - np.pi) < 1e-9:  # opposite: turn positively about EE x (then y, z)
        for k in range(3):
            if axis[k] != 0:
                axis = axis * np.sign(axis[k])
                break
    return r * Rotation.from_rotvec(axis * max_angle)


def angle_between(r1: Rotation, r2: Rotation) -> float:
    q1, q2 = r1.as_quat(), r2.as_quat()
    return 2.0 * np.arccos(min(1.0, abs(float(np.dot(q1, q2)))))


# --- collisions: the gripper's capsules against the objects, with CPU MuJoCo ---------


class Collider:
    """CPU MuJoCo (``mj_geomDistance``) on a model of one scene's real objects and the
    three gripper capsules, posed directly (no kinematics). The objects come from the
    baked arrays (a mesh object as a MuJoCo mesh of its baked hull's corners, which
    MuJoCo hulls again), or with ``mjcf`` from the scene's exported MJCF (its geoms
    named ``object:*``, meshes as the scene's own); the capsules are added to either
    model with MjSpec. MuJoCo collides with a mesh's convex hull."""

    def __init__(self, baked, scene: int, mjcf: str | None = None):
        import mujoco

        s = scene
        self.length = float(baked.gripper_finger_length[s])
        self.opening = float(baked.gripper_opening[s])
        r_f, r_p = float(baked.gripper_finger_radius[s]), float(baked.gripper_palm_radius[s])
        if mjcf is None:
            geoms, assets = [], []
            fmt = lambda v: " ".join(repr(float(x)) for x in np.ravel(v))  # noqa: E731
            for o in np.flatnonzero(baked.obj_mask[s]):
                pose = f'pos="{fmt(baked.obj_center[s, o])}" quat="{fmt(baked.obj_quat[s, o])}"'
                if baked.obj_kind[s, o] == MESH:
                    corners = np.unique(baked.obj_hull[s, o].reshape(-1, 3), axis=0)
                    assets.append(f'<mesh name="hull:{o}" vertex="{fmt(corners)}"/>')
                    geoms.append(f'<geom name="object:{o}" type="mesh" mesh="hull:{o}" {pose}/>')
                    continue
                kind = KINDS[baked.obj_kind[s, o]]
                size = baked.obj_size[s, o] if kind == "box" else baked.obj_size[s, o][:2]
                geoms.append(f'<geom name="object:{o}" type="{kind}" size="{fmt(size)}" {pose}/>')
            mjcf = (f'<mujoco><asset>{"".join(assets)}</asset>'
                    f'<worldbody>{"".join(geoms)}</worldbody></mujoco>')
        self.mujoco = mujoco
        self.model = _model(mjcf, r_f, r_p, self.length, self.opening)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_kinematics(self.model, self.data)  # places the object geoms
        self.objects = np.array([g for g in range(self.model.ngeom)
                                 if self.model.geom(g).name.startswith("object:")])
        self.capsules = np.arange(self.model.ngeom - 3, self.model.ngeom)

    def nearest_kind(self, p, r: Rotation) -> str:
        """The kind of the object geom nearest the gripper at (p, r) ("mesh", "box", ...),
        by MuJoCo's distances (the one that decides a collision there)."""
        self._pose(p, r)
        dist = [min(self.mujoco.mj_geomDistance(self.model, self.data, g, c, 1.0, None)
                    for c in self.capsules) for g in self.objects]
        kind = self.model.geom_type[self.objects[int(np.argmin(dist))]]
        return self.mujoco.mjtGeom(kind).name.removeprefix("mjGEOM_").lower()

    def _pose(self, p, r: Rotation) -> None:
        R = r.as_matrix()
        x, y, z = R[:, 0], R[:, 1], R[:, 2]
        half = self.opening / 2
        # fingers along z from the palm (z = -length) to p; the palm along y at z = -length
        centres = [p + half * y - self.length / 2 * z, p - half * y - self.length / 2 * z,
                   p - self.length * z]
        palm = np.column_stack([x, -z, y])
        for g, c, m in zip(self.capsules, centres, [R, R, palm], strict=True):
            self.data.geom_xpos[g] = c
            self.data.geom_xmat[g] = m.ravel()

    def deepest(self, p, r: Rotation) -> float:
        self._pose(p, r)
        # mj_geomDistance answers exactly up to distmax (1 m) and distmax beyond it; pairs
        # whose bounding spheres are apart by more than 1 cm cannot decide a penetration.
        xpos, rbound = self.data.geom_xpos, self.model.geom_rbound
        obj, cap = self.objects, self.capsules
        apart = np.linalg.norm(xpos[obj, None] - xpos[None, cap], axis=-1)
        near = np.argwhere(apart < rbound[obj, None] + rbound[None, cap] + 0.01)
        return min((self.mujoco.mj_geomDistance(self.model, self.data, obj[o], cap[k], 1.0,
                                                None) for o, k in near), default=1.0)

    def penetrates(self, p, r: Rotation) -> bool:
        return self.deepest(p, r) < -PENETRATION


@functools.lru_cache(maxsize=64)
def _model(mjcf: str, r_f: float, r_p: float, length: float, opening: float):
    """The objects of ``mjcf`` and the gripper's capsules as one MuJoCo model, compiled
    once per scene and gripper (a mesh's hull is computed in the compile)."""
    import mujoco

    spec = mujoco.MjSpec.from_string(mjcf)
    hand = spec.worldbody.add_body(name="gripper")
    hand.add_freejoint()
    for radius, half in ((r_f, length / 2), (r_f, length / 2), (r_p, opening / 2)):
        hand.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[radius, half, 0])
    return spec.compile()


# --- the rollout -----------------------------------------------------------------------


@dataclass
class Result:
    outcome: str
    activated: int
    step: int
    point: np.ndarray
    delta_R: float
    meta_steps: int
    path_length: float
    quat: np.ndarray  # R at the end (w, x, y, z)
    # Steps before activation under no, scene, correct and wrong assistance (the intent
    # modes count all four; the others' come from the meta steps).
    assist: tuple[int, int, int, int] | None = None


def turn_across(u, w) -> np.ndarray:
    """u turned by the rotation vector w's part across it: the wandering hand's turn
    of a commanded direction. The way scipy's ``Rotation.from_rotvec(a).apply(u)``
    goes (the rotation vector to a unit quaternion, that to a matrix, the matrix times
    u), on Python floats: seven times faster for one vector, and within 5e-16 of
    scipy's (test_users holds them together)."""
    ux, uy, uz = (float(v) for v in u)
    wx, wy, wz = (float(v) for v in w)
    d = wx * ux + wy * uy + wz * uz
    ax, ay, az = wx - d * ux, wy - d * uy, wz - d * uz
    theta = math.sqrt(ax * ax + ay * ay + az * az)
    if theta == 0.0:  # no turn (a user without noise)
        return np.array([ux, uy, uz])
    s = math.sin(0.5 * theta) / theta
    qw, qx, qy, qz = math.cos(0.5 * theta), s * ax, s * ay, s * az
    return np.array([
        (1 - 2 * (qy * qy + qz * qz)) * ux + 2 * (qx * qy - qz * qw) * uy
        + 2 * (qx * qz + qy * qw) * uz,
        2 * (qx * qy + qz * qw) * ux + (1 - 2 * (qx * qx + qz * qz)) * uy
        + 2 * (qy * qz - qx * qw) * uz,
        2 * (qx * qz - qy * qw) * ux + 2 * (qy * qz + qx * qw) * uy
        + (1 - 2 * (qx * qx + qy * qy)) * uz])


def first_entry(space: Space, a, b, tau: float) -> float | None:
    """The first t in [0, 1] with sdf(a + t (b - a)) <= tau, None if there is none: the
    signed distance to a convex space is convex along a segment, so a golden-section
    search finds its minimum and a bisection the entry before it. Skipped when no
    point of the segment can be that close (the distance is 1-Lipschitz)."""
    def f(t):
        return space.sdf(a + t * (b - a))

    f0, f1, half = f(0.0), f(1.0), 0.5 * float(np.linalg.norm(b - a))
    if f0 <= tau:
        return 0.0
    if min(f0, f1) - half > tau:
        return None
    lo, hi = 0.0, 1.0
    for _ in range(80):
        m1, m2 = lo + 0.381966 * (hi - lo), lo + 0.618034 * (hi - lo)
        if f(m1) <= f(m2):
            hi = m2
        else:
            lo = m1
    t_min = 0.5 * (lo + hi)
    if min(f(t_min), f1) > tau:
        return None
    end = t_min if f(t_min) <= tau else 1.0
    lo, hi = 0.0, end
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if f(mid) <= tau:
            hi = mid
        else:
            lo = mid
    return hi


@dataclass
class User:
    """A simulated user (the user_* settings, reference/model "Simulated users") with
    its random numbers, given as arrays (the kernel's stream:
    ``shacc_jax.streams.user_draws``): per step the wandering hand's innovation xi (n, 3);
    once per rollout the tremor's axis and phase, the hand's first vector in units of
    user_noise, and the change of mind's two uniform numbers."""

    noise: float
    noise_tau: float
    tremor: float
    tremor_hz: float
    switch: float
    switch_at: float
    mode_switch_s: float
    xi: np.ndarray
    tremor_axis: np.ndarray
    tremor_phase: float
    noise0: np.ndarray
    switch_u: float
    other_u: float
    modes: bool = False
    aim: bool = False  # steers at the task's aim point (user_aim = object)


def first_headed(user: User, target: int, n_tasks: int) -> int:
    """The task a rollout heads for first: another of the scene's tasks, each as likely,
    where its uniform number falls below user_switch (and the scene has another task);
    else its own."""
    if not (user.switch_u < user.switch and n_tasks > 1):
        return target
    j = min(int(user.other_u * (n_tasks - 1)), n_tasks - 2)
    return j + 1 if j >= target else j


def rollout(baked, scene: int, mode_name: str, start: int, target: int,
            user: User | None = None, swept: bool = False, mjcf: str | None = None) -> Result:
    """One rollout from baked arrays (float64), the step rule step by step; with
    ``user``, the imperfect user of the model page's "Simulated users" (a wandering
    hand, a tremor, a two-mode joystick, a change of mind, aiming at the object) in
    mode ``mode_name`` instead of the perfect one; with
    ``swept``, activation where the gripper's segment of a step first enters a space
    (the path length up to there, in proportion); with ``mjcf``, collisions against
    that MJCF's objects (the scene's export) instead of the baked ones."""
    T = int(baked.task_mask[scene].sum())
    which = "init" if mode_name in ("baseline", "blend", "ho") else "opt"
    intent = mode_name in ("blend", "ho", "shacc_ho")

    def spaces(w):
        return [Space(int(baked.kind[scene, j]), getattr(baked, f"center_{w}")[scene, j],
                      getattr(baked, f"quat_{w}")[scene, j], getattr(baked, f"dims_{w}")[scene, j])
                for j in range(T)]

    active = spaces(which)
    init, opt = spaces("init"), spaces("opt")
    cluster = baked.cluster[scene, :T]
    orient = [(int(baked.orient_kind[scene, j]), baked.orient_quat[scene, j],
               baked.orient_axis[scene, j]) for j in range(T)]
    dt, v_max = float(baked.dt[scene]), float(baked.v_max[scene])
    omega, tau = float(baked.omega_max[scene]), float(baked.activation_tol[scene])
    max_steps = int(baked.max_steps[scene])
    nearest_rule = bool(baked.ambiguity_nearest[scene])
    start_pose = baked.starts[scene, start]
    p = start_pose[:3].astype(float).copy()
    r = _rot(start_pose[3:])
    travelled, meta_steps = 0.0, 0
    collider = Collider(baked, scene, mjcf) if bool(baked.collision[scene]) else None

    def check(p):
        sd = np.array([s.sdf(p) for s in active])
        return sd, np.flatnonzero(sd <= tau)

    def collided(step):
        return Result("collision", -1, step, p, np.nan, meta_steps, travelled, _wxyz(r),
                      counts())

    # Intent inference: the posterior over the tasks from V_j, the distance left to each
    # space, against V_j at the start; its best task and confidence.
    beta, threshold = float(baked.intent_beta[scene]), float(baked.blend_threshold[scene])
    gain = float(baked.ho_gain[scene])
    correct = wrong = 0

    def counts():
        return (step_count - meta_steps - correct - wrong, meta_steps, correct, wrong) \
            if intent else None

    def posterior(at):
        v = np.array([max(s.sdf(at), 0.0) for s in active])
        e = np.exp(-(v - v_start) / beta)
        return e / e.sum()

    def best_and_confidence(prob):
        best = int(np.argmax(prob))
        second = max((prob[j] for j in range(T) if j != best), default=0.0)
        return best, prob[best] - second

    q = p.copy()

    def gripper(k):  # the commanded position plus the tremor at step k
        if user is None:
            return q.copy()
        wave = math.sin(2 * math.pi * user.tremor_hz * k * dt + user.tremor_phase)
        return q + user.tremor * wave * np.asarray(user.tremor_axis, float)

    p = gripper(0)
    v_start = np.array([max(s.sdf(p), 0.0) for s in active])
    step_count = 0
    # The user's state: the wandering hand, the joystick's mode and pause, the change of
    # mind (its first task, and the distance to that task's space at the start).
    if user is not None:
        decoy = first_headed(user, target, T)
        turned = decoy == target
        d0 = float(np.linalg.norm(active[decoy].project(p) - p))
        w = user.noise * np.asarray(user.noise0, float)
        a = math.exp(-dt / user.noise_tau) if user.noise_tau > 0 else 0.0
        b = math.sqrt(max(1.0 - a * a, 0.0)) * user.noise
        mode, pause = -1, 0
        switch_steps = round(user.mode_switch_s / dt)
        aims = baked.aim_point[scene]
    # Collision checks come first: a skill never activates at a penetrating pose.
    if collider is not None and collider.penetrates(p, r):
        return collided(0)
    sd, act = check(p)
    step = 0
    while act.size == 0 and step < max_steps:
        step_count = step
        if user is None:
            c = active[target].project(p)
            gap = np.linalg.norm(c - p)
            move = (c - p) / gap * min(v_max * dt, gap) if gap > 0 else np.zeros(3)
        else:
            if not turned and np.linalg.norm(active[decoy].project(p) - p) <= \
                    (1.0 - user.switch_at) * d0:
                turned = True
            heading = target if turned else decoy
            c = aims[heading] if user.aim else active[heading].project(p)
            gap = np.linalg.norm(c - p)
            u = (c - p) / gap if gap > 0 else np.zeros(3)
            cmd = turn_across(u, w) if gap > 0 else np.zeros(3)
            horizontal, vertical = gap * np.linalg.norm(cmd[:2]), gap * abs(cmd[2])
            undecided = mode < 0
            if undecided:
                mode = 1 if vertical > horizontal else 0
            current, other = (horizontal, vertical) if mode == 0 else (vertical, horizontal)
            waiting = pause > 0
            switch = user.modes and not waiting and not undecided and gap > 0 and \
                current < 0.5 * other
            if switch:
                mode = 1 - mode
            pause = pause - 1 if waiting else (max(switch_steps - 1, 0) if switch else 0)
            still = user.modes and (waiting or (switch and switch_steps > 0))
            if user.modes:
                part = cmd * (np.array([1.0, 1.0, 0.0]) if mode == 0 else
                              np.array([0.0, 0.0, 1.0]))
                part_len = gap * np.linalg.norm(part)
                unit = part / np.linalg.norm(part) if part_len > 0 else np.zeros(3)
            else:
                part_len, unit = gap, cmd
            go = gap > 0 and not still and part_len > 0
            move = unit * min(v_max * dt, part_len) if go else np.zeros(3)
            w = a * w + b * np.asarray(user.xi[step], float)
        if intent:  # the position assistance, from the posterior at p
            prob = posterior(p)
            towards = []
            for s in active:
                d = s.project(p) - p
                dist = float(np.linalg.norm(d))
                towards.append((d / dist if dist > 0 else np.zeros(3), dist))
            if mode_name == "blend":
                best, conf = best_and_confidence(prob)
                if conf >= threshold:
                    unit, dist = towards[best]
                    move = (1 - conf) * move + conf * unit * min(v_max * dt, dist)
                    move = move * min(1.0, v_max * dt / np.linalg.norm(move)) \
                        if np.linalg.norm(move) > 0 else move
            else:
                move = move + gain * v_max * dt * sum(prob[j] * towards[j][0] for j in range(T))
                if np.linalg.norm(move) > v_max * dt:
                    move = move * (v_max * dt / np.linalg.norm(move))
        step += 1
        step_count = step
        q = q + move
        before, p = p, gripper(step)
        travelled += float(np.linalg.norm(move))
        if collider is not None and collider.penetrates(p, r):
            return collided(step)
        sd, act = check(p)
        if swept:
            entries = [t for t in (first_entry(s, before, p, tau) for s in active)
                       if t is not None]
            if entries:
                t_hit = min(entries)
                travelled -= (1.0 - t_hit) * float(np.linalg.norm(move))
                p = before + t_hit * (p - before)
                sd = np.array([s.sdf(p) for s in active])
                act = np.flatnonzero(sd <= tau + 1e-9)
        if act.size:
            break
        inside = []
        if mode_name in ("shacc", "shacc_ho"):
            sd_init = np.array([s.sdf(p) for s in init])
            inside = [j for j in range(T) if cluster[j] >= 0 and sd_init[j] <= tau]
            if inside:
                j0 = min(inside, key=lambda j: (sd_init[j], j))
                members = [j for j in range(T) if cluster[j] == cluster[j0]]
                d = np.array([max(opt[j].sdf(p), 1e-6) for j in members])
                wt = (1.0 / d**2) / np.sum(1.0 / d**2)
                rots = task_rotations([orient[j] for j in members], p)
                r = rotate_towards(r, rots.mean(weights=wt), omega * dt)
                meta_steps += 1
        if intent and not inside:  # the orientation assistance, from the posterior at p
            prob = posterior(p)
            best, conf = best_and_confidence(prob)
            rots = task_rotations(orient[:T], p)
            if mode_name == "blend":
                goal = rots[best] if conf >= threshold else None
            else:
                goal = rots.mean(weights=prob)
            if goal is not None:
                r = rotate_towards(r, goal, omega * dt)
                if best == target:
                    correct += 1
                else:
                    wrong += 1
    if act.size == 0:
        return Result("timeout", -1, max_steps, p, np.nan, meta_steps, travelled, _wxyz(r),
                      counts())
    smallest = min(sd[j] for j in act)
    nearest = int(min(j for j in act if sd[j] <= smallest + TIE))
    if nearest_rule:
        outcome = "success" if nearest == target else "wrong"
    elif target in act:
        outcome = "success" if act.size == 1 else "ambiguous"
    else:
        outcome = "wrong"
    dr = angle_between(r, task_rotation(*orient[target], p)) if outcome == "success" else np.nan
    return Result(outcome, nearest, step, p, dr, meta_steps, travelled, _wxyz(r), counts())
