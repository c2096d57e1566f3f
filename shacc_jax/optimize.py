"""The ``optimized`` mode's search (reference/model): for each scene, the sizes of its
task spaces, within Shrinking's bounds, that make the most rollouts succeed.

A candidate is every task's shrinkable parameters q, each within [q_min, q_init].
Its spaces are built here, on the accelerator, from the bake's affine maps (every
template's space is affine in q: ``geometry_precompute.bake``), and it is scored by
u_scene under the ``shrinking`` rules (its spaces as the optimised ones, no meta skill)
on the search's own starts. Ties go to the larger summed volume: the fitness is
successes + V / (2 V_init), and V <= V_init within the bounds, so the volume only ever
decides between equal success counts.

The search is CMA-ES from evosax on q normalised to the unit box (z = 0 at q_min, 1 at
q_init). Candidates are clipped into the box before they are scored and told, so none
ever leaves the bounds, and rounded to a grid of 1/``GRID`` of each range. The mean
starts at the centre of the box with step ``SIGMA0`` (measured against starting at
Shrinking's parameters: docs/DECISIONS.md); the first generation's first two candidates
are replaced by the initial and the Shrinking parameters (exact, off the grid), so the
result is never worse than either on the search starts. One jitted program runs every
generation (``lax.scan``) for a batch of scenes (``vmap``): candidates x starts x tasks
are one batch, with no host round trip.

The same seed gives the same result on a CPU and a GPU, and in any batch: the search
runs in float64, and CMA-ES samples with the symmetric square root of its covariance
(:func:`_cma_es`), which, unlike the eigenvector basis, is the same on every device.

Scenes are searched in groups of equal task count, each cut to its own tasks (see
:func:`search`): a scene's result depends only on the scene, its settings and
``optimize_seed``, never on the other scenes of a batch.
"""

from __future__ import annotations

import contextlib
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from geometry_precompute import schema

from . import flatmap, program_cache, shapes
from . import quaternion as quat
from .automaton import activation_pass
from .types import SUCCESS, AnyArray, Geometry, Params, Search, SearchProblem

SIGMA0 = 0.3  # CMA-ES's initial step, in units of each parameter's range
GRID = 1024   # candidates lie on a grid of 1/GRID of each parameter's range
MEAN0 = "center"  # where CMA-ES's mean starts: "center" of the box, or "shrinking"


def spaces_at(center_init: AnyArray, dims_init: AnyArray, problem: SearchProblem,
              q: AnyArray, xp=jnp) -> tuple[Any, Any]:
    """The spaces' centres and dims (..., T, 3) at parameters q (..., T, P): the bake's
    affine maps, for one scene or a batch alike (``xp``: jax.numpy, or numpy on the
    host)."""
    dq = xp.where(problem.q_mask, q - problem.q_init, 0.0)
    center = center_init + xp.einsum("...ij,...j->...i", problem.center_dq, dq)
    dims = dims_init + xp.einsum("...ij,...j->...i", problem.dims_dq, dq)
    return center, dims


def objective(geometry: Geometry, params: Params, pb: SearchProblem, q: Array
              ) -> tuple[Array, Array]:
    """(successes on the search starts under the shrinking rules, summed volume) of one
    scene's candidate q (T, P); u_scene is successes / (search starts x tasks)."""
    g = geometry
    center, dims = spaces_at(g.center_init, g.dims_init, pb, q)
    # The search scores with the perfect user (the closed form), on its own starts.
    index = jnp.arange(pb.opt_starts.shape[0], dtype=g.start_index.dtype)
    cand = g._replace(starts=pb.opt_starts, start_index=index, center_opt=center,
                      dims_opt=dims)
    _, _, out = activation_pass(cand, params, "opt")  # outcomes (No, T)
    counted = pb.opt_start_mask[:, None] & g.task_mask[None, :]
    hits = jnp.sum((out.code == SUCCESS) & counted, dtype=jnp.int32)
    volume = jnp.sum(jnp.where(g.task_mask, jax.vmap(shapes.volume)(g.kind, dims), 0.0))
    return hits, volume


@contextlib.contextmanager
def _standard_promotion():
    with jax.numpy_dtype_promotion("standard"), jax.numpy_rank_promotion("allow"):
        yield


