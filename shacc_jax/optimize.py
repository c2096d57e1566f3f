"""The ``optimized`` mode's search (SPEC section 17): for each scene, the sizes of its
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

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from geometry_precompute import schema

from . import program_cache, shapes
from .evaluation import activation_pass
from .types import SUCCESS, Geometry, Params, Search, SearchProblem

SIGMA0 = 0.3  # CMA-ES's initial step, in units of each parameter's range
GRID = 1024   # candidates lie on a grid of 1/GRID of each parameter's range
MEAN0 = "center"  # where CMA-ES's mean starts: "center" of the box, or "shrinking"


def spaces_at(center_init: Array, dims_init: Array, problem: SearchProblem, q: Array,
              xp=jnp) -> tuple[Array, Array]:
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
    cand = g._replace(starts=pb.opt_starts, center_opt=center, dims_opt=dims)
    _, _, out = activation_pass(cand, params, "opt")  # outcomes (No, T)
    counted = pb.opt_start_mask[:, None] & g.task_mask[None, :]
    hits = jnp.sum((out.code == SUCCESS) & counted, dtype=jnp.int32)
    volume = jnp.sum(jnp.where(g.task_mask, jax.vmap(shapes.volume)(g.kind, dims), 0.0))
    return hits, volume


def _cma_es(population: int, solution: Array):
    """evosax's CMA-ES, sampling with the symmetric square root of C (B D B^T) instead
    of B D. Both give N(m, sigma^2 C); but the eigenvectors B are unique only up to
    sign (and to a basis within a repeated eigenvalue, as in the first generation's
    C = I), and CPU LAPACK and GPU cuSOLVER choose differently, so the B D samples, and
    from then on the whole search, differed between devices. B D B^T is unique. The
    update (``tell``) already uses C^(-1/2) = B D^-1 B^T only."""
    from evosax.algorithms import CMA_ES
    from evosax.algorithms.distribution_based.cma_es import eigen_decomposition

    class SymmetricCMA_ES(CMA_ES):
        def _ask(self, key, state, params):
            C, B, D = eigen_decomposition(state.C)
            z = jax.random.normal(key, (self.population_size, self.num_dims))
            z = z @ ((B * D) @ B.T)
            return state.mean + state.std * z, state.replace(C=C, B=B, D=D)

    return SymmetricCMA_ES(population_size=population, solution=solution)


def _search_one(geometry: Geometry, settings: Params, pb: SearchProblem, population: int,
                generations: int) -> Search:
    T, P = pb.q_init.shape
    span = pb.q_init - pb.q_min
    movable = pb.q_mask & (span > 0)

    def to_q(z):
        z = jnp.clip(z.reshape(T, P), 0.0, 1.0)
        return jnp.where(movable, pb.q_min + z * span, pb.q_init)

    z_init = jnp.ones(T * P, span.dtype)
    z_shrunk = jnp.where(movable, (pb.q_shrunk - pb.q_min) / jnp.where(movable, span, 1.0),
                         1.0).reshape(T * P)
    # Success counts stay integers until the end: u = count / n is then one operation
    # on equal integers, never two roundings of the same value.
    h_init, v_init = objective(geometry, settings, pb, to_q(z_init))
    h_shrunk, _ = objective(geometry, settings, pb, to_q(z_shrunk))
    n_counted = jnp.sum(pb.opt_start_mask, dtype=jnp.int32) * jnp.sum(geometry.task_mask,
                                                                     dtype=jnp.int32)

    def fitness(h, v):  # evosax minimises; half a success is worth all the volume
        return -(h.astype(span.dtype) + 0.5 * v / v_init)

    es = _cma_es(population, z_init)
    es_params = es.default_params.replace(std_init=jnp.asarray(SIGMA0, span.dtype))
    key = jax.random.key(pb.optimize_seed)
    key, k0 = jax.random.split(key)
    mean0 = z_shrunk if MEAN0 == "shrinking" else jnp.full_like(z_init, 0.5)
    state = es.init(k0, mean0, es_params)

    def generation(carry, g):
        state, key, best_z, best_f, best_h, best_v = carry
        key, k_ask, k_tell = jax.random.split(key, 3)
        pop, state = es.ask(k_ask, state, es_params)
        pop = jnp.round(jnp.clip(pop, 0.0, 1.0) * GRID) / GRID
        seeded = pop.at[0].set(z_init).at[1].set(z_shrunk)
        pop = jnp.where(g == 0, seeded, pop)
        h, v = jax.vmap(lambda z: objective(geometry, settings, pb, to_q(z)))(pop)
        f = fitness(h, v)
        i = jnp.argmin(f)
        better = f[i] < best_f
        best = (jnp.where(better, pop[i], best_z), jnp.where(better, f[i], best_f),
                jnp.where(better, h[i], best_h), jnp.where(better, v[i], best_v))
        state, _ = es.tell(k_tell, pop, f, state, es_params)
        return (state, key, *best), best[2]

    start = (state, key, z_shrunk, jnp.asarray(jnp.inf, span.dtype), h_shrunk, v_init)
    (_, _, best_z, _, best_h, best_v), history = jax.lax.scan(
        generation, start, jnp.arange(generations))
    u = jnp.concatenate([jnp.stack([best_h, h_init, h_shrunk]), history]).astype(
        span.dtype) / n_counted.astype(span.dtype)
    return Search(to_q(best_z), u[0], best_v, u[1], u[2], u[3:])


@partial(jax.jit, static_argnames=("population", "generations"))
def _search(geometry: Geometry, params: Params, problem: SearchProblem, population: int,
            generations: int) -> Search:
    return jax.vmap(partial(_search_one, population=population, generations=generations))(
        geometry, params, problem)


_SEARCH_STRUCTURE = Search(*[0] * len(Search._fields))


def search_sizes(baked) -> tuple[int, int]:
    """(population, generations) of a batch; they are static sizes of the search's
    program, so every scene of one batch must have the same."""
    sizes = []
    for name in ("optimize_population", "optimize_generations"):
        values = np.unique(np.asarray(getattr(baked, name)))
        if len(values) != 1:
            names = getattr(baked, "labels", {}).get("names", [])
            raise ValueError(f"{name} differs between the scenes of one batch "
                             f"({values.tolist()}{', scenes ' + ', '.join(names) if names else ''}"
                             "); search them apart")
        sizes.append(int(values[0]))
    return sizes[0], sizes[1]


def search(baked, scenes_per_call: int | None = None) -> Search:
    """Run the search for every scene of a bake; NumPy results.

    Scenes are searched in groups of equal task count, each cut to its own tasks, so a
    scene's search has exactly its own dimension (2 per task): its result does not
    depend on the other scenes of the batch or on their padding, and no work goes to
    padded tasks. ``scenes_per_call`` bounds the scenes of one call of the compiled
    program (its memory grows with scenes x population x search starts x tasks); the
    calls of a group have one size (the last padded by repeating a scene), so each
    group compiles once."""
    population, generations = search_sizes(baked)
    with jax.enable_x64(True):
        return _search_groups(baked, scenes_per_call, population, generations)


def _search_groups(baked, scenes_per_call, population, generations) -> Search:
    geometry = jax.tree.map(np.asarray, Geometry.from_bake(baked, np.float64))
    params = jax.tree.map(np.asarray, Params.from_bake(baked, np.float64))
    problem = jax.tree.map(np.asarray, SearchProblem.from_bake(baked, np.float64))
    S = geometry.task_mask.shape[0]
    n_tasks = geometry.task_mask.sum(axis=1)
    static = {"population": population, "generations": generations}
    G = generations
    dtype = geometry.center_init.dtype
    out = Search(q=problem.q_init.copy(), objective=np.zeros(S, dtype),
                 volume=np.zeros(S, dtype), objective_init=np.zeros(S, dtype),
                 objective_shrunk=np.zeros(S, dtype), history=np.zeros((S, G), dtype))
    for n in np.unique(n_tasks):
        members = np.flatnonzero(n_tasks == n)
        per = len(members) if scenes_per_call is None else max(1, min(len(members),
                                                                      int(scenes_per_call)))
        for a in range(0, len(members), per):
            idx = members[np.minimum(np.arange(a, a + per), len(members) - 1)]
            keep = members[a:a + per]
            piece = (cut(geometry, idx, n), cut(params, idx, n), cut(problem, idx, n))
            found = program_cache.call("search", _search, static, piece, _SEARCH_STRUCTURE)
            found = jax.tree.map(lambda x, keep=keep: np.asarray(x)[:len(keep)], found)
            out.q[keep, :n] = found.q
            for name in Search._fields[1:]:
                getattr(out, name)[keep] = getattr(found, name)
    return out


_PER_TASK = schema.per_task(schema.GEOMETRY + schema.SEARCH)


def cut(tree, idx: np.ndarray, n: int):
    """Scenes ``idx`` of a Geometry, Params or SearchProblem (host arrays), cut to their
    first n tasks."""
    return type(tree)(**{k: v[idx][:, :n] if k in _PER_TASK else v[idx]
                         for k, v in tree._asdict().items()})


def optimized_spaces(baked, found: Search) -> tuple[np.ndarray, np.ndarray]:
    """(center, dims) (S, T, 3) of the spaces at the search's parameters, float64, for
    the bake's ``center_opt`` / ``dims_opt`` of the optimized mode."""
    pb = SearchProblem(*(np.asarray(getattr(baked, k)) for k in SearchProblem._fields))
    return spaces_at(np.asarray(baked.center_init, np.float64),
                     np.asarray(baked.dims_init, np.float64), pb,
                     np.asarray(found.q, np.float64), xp=np)
