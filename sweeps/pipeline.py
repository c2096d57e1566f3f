"""Glue between the halves: scenes -> precompute -> bake -> jitted evaluation ->
NumPy results and the one-scene JSON's JSON. Reproduce and sweeps reuse it."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

import shacc_jax
from geometry_precompute import BakedScenes, PrecomputeResult
from geometry_precompute.baking import bake
from geometry_precompute.population import POPULATED
from geometry_precompute.settings import describe_user
from shacc_jax.optimize import winner_name
from shacc_jax.types import ASSISTANCE, OUTCOMES, Evaluation, Search
from sweeps import compile_cache
from sweeps.output import precompute_json, provenance

__all__ = ["Evaluated", "evaluate_results", "scene_json"]


@dataclass(frozen=True)
class Evaluated:
    """An evaluated batch (:func:`evaluate_results`): the precomputed scenes, their
    bake, the evaluation as NumPy arrays (modes in the order of ``modes``), the
    timings (s), the optimized mode's search where it ran, and the provenance."""

    results: list[PrecomputeResult]
    baked: BakedScenes
    evaluation: Evaluation  # NumPy arrays
    modes: tuple[str, ...]
    seconds: dict
    search: Search | None = None  # the optimized mode's search (NumPy), when asked for
    provenance: dict | None = None  # software, backend, device, command line

    def tables(self, point: int = 0) -> dict:
        """The four long tables of a sweep's Parquet dataset for these scenes, as pandas
        DataFrames (``scenes``, ``tasks``, ``starts``, ``rollouts``): the same columns
        and types, made by the same functions (``sweeps.analysis.tables``), with
        ``point`` in the point column and the scenes numbered from 0 (an evaluation
        sweeps no setting, so the scenes table has no ``set.`` columns).

        Example::

            ev = evaluate_results(results)
            frames = ev.tables()
            frames["rollouts"].groupby("mode", observed=True)["time"].mean()
        """
        from geometry_precompute.batch import scene_labels  # deferred: the mesh libraries
        from sweeps.analysis import tables  # deferred: pyarrow, 0.2 s

        S = len(self.results)
        scenes = np.arange(S)
        ro, me = self.evaluation.rollouts, self.evaluation.metrics
        labels = scene_labels(self.results)
        b = self.baked
        params = {"q_min": b.q_min[:S], "q_init": b.q_init[:S], "q_shrunk": b.q_shrunk[:S],
                  "q_optimized": None if self.search is None else np.asarray(self.search.q)[:S],
                  "starts": b.starts[:S], "dt": b.dt[:S]}
        # The rollouts' columns, without the drawn users' where nothing was drawn.
        fields = {k: np.asarray(v) for k, v in ro._asdict().items()}
        if ro.user is None or ro.user.shape[-1] == 0:
            del fields["user"]
        made = {"scenes": tables.scenes_table(point, {}, (), self.modes, scenes, labels, me),
                "tasks": tables.tasks_table(point, self.modes, scenes, labels, params,
                                            np.asarray(ro.outcome)),
                "starts": tables.starts_table(point, scenes, np.asarray(b.starts[:S])),
                "rollouts": tables.rollouts_table(point, self.modes, scenes,
                                                  SimpleNamespace(**fields), params["dt"])}
        return {name: t.to_pandas() for name, t in made.items()}

    def start_extent(self, s: int = 0) -> tuple[tuple[float, float], tuple[float, float]]:
        """The start grid's extent of scene ``s``, ((y_min, y_max), (z_min, z_max)) in m,
        as :func:`sweeps.analysis.plots.success_fields` takes it."""
        st = np.asarray(self.baked.starts[s])
        return ((float(st[:, 1].min()), float(st[:, 1].max())),
                (float(st[:, 2].min()), float(st[:, 2].max())))

    def searched(self) -> Search:
        """The optimized mode's search; a ValueError when the optimized mode was not
        evaluated."""
        if self.search is None:
            raise ValueError("this evaluation has no optimized mode (no search ran)")
        return self.search