def _cma_es(population: int, solution: Array):
    """evosax's CMA-ES, sampling with the symmetric square root of C (B D B^T) instead
    of B D. Both give N(m, sigma^2 C); but the eigenvectors B are unique only up to
    sign (and to a basis within a repeated eigenvalue, as in the first generation's
    C = I), and CPU LAPACK and GPU cuSOLVER choose differently, so the B D samples, and
    from then on the whole search, differed between devices. B D B^T is unique. The
    update (``tell``) already uses C^(-1/2) = B D^-1 B^T only."""
    from evosax.algorithms import CMA_ES  # deferred: 1.2 s to import

    # deferred: importing it takes 761 ms
    from evosax.algorithms.distribution_based.cma_es import eigen_decomposition

    class SymmetricCMA_ES(CMA_ES):
        # evosax is written for JAX's standard promotion rules (it multiplies floats by
        # booleans, broadcasts vectors against matrices): its steps are traced under
        # them, whatever the caller set (the test suite runs with strict promotion).
        @property
        def default_params(self):
            with _standard_promotion():
                return super().default_params

        def init(self, *args, **kwargs):
            with _standard_promotion():
                return super().init(*args, **kwargs)

        def ask(self, *args, **kwargs):
            with _standard_promotion():
                return super().ask(*args, **kwargs)

        def tell(self, *args, **kwargs):
            with _standard_promotion():
                return super().tell(*args, **kwargs)

        def _ask(self, key, state, params):
            C, B, D = eigen_decomposition(state.C)
            z = jax.random.normal(key, (self.population_size, self.num_dims))
            z = z @ ((B * D) @ B.T)
            return state.mean + state.std * z, state.replace(C=C, B=B, D=D)

    return SymmetricCMA_ES(population_size=population, solution=solution)


TIE_POINTS = 512  # points of a scene's initial spaces on which a candidate's C is estimated
C_GRID = 1000     # the estimate is rounded to 1/C_GRID before it breaks ties (noise-free ranks)


def tie_points(geometry: Geometry, pb: SearchProblem, n: int = TIE_POINTS
               ) -> tuple[Array, Array]:
    """(points (n, 3), weights (n,)) on which :func:`clutteredness_of` estimates C of any
    candidate's spaces, all of which lie inside the initial spaces (every template's
    space shrinks into its initial one). Each point is drawn uniformly inside one
    initial space, chosen with probability proportional to its volume, so the points
    are spread over the union with density proportional to k(x), the number of initial
    spaces holding x; weights 1 / k(x) undo that. Drawn from the search's seed with
    JAX's counter-based generator: the same points on every device and in any batch."""
    g = geometry
    T = g.task_mask.shape[0]
    key = jax.random.fold_in(jax.random.key(pb.optimize_seed), 0x5C)
    k_space, k_u = jax.random.split(key)
    vol = jnp.where(g.task_mask, jax.vmap(shapes.volume)(g.kind, g.dims_init), 0.0)
    # Space i with probability V_i / sum V: the inverse of the cumulative volumes.
    cum = jnp.cumsum(vol) / jnp.sum(vol)
    pick = jax.random.uniform(k_space, (n,), dtype=vol.dtype)
    which = jnp.zeros(n, jnp.int32)
    for t in range(T - 1):
        which = which + (pick >= cum[t]).astype(jnp.int32)
    u, v, w = jax.random.uniform(k_u, (3, n), dtype=g.dims_init.dtype)
    kind, dims = g.kind[which], g.dims_init[which]
    theta = 2.0 * jnp.pi * v
    # cylinder and disk: radius r sqrt(u), |z| <= h/2; cone: z = L u^(1/3), radius
    # z tan(alpha) sqrt(w); box: uniform in the half extents.
    r_cyl = dims[:, 0] * jnp.sqrt(u)
    cyl = jnp.stack([r_cyl * jnp.cos(theta), r_cyl * jnp.sin(theta), (w - 0.5) * dims[:, 1]], 1)
    z = dims[:, 0] * jnp.cbrt(u)
    r_cone = z * jnp.tan(dims[:, 1]) * jnp.sqrt(w)
    cone = jnp.stack([r_cone * jnp.cos(theta), r_cone * jnp.sin(theta), z], 1)
    box = (2.0 * jnp.stack([u, v, w], 1) - 1.0) * dims
    local = jnp.where((kind == schema.BOX)[:, None], box,
                      jnp.where((kind == schema.CONE)[:, None], cone, cyl))
    rot = jax.vmap(quat.to_matrix)(g.quat_init[which])
    points = g.center_init[which] + jax.vmap(quat.matvec)(rot, local)
    k = jnp.maximum(_holding(g.spaces("init"), g.task_mask, points), 1)
    return points, 1.0 / k.astype(points.dtype)


