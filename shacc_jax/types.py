"""The pytrees the JAX half works on, built from the bake's arrays by name.

Their fields are the bake's schema (``geometry_precompute.schema``: GEOMETRY, PARAMS,
SEARCH), so the two halves cannot disagree on a name or an axis. Three kinds of data
are kept apart (STYLE pattern 4): :class:`Geometry` (baked arrays), :class:`Params`
(every rollout setting as a leaf, per scene, optionally with a leading axis of sweep
points) and the static :class:`~geometry_precompute.schema.Layout`; the rollout state
lives inside the Automaton's loops.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from geometry_precompute import schema
from geometry_precompute.schema import (  # noqa: F401  (re-exported)
    ALL_MODES,
    AMBIGUOUS,
    ASSISTANCE,
    COLLISION,
    INTENT_MODES,
    INVALID,
    MODES,
    OPTIMIZED,
    OUTCOMES,
    SUCCESS,
    TIMEOUT,
    WRONG,
    Layout,
    batch_layout,
)

from .shapes import prepare_all

# What a result holds: JAX arrays as ``evaluate`` returns them, NumPy arrays once copied
# to the host (``sweeps.pipeline`` returns them so). The inputs (Geometry, Params,
# SearchProblem) are typed as the kernel receives them, JAX arrays.
AnyArray = Array | np.ndarray


class Spaces(NamedTuple):
    """One scene's position spaces, T tasks: ``kind`` (T,) shape codes
    (``geometry_precompute.schema.KINDS``), ``center`` (T, 3) m (a cone's apex),
    ``quat`` (T, 4) rotations (w, x, y, z), ``dims`` (T, 3): cylinder and disk (radius,
    height, 0) m, cone (length m, half angle rad, 0), box half extents m. What
    :func:`shacc_jax.clutteredness_mc` samples.

    Example::

        >>> import jax.numpy as jnp
        >>> from shacc_jax import Spaces
        >>> two_cylinders = Spaces(jnp.zeros(2, jnp.int32),
        ...                        jnp.array([[0.0, -0.05, 0.1], [0.0, 0.05, 0.1]]),
        ...                        jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (2, 1)),
        ...                        jnp.array([[0.08, 0.1, 0.0], [0.08, 0.1, 0.0]]))
        >>> two_cylinders.center.shape
        (2, 3)
    """

    kind: Array
    center: Array
    quat: Array
    dims: Array


def _read(cls, baked, dtype=None, on_host: bool = False):
    """``cls``'s fields read from the bake by name (attributes or a mapping); floats
    cast to ``dtype`` (default: float64 when jax_enable_x64 is on, else float32),
    integers to int32; NumPy arrays with ``on_host``, else on the default device."""
    dtype = dtype or jax.dtypes.canonicalize_dtype(np.float64)
    get = baked.__getitem__ if isinstance(baked, dict) else lambda k: getattr(baked, k)
    out = {}
    for name in cls._fields:
        a = np.asarray(get(name))
        if a.dtype.kind == "f":
            a = a.astype(dtype)
        elif a.dtype.kind in "iu":
            a = a.astype(np.int32)
        # A plain copy to the device: jnp.asarray would compile (or load from the
        # persistent cache) a small program per shape and dtype, ten per chunk shape.
        out[name] = a if on_host else jax.device_put(a)
    return cls(**out)


class Geometry(NamedTuple):
    """A batch's baked arrays, leading axis S scenes: the spaces before and after
    Shrinking (kind, centre in m, quaternion w first, dims in m or rad), the task mask,
    clusters, orientation spaces, objects and the start poses (S, N, 7).
    ``geometry_precompute.schema.GEOMETRY`` gives each field's meaning (the reference's
    outputs page lists them); ``Geometry.from_bake(baked)`` builds it. The fields are
    the schema's, in its order (a test keeps them so)."""

    task_mask: Bool[Array, "S T"]
    kind: Int[Array, "S T"]
    center_init: Float[Array, "S T 3"]
    quat_init: Float[Array, "S T 4"]
    dims_init: Float[Array, "S T 3"]
    center_opt: Float[Array, "S T 3"]
    quat_opt: Float[Array, "S T 4"]
    dims_opt: Float[Array, "S T 3"]
    cluster: Int[Array, "S T"]
    yaw_meta: Bool[Array, " S"]
    orient_kind: Int[Array, "S T"]
    orient_quat: Float[Array, "S T 4"]
    orient_axis: Float[Array, "S T 2"]
    aim_point: Float[Array, "S T 3"]
    starts: Float[Array, "S N 7"]
    start_index: Int[Array, "S N"]
    obj_mask: Bool[Array, "S O"]
    obj_kind: Int[Array, "S O"]
    obj_center: Float[Array, "S O 3"]
    obj_quat: Float[Array, "S O 4"]
    obj_size: Float[Array, "S O 3"]
    obj_hull: Float[Array, "S O F 3 3"]
    obj_hull_plane: Float[Array, "S O F 4"]
    scene_key: Int[Array, " S"]

    @classmethod
    def from_bake(cls, baked, dtype=None, on_host: bool = False) -> Geometry:
        """The fields read from a bake (or a mapping) by name; floats cast to ``dtype``
        (default float32, float64 with x64 on); NumPy arrays ``on_host``, else on the
        default device."""
        return _read(cls, baked, dtype, on_host)

    def spaces(self, which: str):
        """One scene's ``init`` or ``opt`` spaces, prepared for queries (rotation
        matrices and cone trigonometry computed once): a ``shapes.Prepared`` over
        tasks."""
        return prepare_all(self.kind, getattr(self, f"center_{which}"),
                           getattr(self, f"quat_{which}"), getattr(self, f"dims_{which}"))