def evaluate_results(results: Sequence[PrecomputeResult], modes=shacc_jax.MODES,
                     max_tasks: int | None = None, found: Search | None = None,
                     budget_bytes: int | None = None) -> Evaluated:
    """Bake and evaluate precomputed scenes in one batch: what ``shacc evaluate`` does.

    :param results: S precomputed scenes (``geometry_precompute.precompute``).
    :param modes: any of baseline, shrinking, shacc, optimized (which runs its search
        first), in the order of the result's mode axis.
    :param max_tasks: pad the task axis to at least this.
    :param found: a search already run for these scenes (the optimized mode reuses it).
    :param budget_bytes: the memory the evaluation may use (default: the machine's
        budget, ``shacc_jax.budget()``); a part of it where evaluations run side by side.
    :returns: an :class:`Evaluated` holding NumPy arrays: ``evaluation.rollouts``
        fields of shape (S, M, N, T), ``evaluation.metrics`` of shape (S, M), the bake
        (``baked.starts`` (S, N, 7)), the timings and the provenance. Memory-bound
        batches are split into pieces and joined, with the same results.

    Example::

        ev = evaluate_results([precompute(load_scene(p)) for p in shipped_scene_paths()])
        ev.evaluation.metrics.u_scene[:, ev.modes.index("shacc")]   # (S,)
        scene_json(ev, 0)["modes"]["baseline"]["outcome"]          # per start and task
    """
    shacc_jax.configure_runtime()  # from Python too, not only from the command line
    compile_cache.enable()
    t0 = time.perf_counter()
    baked = bake(results, max_tasks)
    t1 = time.perf_counter()
    out = shacc_jax.run(baked, modes, found=found, budget_bytes=budget_bytes)
    assert not isinstance(out.search, list)  # one search: no points axis here
    t2 = time.perf_counter()
    return Evaluated(list(results), baked, out.evaluation, tuple(modes),
                     {"bake": t1 - t0, "evaluate": t2 - t1}, out.search,
                     provenance(device=True))


def _none_if_nan(x: float):
    return None if not np.isfinite(x) else float(x)


def scene_json(ev: Evaluated, s: int) -> dict:
    """The one-scene JSON object (reference/outputs) of scene ``s`` of an evaluated
    batch, as ``shacc evaluate --json`` writes it: task ids, C, clusters, Shrinking's
    parameters, d and h, the starts, per mode the outcome, activated task and delta_R
    of every (start, task), with a population of users each (start, task)'s drawn user
    settings (the same in every mode), per task its rates, the settings and the
    provenance.

    Example::

        ev = evaluate_results(results)
        json.dumps(scene_json(ev, 0))
    """
    r = ev.results[s]
    ids = r.task_ids
    T = len(ids)
    out = precompute_json(r)
    out["starts"] = ev.baked.starts[s].tolist()
    ro, me = ev.evaluation.rollouts, ev.evaluation.metrics
    modes = {}
    for m, mode in enumerate(ev.modes):
        code = ro.outcome[s, m, :, :T]
        act = ro.activated[s, m, :, :T]
        dr = ro.delta_R[s, m, :, :T]
        dt = float(ev.baked.dt[s])
        modes[mode] = {
            "success_rate": float(me.u_scene[s, m]),
            "delta_R_mean": _none_if_nan(float(me.delta_R_mean[s, m])),
            "outcome": [[OUTCOMES[c] for c in row] for row in code.tolist()],
            "activated": [[ids[a] if a >= 0 else None for a in row] for row in act.tolist()],
            "delta_R": [[_none_if_nan(v) for v in row] for row in dr.tolist()],
            # Added later, so after the keys above (the object only grows).
            "time_to_activation_mean": _none_if_nan(float(me.time_mean[s, m])),
            "path_length_mean": _none_if_nan(float(me.path_length_mean[s, m])),
            "assistance": {k: _none_if_nan(float(v))
                           for k, v in zip(ASSISTANCE, me.assist_fraction[s, m], strict=True)},
            "time_to_activation": (ro.step[s, m, :, :T] * dt).tolist(),
            "path_length": ro.path_length[s, m, :, :T].tolist(),
            "assist_steps": ro.assist[s, m, :, :T].tolist(),
        }
    out["modes"] = modes
    user = ro.user
    if user is not None and user.shape[-1]:  # a population: each rollout's drawn values
        out["users"] = {k: user[s, 0, :, :T, i].tolist() for i, k in enumerate(POPULATED)}
    for m, mode in enumerate(ev.modes):
        modes[mode]["n_rollouts"] = int(me.n_rollouts[s, m])
        modes[mode]["outcome_counts"] = {o: int(c) for o, c in
                                         zip(OUTCOMES, me.outcome_counts[s, m], strict=True)}
    out["tasks_detail"] = tasks_json(ev, s)
    if ev.search is not None:
        out["optimize"] = optimize_json(ev, s)
    out["user"] = describe_user(r.settings)
    out["settings"] = r.settings.to_dict()
    out["provenance"] = ev.provenance
    return out