def _holding(spaces: shapes.Prepared, mask: Array, points: Array) -> Array:
    """(n,) int: how many of the (masked) spaces hold each point. Added up task by task,
    elementwise over the points: as a reduction over the tasks, fused with the tests
    under the search's three vmaps, XLA took minutes to compile it for a GPU."""
    count = jnp.zeros(points.shape[0], jnp.int32)
    for t in range(mask.shape[0]):
        space = jax.tree.map(lambda a, t=t: a[t], spaces)
        inside = jax.vmap(lambda p, space=space: shapes.prepared_contains(space, p))(points)
        count = count + (inside & mask[t]).astype(jnp.int32)
    return count


def clutteredness_of(geometry: Geometry, center: Array, dims: Array, points: Array,
                     weights: Array) -> Array:
    """C of the spaces (center, dims) with the initial rotations, estimated on
    :func:`tie_points`: sum over pairs of V(p_i and p_j) over sum of V(p_i) is
    sum_x w(x) k(x)(k(x) - 1)/2 over sum_x w(x) k(x), k(x) the spaces holding x."""
    g = geometry
    spaces = shapes.prepare_all(g.kind, center, g.quat_init, dims)
    k = _holding(spaces, g.task_mask, points).astype(weights.dtype)
    total = jnp.sum(weights * k)
    return jnp.where(total > 0, jnp.sum(weights * k * (k - 1.0) / 2.0) / total, 0.0)


def validation_starts(pb: SearchProblem, n: int) -> tuple[Array, Array]:
    """(starts (n, 7), mask (n,)): a scene's validation starts, uniform on its start
    plane from ``optimize_validation_seed`` (JAX's generator: the same on every device).
    Only their positions matter (the search scores under the shrinking rules, which
    never turn the gripper), so their orientation is the identity."""
    key = jax.random.fold_in(jax.random.key(pb.optimize_validation_seed), 0x7A1)
    u = jax.random.uniform(key, (2, n), dtype=pb.start_plane.dtype)
    x, y0, y1, z0, z1 = (pb.start_plane[i] for i in range(5))
    pos = jnp.stack([jnp.full(n, x), y0 + (y1 - y0) * u[0], z0 + (z1 - z0) * u[1]], 1)
    quats = jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0, 0.0], pos.dtype), (n, 4))
    n_real = pb.optimize_validation_starts
    return jnp.concatenate([pos, quats], 1), jnp.arange(n, dtype=n_real.dtype) < n_real


def _best_distinct(z: Array, f: Array, *scores: Array, k: int) -> tuple[Array, ...]:
    """The k lowest-fitness rows of ``z`` with no row repeated (a repeat's fitness is
    made inf), in order of fitness, the earlier row first on a tie; with their fitness
    and ``scores``."""
    order = jnp.argsort(f, stable=True)
    z, f, scores = z[order], f[order], tuple(s[order] for s in scores)
    same = jnp.all(z[:, None, :] == z[None, :, :], axis=-1)
    f = jnp.where(jnp.any(jnp.tril(same, k=-1), axis=1), jnp.inf, f)
    order = jnp.argsort(f, stable=True)[:k]
    return (z[order], f[order], *(s[order] for s in scores))