class Params(NamedTuple):
    """Every rollout setting (``geometry_precompute.schema.PARAMS``) as a leaf of shape
    (S,), or (P, S) for P sweep points over one geometry; the populations of simulated
    users (``user_dist*``) have trailing axes: the seven populated user settings, then
    their numbers or a list's 16 values. Leaves, so new values never recompile. The fields are the
    schema's, in its order (a test keeps them so)."""

    dt: Float[Array, "*P S"]
    v_max: Float[Array, "*P S"]
    omega_max: Float[Array, "*P S"]
    max_steps: Int[Array, "*P S"]
    activation_tol: Float[Array, "*P S"]
    ambiguity_nearest: Bool[Array, "*P S"]
    user_seed: Int[Array, "*P S"]
    collision: Bool[Array, "*P S"]
    user_noise: Float[Array, "*P S"]
    user_noise_tau: Float[Array, "*P S"]
    user_tremor: Float[Array, "*P S"]
    user_tremor_hz: Float[Array, "*P S"]
    user_input_modes: Bool[Array, "*P S"]
    user_mode_switch_s: Float[Array, "*P S"]
    user_switch: Float[Array, "*P S"]
    user_switch_at: Float[Array, "*P S"]
    user_aim_object: Bool[Array, "*P S"]
    activation_swept: Bool[Array, "*P S"]
    intent_beta: Float[Array, "*P S"]
    blend_threshold: Float[Array, "*P S"]
    ho_gain: Float[Array, "*P S"]
    gripper_finger_length: Float[Array, "*P S"]
    gripper_finger_radius: Float[Array, "*P S"]
    gripper_opening: Float[Array, "*P S"]
    gripper_palm_radius: Float[Array, "*P S"]
    user_dist: Int[Array, "*P S 7"]
    user_dist_args: Float[Array, "*P S 7 4"]
    user_dist_values: Float[Array, "*P S 7 16"]

    @classmethod
    def from_bake(cls, baked, dtype=None, on_host: bool = False) -> Params:
        """The settings read from a bake (or a mapping) by name (see
        :meth:`Geometry.from_bake`)."""
        return _read(cls, baked, dtype, on_host)

    def gripper(self) -> Float[Array, "... 4"]:
        """[finger_length, finger_radius, opening, palm_radius] (``gripper.gripper_geoms``)."""
        return jnp.stack([getattr(self, k) for k in schema.GRIPPER], axis=-1)


class SearchProblem(NamedTuple):
    """What the optimized mode's search needs beyond Geometry and Params
    (``geometry_precompute.schema.SEARCH``; the fields are the schema's, in its
    order)."""

    q_mask: Bool[Array, "S T P"]
    q_min: Float[Array, "S T P"]
    q_init: Float[Array, "S T P"]
    q_shrunk: Float[Array, "S T P"]
    center_dq: Float[Array, "S T 3 P"]
    dims_dq: Float[Array, "S T 3 P"]
    opt_starts: Float[Array, "S No 7"]
    opt_start_mask: Bool[Array, "S No"]
    optimize_seed: Int[Array, " S"]
    optimize_population: Int[Array, " S"]
    optimize_generations: Int[Array, " S"]
    start_plane: Float[Array, "S 5"]
    optimize_validation_starts: Int[Array, " S"]
    optimize_validation_seed: Int[Array, " S"]
    optimize_candidates: Int[Array, " S"]
    optimize_validate: Bool[Array, " S"]

    @classmethod
    def from_bake(cls, baked, dtype=None, on_host: bool = False) -> SearchProblem:
        """The search's arrays read from a bake by name (see :meth:`Geometry.from_bake`)."""
        return _read(cls, baked, dtype, on_host)


def inputs(baked, modes=MODES, dtype=None, lanes_per_block: int | None = None,
           samples_per_block: int = 16) -> tuple[Geometry, Params, Layout]:
    """(geometry, params, layout) of a bake, ready for ``shacc_jax.evaluate``.

    :param baked: a ``geometry_precompute.bake`` result.
    :param modes: the modes to evaluate, in this order (default baseline, shrinking,
        shacc).
    :param dtype: the float type of the arrays (default float32, float64 with x64 on).

    Example::

        geometry, params, layout = shacc_jax.inputs(bake(results))
        ev = shacc_jax.evaluate(geometry, params, layout)
        ev.metrics.u_scene          # (S, M) success per scene and mode
    """
    return (Geometry.from_bake(baked, dtype), Params.from_bake(baked, dtype),
            batch_layout(baked, modes, lanes_per_block, samples_per_block))


