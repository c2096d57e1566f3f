"""The pytrees the JAX half works on, built from the bake's arrays by name.

Three kinds of data are kept apart (STYLE): ``Scenes`` (baked geometry and the
per-scene numeric settings, pytree leaves so sweeps vary them without
recompiling), the rollout state (inside the Automaton's loops), and static
layout (array shapes and the tuple of modes, static arguments of the jit).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

MODES = ("baseline", "shrinking", "shacc")
# The fourth mode (SPEC section 17): shacc's rules on the spaces that the search found.
# ``evaluate`` computes MODES; ``optimized`` needs the search first (shacc_jax.optimize).
OPTIMIZED = "optimized"
ALL_MODES = (*MODES, OPTIMIZED)
OUTCOMES = ("success", "wrong", "ambiguous", "timeout", "collision")
SUCCESS, WRONG, AMBIGUOUS, TIMEOUT, COLLISION = range(5)
INVALID = -1  # the rollout's intended task is a padded (masked) task


class Spaces(NamedTuple):
    """One scene's position spaces (T tasks)."""

    kind: Int[Array, " T"]
    center: Float[Array, "T 3"]
    quat: Float[Array, "T 4"]
    dims: Float[Array, "T 3"]


class Scenes(NamedTuple):
    """A batch of baked scenes (leading axis S) and their numeric settings."""

    task_mask: Bool[Array, "S T"]
    kind: Int[Array, "S T"]
    center_init: Float[Array, "S T 3"]
    quat_init: Float[Array, "S T 4"]
    dims_init: Float[Array, "S T 3"]
    center_opt: Float[Array, "S T 3"]
    quat_opt: Float[Array, "S T 4"]
    dims_opt: Float[Array, "S T 3"]
    cluster: Int[Array, "S T"]
    orient_kind: Int[Array, "S T"]
    orient_quat: Float[Array, "S T 4"]
    orient_axis: Float[Array, "S T 2"]
    starts: Float[Array, "S N 7"]
    obj_mask: Bool[Array, "S O"]
    obj_kind: Int[Array, "S O"]
    obj_center: Float[Array, "S O 3"]
    obj_quat: Float[Array, "S O 4"]
    obj_size: Float[Array, "S O 3"]
    dt: Float[Array, " S"]
    v_max: Float[Array, " S"]
    omega_max: Float[Array, " S"]
    activation_tol: Float[Array, " S"]
    max_steps: Int[Array, " S"]
    ambiguity_nearest: Bool[Array, " S"]
    collision: Bool[Array, " S"]
    gripper_finger_length: Float[Array, " S"]
    gripper_finger_radius: Float[Array, " S"]
    gripper_opening: Float[Array, " S"]
    gripper_palm_radius: Float[Array, " S"]

    @classmethod
    def from_bake(cls, baked, dtype=None) -> Scenes:
        """Read the bake's arrays by name (any object with those attributes, or a
        mapping); floats are cast to ``dtype`` (default: float64 when jax_enable_x64
        is on, else float32)."""
        return _read_bake(cls, baked, dtype)

    def gripper(self) -> Float[Array, "... 4"]:
        """[finger_length, finger_radius, opening, palm_radius] (collision.gripper_geoms)."""
        return jnp.stack([self.gripper_finger_length, self.gripper_finger_radius,
                          self.gripper_opening, self.gripper_palm_radius], axis=-1)

    def raw_spaces(self, which: str) -> Spaces:
        return Spaces(self.kind, getattr(self, f"center_{which}"), getattr(self, f"quat_{which}"),
                      getattr(self, f"dims_{which}"))

    def spaces(self, which: str):
        """One scene's ``init`` or ``opt`` spaces, prepared for queries (rotation matrices
        and cone trigonometry computed once): a ``shapes.Prepared`` over tasks."""
        from .shapes import prepare_all

        return prepare_all(*self.raw_spaces(which))


def _read_bake(cls, baked, dtype=None):
    """``cls``'s fields read from the bake by name, floats cast to ``dtype``."""
    dtype = dtype or jnp.zeros(()).dtype
    get = baked.__getitem__ if isinstance(baked, dict) else lambda k: getattr(baked, k)
    out = {}
    for name in cls._fields:
        a = np.asarray(get(name))
        if a.dtype.kind == "f":
            a = a.astype(dtype)
        elif a.dtype.kind in "iu":
            a = a.astype(np.int32)
        out[name] = jnp.asarray(a)
    return cls(**out)


class SearchProblem(NamedTuple):
    """What the optimized mode's search needs beyond :class:`Scenes` (the bake's
    search fields; P = 2 parameter slots per task, No search starts)."""

    q_mask: Bool[Array, "S T P"]
    q_min: Float[Array, "S T P"]
    q_init: Float[Array, "S T P"]
    q_shrunk: Float[Array, "S T P"]
    center_dq: Float[Array, "S T 3 P"]
    dims_dq: Float[Array, "S T 3 P"]
    opt_starts: Float[Array, "S No 7"]
    opt_start_mask: Bool[Array, "S No"]
    optimize_seed: Int[Array, " S"]

    @classmethod
    def from_bake(cls, baked, dtype=None) -> SearchProblem:
        return _read_bake(cls, baked, dtype)


class Search(NamedTuple):
    """The search's result per scene (leading axis S). The objective is u_scene under
    the shrinking rules on the search's own starts (never the evaluation grid)."""

    q: Float[Array, "S T P"]                # the best candidate's parameters
    objective: Float[Array, " S"]           # its u_scene on the search starts
    volume: Float[Array, " S"]              # its spaces' summed volume, m^3
    objective_init: Float[Array, " S"]      # the initial spaces' u_scene, same starts
    objective_shrunk: Float[Array, " S"]    # Shrinking's
    history: Float[Array, "S G"]            # best objective so far, per generation


class Rollouts(NamedTuple):
    """Per rollout, shape (S, M, N, T): scenes, modes, starts, intended tasks."""

    outcome: Int[Array, "S M N T"]
    activated: Int[Array, "S M N T"]
    step: Int[Array, "S M N T"]
    point: Float[Array, "S M N T 3"]
    path_length: Float[Array, "S M N T"]
    meta_steps: Int[Array, "S M N T"]
    delta_R: Float[Array, "S M N T"]  # NaN unless success


class SceneMetrics(NamedTuple):
    """Per scene and mode, shape (S, M, ...) (SPEC section 10)."""

    u_scene: Float[Array, "S M"]
    delta_R_mean: Float[Array, "S M"]  # NaN where a mode has no success
    outcome_counts: Int[Array, "S M 5"]
    n_rollouts: Int[Array, "S M"]


class Evaluation(NamedTuple):
    rollouts: Rollouts
    metrics: SceneMetrics