def _search_one(geometry: Geometry, settings: Params, pb: SearchProblem, population: int,
                generations: int, candidates: int, n_val: int) -> Search:
    T, P = pb.q_init.shape
    span = pb.q_init - pb.q_min
    movable = pb.q_mask & (span > 0)

    def to_q(z):
        z = jnp.clip(z.reshape(T, P), 0.0, 1.0)
        return jnp.where(movable, pb.q_min + z * span, pb.q_init)

    z_init = jnp.ones(T * P, span.dtype)
    z_shrunk = jnp.where(movable, (pb.q_shrunk - pb.q_min) / jnp.where(movable, span, 1.0),
                         1.0).reshape(T * P)
    points, weights = tie_points(geometry, pb)

    def score(z):
        """(successes, volume, C) of a candidate on the search starts."""
        q = to_q(z)
        h, v = objective(geometry, settings, pb, q)
        center, dims = spaces_at(geometry.center_init, geometry.dims_init, pb, q)
        return h, v, clutteredness_of(geometry, center, dims, points, weights)

    # The initial spaces' volume, without rollouts (the fitness needs it from the first
    # generation on). Each rollout pass is scored at two places only, the population of
    # a generation and the final validation: every further place would be one more copy
    # of the whole activation pass in the compiled program (the GPU's compile time grew
    # with them). The initial and Shrinking sizes are scored as the first generation's
    # first two candidates, and every candidate kept carries its own scores.
    _, dims_init = spaces_at(geometry.center_init, geometry.dims_init, pb, to_q(z_init))
    v_init = jnp.sum(jnp.where(geometry.task_mask,
                               jax.vmap(shapes.volume)(geometry.kind, dims_init), 0.0))
    n_counted = jnp.sum(pb.opt_start_mask, dtype=jnp.int32) * jnp.sum(geometry.task_mask,
                                                                     dtype=jnp.int32)

    def fitness(h, v, c):
        """evosax minimises. Successes first; among equal successes the lower C (the
        overlap that makes activations wrong, rounded to 1/C_GRID), then the larger
        volume: 0.49 / C_GRID for one step of C outweighs 4e-4 of all the volume. The
        ``search`` selection keeps the earlier objective: successes, then volume."""
        c_step = jnp.round(jnp.minimum(c, 1.0) * C_GRID) / C_GRID
        new = h.astype(span.dtype) + 0.49 * (1.0 - c_step) + 4e-4 * v / v_init
        old = h.astype(span.dtype) + 0.5 * v / v_init
        return -jnp.where(pb.optimize_validate, new, old)

    es = _cma_es(population, z_init)
    es_params = es.default_params.replace(std_init=jnp.asarray(SIGMA0, span.dtype))
    key = jax.random.key(pb.optimize_seed)
    key, k0 = jax.random.split(key)
    mean0 = z_shrunk if MEAN0 == "shrinking" else jnp.full_like(z_init, 0.5)
    state = es.init(k0, mean0, es_params)

    def generation(carry, g):
        state, key, top, seeds, best_h = carry
        key, k_ask, k_tell = jax.random.split(key, 3)
        pop, state = es.ask(k_ask, state, es_params)
        pop = jnp.round(jnp.clip(pop, 0.0, 1.0) * GRID) / GRID
        seeded = pop.at[0].set(z_init).at[1].set(z_shrunk)
        pop = jnp.where(g == 0, seeded, pop)
        h, v, c = jax.vmap(score)(pop)
        f = fitness(h, v, c)
        # (h, v, c) of the initial and the Shrinking sizes, from the first generation.
        seeds = jax.tree.map(lambda old, new: jnp.where(g == 0, new, old), seeds,
                             (h[:2], v[:2], c[:2]))
        top = _best_distinct(*flatmap.stacked(top, (pop, f, h, v, c)), k=candidates)
        best_h = jnp.maximum(best_h, jnp.max(h))
        state, _ = es.tell(k_tell, pop, f, state, es_params)
        return (state, key, top, seeds, best_h), best_h

    D = T * P
    top0 = (jnp.broadcast_to(z_shrunk, (candidates, D)), jnp.full(candidates, jnp.inf, span.dtype),
            jnp.zeros(candidates, jnp.int32), jnp.zeros(candidates, span.dtype),
            jnp.zeros(candidates, span.dtype))
    seeds0 = (jnp.zeros(2, jnp.int32), jnp.zeros(2, span.dtype), jnp.zeros(2, span.dtype))
    start = (state, key, top0, seeds0, jnp.zeros((), jnp.int32))
    (_, _, top, seeds, _), history = jax.lax.scan(generation, start, jnp.arange(generations))
    top_z, top_f, top_h, top_v, top_c = top
    (h_init, h_shrunk), (_, v_shrunk), (c_init, c_shrunk) = ((a[0], a[1]) for a in seeds)
    # The final choice: Shrinking, the search's best distinct candidates (in order of
    # their search fitness) and the initial sizes, scored on the validation starts;
    # the first of the best wins, so a tie goes to Shrinking. Without validation
    # (``search``) the search's best wins.
    pool = jnp.concatenate([z_shrunk[None], top_z, z_init[None]])
    pool_h = jnp.concatenate([h_shrunk[None], top_h, h_init[None]])
    pool_v = jnp.concatenate([v_shrunk[None], top_v, v_init[None]])
    pool_c = jnp.concatenate([c_shrunk[None], top_c, c_init[None]])
    real = jnp.concatenate([jnp.array([True]), jnp.isfinite(top_f), jnp.array([True])])
    val_starts, val_mask = validation_starts(pb, n_val)
    val_pb = pb._replace(opt_starts=val_starts, opt_start_mask=val_mask)
    h_val, _ = jax.vmap(lambda z: objective(geometry, settings, val_pb, to_q(z)))(pool)
    h_val = jnp.where(real, h_val, -1)
    winner = jnp.where(pb.optimize_validate, jnp.argmax(h_val), 1)
    n_val_counted = jnp.sum(val_mask, dtype=jnp.int32) * jnp.sum(geometry.task_mask,
                                                                 dtype=jnp.int32)

    def rate(count, n):
        return count.astype(span.dtype) / jnp.maximum(n, 1).astype(span.dtype)

    return Search(q=to_q(pool[winner]), objective=rate(pool_h[winner], n_counted),
                  volume=pool_v[winner], objective_init=rate(h_init, n_counted),
                  objective_shrunk=rate(h_shrunk, n_counted),
                  history=rate(history, n_counted),
                  validation=rate(h_val[winner], n_val_counted),
                  validation_init=rate(h_val[-1], n_val_counted),
                  validation_shrunk=rate(h_val[0], n_val_counted),
                  winner=winner.astype(jnp.int32), clutteredness=pool_c[winner])