def task_counts(outcome: np.ndarray) -> np.ndarray:
    """(T, 5) counts of each outcome per task of one scene and mode's (N, T) outcomes."""
    return np.stack([np.sum(outcome == c, axis=0) for c in range(len(OUTCOMES))], axis=1)


def tasks_json(ev: Evaluated, s: int) -> list[dict]:
    """Per task of scene ``s``: who it is, its parameters (bounds, Shrinking's, the
    optimized mode's where it ran) and per mode its success rate (an exact fraction)
    and outcome counts."""
    r = ev.results[s]
    T = len(r.spaces)
    per_mode = {mode: task_counts(np.asarray(ev.evaluation.rollouts.outcome[s, m, :, :T]))
                for m, mode in enumerate(ev.modes)}
    out = []
    for t, (task, sp) in enumerate(zip(r.scene.tasks, r.spaces, strict=True)):
        n = len(sp.param_names)
        params = {"names": list(sp.param_names), "min": sp.q_min.tolist(),
                  "init": sp.q_init.tolist(), "shrinking": r.q_opt[t].tolist()}
        if ev.search is not None:
            params["optimized"] = [float(v) for v in ev.search.q[s, t, :n]]
        modes = {}
        for mode, counts in per_mode.items():
            c = counts[t]
            modes[mode] = {"success_rate": float(c[0]) / max(int(c.sum()), 1),
                           "outcome_counts": {o: int(k) for o, k in
                                              zip(OUTCOMES, c, strict=True)}}
        out.append({"id": task.id, "object": task.object,
                    "object_kind": r.scene.object(task.object).kind,
                    "template": task.template, "params": params, "modes": modes})
    return out


def optimized_params(ev: Evaluated, s: int) -> dict[str, dict[str, float]]:
    """The search's parameters of scene ``s``, per task id and parameter name."""
    r, q = ev.results[s], ev.searched().q
    return {sp.task.id: {n: float(q[s, t, k]) for k, n in enumerate(sp.param_names)}
            for t, sp in enumerate(r.spaces)}


def optimize_json(ev: Evaluated, s: int) -> dict:
    """The ``optimize`` block of the one-scene JSON (reference/outputs, model): the parameters
    chosen, and success on the search's starts, on the validation starts and on the
    held-out grid (where those modes were evaluated) side by side, and which candidate
    won."""

    f, st = ev.searched(), ev.results[s].settings
    held = {m: float(ev.evaluation.metrics.u_scene[s, i]) for i, m in enumerate(ev.modes)}
    return {
        "params": optimized_params(ev, s),
        "chosen": winner_name(int(f.winner[s]), st["optimize_candidates"]),
        "success": {
            "search": {"init": float(f.objective_init[s]),
                       "shrinking": float(f.objective_shrunk[s]),
                       "optimized": float(f.objective[s])},
            "validation": {"init": float(f.validation_init[s]),
                           "shrinking": float(f.validation_shrunk[s]),
                           "optimized": float(f.validation[s])},
            "held_out": {m: held[m] for m in ("baseline", "shrinking", "shacc", "optimized")
                         if m in held}},
        "objective": {"init": float(f.objective_init[s]),
                      "shrinking": float(f.objective_shrunk[s]),
                      "optimized": float(f.objective[s]),
                      "per_generation": [float(v) for v in f.history[s]]},
        "volume": float(f.volume[s]),
        "clutteredness": float(f.clutteredness[s]),
        "search_starts": ev.baked.opt_starts[s][ev.baked.opt_start_mask[s]].tolist(),
        "settings": {k: st[k] for k in ("optimize_starts", "optimize_seed",
                                        "optimize_population", "optimize_generations",
                                        "optimize_validation_starts",
                                        "optimize_validation_seed", "optimize_candidates",
                                        "optimize_selection")},
    }