class Search(NamedTuple):
    """The search's result per scene (leading axis S). The search objective is u_scene
    under the shrinking rules on the search's own starts, the validation one the same
    on the validation starts; neither is the evaluation grid, which stays held out.
    ``winner`` names the chosen candidate: 0 Shrinking's sizes, 1 + r the search's
    (r + 1)-th best distinct candidate, ``optimize_candidates`` + 1 the initial sizes."""

    q: Float[AnyArray, "S T P"]                # the chosen candidate's parameters
    objective: Float[AnyArray, " S"]           # its u_scene on the search starts
    volume: Float[AnyArray, " S"]              # its spaces' summed volume, m^3
    objective_init: Float[AnyArray, " S"]      # the initial spaces' u_scene, same starts
    objective_shrunk: Float[AnyArray, " S"]    # Shrinking's
    history: Float[AnyArray, "S G"]            # best search objective so far, per generation
    validation: Float[AnyArray, " S"]          # the chosen candidate's u_scene, validation
    validation_init: Float[AnyArray, " S"]     # the initial sizes', validation starts
    validation_shrunk: Float[AnyArray, " S"]   # Shrinking's, validation starts
    winner: Int[AnyArray, " S"]                # which candidate was chosen (above)
    clutteredness: Float[AnyArray, " S"]       # C of the chosen spaces, estimated


class Rollouts(NamedTuple):
    """Per rollout, shape (S, M, N, T): scenes, modes, starts, intended tasks.

    ``outcome``: codes into ``shacc_jax.OUTCOMES`` (success, wrong, ambiguous,
    timeout, collision); ``activated``: the task index that activated, -1 for none;
    ``step``: the step of activation (``max_steps`` on a timeout); ``point``: where it
    ended (m); ``path_length`` (m); ``meta_steps``: steps spent in a meta-skill region;
    ``delta_R`` (rad): the orientation jump at activation, NaN unless success;
    ``orientation``: the end orientation, a unit quaternion (w, x, y, z); ``user``: the
    values of the populated user settings the rollout drew
    (``geometry_precompute.population.POPULATED``, in that order; the same in every
    mode), (S, M, N, T, U) where some scene's user is a population
    (``Layout.populations``), else (S, M, N, T, 0); ``assist``: the steps before the
    rollout ended under each kind of assistance, (S, M, N, T, 4) in the order of
    ``ASSISTANCE`` (none; scene: the meta skill's cluster average; correct: towards
    the intended task; wrong: towards another), summing to ``step``. Padded tasks
    (``task_mask`` False) hold no rollout: read ``[..., :T_scene]``."""

    outcome: Int[AnyArray, "S M N T"]
    activated: Int[AnyArray, "S M N T"]
    step: Int[AnyArray, "S M N T"]
    point: Float[AnyArray, "S M N T 3"]
    path_length: Float[AnyArray, "S M N T"]
    meta_steps: Int[AnyArray, "S M N T"]
    delta_R: Float[AnyArray, "S M N T"]  # NaN unless success
    orientation: Float[AnyArray, "S M N T 4"]  # R at the end (w, x, y, z)
    user: Float[AnyArray, "S M N T U"]  # drawn user settings (U = len(POPULATED) or 0)
    assist: Int[AnyArray, "S M N T 4"]  # steps under no, scene, correct, wrong assistance


class SceneMetrics(NamedTuple):
    """Per scene and mode, shape (S, M, ...) (reference/statistics): ``u_scene``, the
    fraction of successful rollouts; ``delta_R_mean`` (rad), NaN where a mode has no
    success; ``outcome_counts`` (S, M, 5) in the order of ``shacc_jax.OUTCOMES``;
    ``n_rollouts``, the real (unpadded) rollouts; ``time_mean`` (s) and
    ``path_length_mean`` (m), the means over successes of the time to activation and
    of the path length, NaN without a success; ``assist_fraction`` (S, M, 4), the
    fraction of all the rollouts' steps spent under each kind of assistance
    (``ASSISTANCE``), NaN where no rollout took a step."""

    u_scene: Float[AnyArray, "S M"]
    delta_R_mean: Float[AnyArray, "S M"]  # NaN where a mode has no success
    outcome_counts: Int[AnyArray, "S M 5"]
    n_rollouts: Int[AnyArray, "S M"]
    time_mean: Float[AnyArray, "S M"]
    path_length_mean: Float[AnyArray, "S M"]
    assist_fraction: Float[AnyArray, "S M 4"]


class Evaluation(NamedTuple):
    """What :func:`shacc_jax.evaluate` returns: ``rollouts`` (every rollout, (S, M, N,
    T)) and ``metrics`` (per scene and mode, (S, M)); a leading points axis P when the
    Params had one."""

    rollouts: Rollouts
    metrics: SceneMetrics