@partial(jax.jit, static_argnames=("population", "generations", "candidates", "n_val"))
def _search(geometry: Geometry, params: Params, problem: SearchProblem, population: int,
            generations: int, candidates: int, n_val: int) -> Search:
    return jax.vmap(partial(_search_one, population=population, generations=generations,
                            candidates=candidates, n_val=n_val))(geometry, params, problem)


_SEARCH_STRUCTURE = Search._make([0] * len(Search._fields))


# A search's activation rollouts per closed-form rollout of work (program_cache.quick):
# at level 0 on the 2-core CPU one costs about a third of a closed-form rollout
# (benchmarks/bench_levels.py; break-even 181 000-446 000 activation rollouts against
# 66 000 closed-form ones), so a search is compiled quickly up to 98 304 of them.
ACTIVATIONS_PER_ROLLOUT = 3

SIZES = ("optimize_population", "optimize_generations", "optimize_candidates")


def search_sizes(baked) -> tuple[int, int, int]:
    """(population, generations, candidates) of a batch; they are static sizes of the
    search's program, so every scene of one batch must have the same."""
    sizes = []
    for name in SIZES:
        values = np.unique(np.asarray(getattr(baked, name)))
        if len(values) != 1:
            names = getattr(baked, "labels", {}).get("names", [])
            raise ValueError(f"{name} differs between the scenes of one batch "
                             f"({values.tolist()}{', scenes ' + ', '.join(names) if names else ''}"
                             "); search them apart")
        sizes.append(int(values[0]))
    return sizes[0], sizes[1], sizes[2]


def search(baked, scenes_per_call: int | None = None, calls: int = 1) -> Search:
    """Run the search for every scene of a bake; NumPy results.

    Scenes are searched in groups of equal task count, each cut to its own tasks, so a
    scene's search has exactly its own dimension (2 per task): its result does not
    depend on the other scenes of the batch or on their padding, and no work goes to
    padded tasks. ``scenes_per_call`` bounds the scenes of one call of the compiled
    program (its memory grows with scenes x population x search starts x tasks); the
    calls of a group have one size (the last padded by repeating a scene), so each
    group compiles once. ``calls``: how many batches of this shape the caller searches
    (a sweep's chunks), for the program's compiler options
    (``program_cache.quick``)."""
    population, generations, candidates = search_sizes(baked)
    with jax.enable_x64(True):
        return _search_groups(baked, scenes_per_call, population, generations, candidates,
                              calls)


def _search_groups(baked, scenes_per_call, population, generations, candidates,
                   calls) -> Search:
    geometry = jax.tree.map(np.asarray, Geometry.from_bake(baked, np.float64))
    params = jax.tree.map(np.asarray, Params.from_bake(baked, np.float64))
    problem = jax.tree.map(np.asarray, SearchProblem.from_bake(baked, np.float64))
    S = geometry.task_mask.shape[0]
    n_tasks = geometry.task_mask.sum(axis=1)
    # The most validation starts of a scene: a static size (fewer are masked).
    n_val = int(np.max(problem.optimize_validation_starts))
    static = {"population": population, "generations": generations,
              "candidates": candidates, "n_val": n_val}
    G = generations
    dtype = geometry.center_init.dtype
    out = Search(q=problem.q_init.copy(), objective=np.zeros(S, dtype),
                 volume=np.zeros(S, dtype), objective_init=np.zeros(S, dtype),
                 objective_shrunk=np.zeros(S, dtype), history=np.zeros((S, G), dtype),
                 validation=np.zeros(S, dtype), validation_init=np.zeros(S, dtype),
                 validation_shrunk=np.zeros(S, dtype), winner=np.zeros(S, np.int32),
                 clutteredness=np.zeros(S, dtype))
    pieces = []  # (task count, scenes of the call, scenes kept, the program's work)
    for n in np.unique(n_tasks):
        members = np.flatnonzero(n_tasks == n)
        per = len(members) if scenes_per_call is None else max(1, min(len(members),
                                                                      int(scenes_per_call)))
        firsts_of_group = range(0, len(members), per)
        # The program's work: its activation rollouts (each generation's population from
        # the search starts, then the candidates, Shrinking's and the initial sizes from
        # the validation's) in every call of it, the group's and the caller's, in
        # closed-form rollouts.
        activations = calls * len(firsts_of_group) * per * int(n) * (
            population * generations * problem.opt_starts.shape[1] + (candidates + 2) * n_val)
        work = -(-activations // ACTIVATIONS_PER_ROLLOUT)
        for a in firsts_of_group:
            idx = members[np.minimum(np.arange(a, a + per), len(members) - 1)]
            pieces.append((int(n), idx, members[a:a + per], work))

    def arrays(n, idx):
        return cut(geometry, idx, n), cut(params, idx, n), cut(problem, idx, n)

    # One program per task count: each group's first call stands for its program, and
    # they all compile side by side while the first group runs.
    firsts: dict[int, tuple] = {}
    for n, idx, _, work in pieces:
        if n not in firsts:
            firsts[n] = (arrays(n, idx), work)
    with program_cache.ahead("search", _search, static, list(firsts.values())) as compiled:
        ready = dict(zip(firsts, compiled, strict=True))
        for n, idx, keep, work in pieces:
            ready[n].result()
            # A group's first call takes the arrays its program was compiled for.
            args = firsts.pop(n)[0] if n in firsts else arrays(n, idx)
            found = program_cache.call("search", _search, static, args,
                                       _SEARCH_STRUCTURE, work=work)
            found = jax.tree.map(lambda x, keep=keep: np.asarray(x)[:len(keep)], found)
            out.q[keep, :n] = found.q
            for name in Search._fields[1:]:
                getattr(out, name)[keep] = getattr(found, name)
    return out


def winner_name(winner: int, candidates: int) -> str:
    """What :class:`~shacc_jax.types.Search`'s ``winner`` code names: "shrinking",
    "initial", or "search #r" (the search's r-th best distinct candidate)."""
    winner = int(winner)
    if winner == 0:
        return "shrinking"
    return "initial" if winner == candidates + 1 else f"search #{winner}"


_PER_TASK = schema.per_task(schema.GEOMETRY + schema.SEARCH)


def cut(tree, idx: np.ndarray, n: int):
    """Scenes ``idx`` of a Geometry, Params or SearchProblem (host arrays), cut to their
    first n tasks."""
    return type(tree)(**{k: v[idx][:, :n] if k in _PER_TASK else v[idx]
                         for k, v in tree._asdict().items()})


def optimized_spaces(baked, found: Search) -> tuple[np.ndarray, np.ndarray]:
    """(center, dims) (S, T, 3) of the spaces at the search's parameters, float64, for
    the bake's ``center_opt`` / ``dims_opt`` of the optimized mode."""
    pb = SearchProblem._make(np.asarray(getattr(baked, k)) for k in SearchProblem._fields)
    return spaces_at(np.asarray(baked.center_init, np.float64),
                     np.asarray(baked.dims_init, np.float64), pb,
                     np.asarray(found.q, np.float64), xp=np)
