"""A sweep's results as a typed, self-describing Parquet dataset (reference/outputs).

Four tables, each a folder of one part file per chunk, ``part-000123.parquet``,
written atomically (a temporary name starting with ``.`` that every reader skips, then
a rename); the scenes part is written last and marks the chunk done:

- ``OUT/scenes/``: one row per sweep point and scene;
- ``OUT/tasks/``: one row per sweep point, scene and task (who the task is, its
  parameters: initial, Shrinking's, the optimized mode's);
- ``OUT/starts/``: one row per sweep point, scene and start pose;
- ``OUT/rollouts/``: one row per rollout, which joins the other three by the keys
  (point, scene_index), (point, scene_index, task) and (point, scene_index, start).

Read a folder as one table with ``pyarrow.dataset.dataset(DIR)``,
``pandas.read_parquet(DIR)``, ``polars.read_parquet(f"{DIR}/*.parquet")`` or DuckDB's
``read_parquet('DIR/*.parquet')``; every reader gets the same typed columns. Every
column is described in :data:`COLUMNS` (type, unit, meaning), and each part carries
that description and its provenance (software versions, device, config hash) as
Parquet key-value metadata (``shacc.columns``, ``shacc.provenance``). A swept setting
is a typed ``set.NAME`` column (float64, int64, string, or a list for a pair such as
``start_grid``), null where the point leaves the setting at its default.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from geometry_precompute.population import POPULATED, text_of
from geometry_precompute.schema import ASSISTANCE, OUTCOMES
from geometry_precompute.settings import SPECS

PART = "part-{:06d}.parquet"
TABLES = ("scenes", "tasks", "starts", "rollouts")  # the scenes part is written last

# Every column of every table: (Arrow type, unit, meaning). NAME, MODE and OUTCOME stand
# for a setting's name, a mode and an outcome.
COLUMNS: dict[str, dict[str, tuple[str, str, str]]] = {
    "scenes": {
        "point": ("int64", "", "index of the sweep point (the config's order)"),
        "set.NAME": ("float64 | int64 | string | list", "the setting's",
                     "the point's value of a swept or fixed setting; null: its default; a "
                     "user setting that some point gives a population is text, e.g. "
                     "'uniform(0, 0.4)' or '0.2'"),
        "scene_index": ("int64", "", "index of the scene in the source"),
        "scene": ("string", "", "the scene's name"),
        "n_tasks": ("int64", "", "its number of tasks"),
        "C_init": ("float64", "", "clutteredness of the initial position spaces"),
        "C_final": ("float64", "", "clutteredness of the shrunk position spaces"),
        "d": ("float64", "m", "mean distance of the objects to their centroid"),
        "h": ("float64", "", "entropic clutteredness of the object positions"),
        "MODE.success": ("float64", "", "successful rollouts / rollouts (an exact fraction)"),
        "MODE.delta_R_mean": ("float64", "rad",
                              "mean orientation jump over successes; null without one"),
        "MODE.n_OUTCOME": ("int64", "", "rollouts that ended with OUTCOME"),
        "MODE.time_mean": ("float64", "s", "mean time to activation over successes; null "
                           "without one"),
        "MODE.path_length_mean": ("float64", "m", "mean path length over successes; null "
                                  "without one"),
        "MODE.assist_KIND": ("float64", "", "the fraction of all the rollouts' steps spent "
                             "under assistance KIND (none, scene, correct, wrong); null "
                             "where no rollout took a step"),
    },
    "tasks": {
        "point": ("int32", "", "sweep point"),
        "scene_index": ("int32", "", "scene"),
        "task": ("int16", "", "index of the task in its scene"),
        "task_id": ("string", "", "the task's id in the scene"),
        "object_id": ("string", "", "the id of the object it acts on"),
        "object_kind": ("string", "", "mug, cup, box or mesh"),
        "template": ("string", "", "the template's name: side_grasp, handle_grasp, top_grasp, "
                     "drawer_pull or one of a template file's"),
        "param_names": ("list<string>", "", "the shrinkable parameters, in order"),
        "q_min": ("list<float64>", "m or rad", "their lower bounds"),
        "q_init": ("list<float64>", "m or rad", "their initial values (upper bounds)"),
        "q_shrunk": ("list<float64>", "m or rad", "Shrinking's values"),
        "q_optimized": ("list<float64>", "m or rad",
                        "the optimized mode's values; null unless that mode ran"),
        "MODE.success": ("float64", "", "successful rollouts towards this task / its rollouts"),
        "MODE.n_OUTCOME": ("int64", "", "its rollouts that ended with OUTCOME"),
    },
    "starts": {
        "point": ("int32", "", "sweep point"),
        "scene_index": ("int32", "", "scene"),
        "start": ("int32", "", "index of the start pose (y-major on the grid)"),
        "x": ("float64", "m", "start position, world frame"),
        "y": ("float64", "m", ""), "z": ("float64", "m", ""),
        "qw": ("float64", "", "start orientation, unit quaternion (w, x, y, z)"),
        "qx": ("float64", "", ""), "qy": ("float64", "", ""), "qz": ("float64", "", ""),
    },
    "rollouts": {
        "point": ("int32", "", "sweep point"),
        "scene_index": ("int32", "", "scene"),
        "mode": ("dictionary<string>", "", "baseline, shrinking, shacc or optimized"),
        "start": ("int32", "", "start pose (joins starts)"),
        "task": ("int16", "", "intended task (joins tasks)"),
        "outcome": ("dictionary<string>", "", "success, wrong, ambiguous, timeout, collision"),
        "activated": ("int16", "", "the task that activated (-1: none)"),
        "steps": ("int32", "", "step of activation (max_steps on timeout)"),
        "delta_R": ("float32", "rad", "orientation jump at activation; null unless success"),
        "time": ("float32", "s", "time to activation, steps x dt (to the end where none)"),
        "path_length": ("float32", "m", "length of the commanded path until the end"),
        "assist_KIND": ("int32", "", "steps taken under assistance KIND (none, scene, "
                        "correct, wrong; they sum to steps)"),
        "user_noise": ("float32", "rad", "the user's noise this rollout drew; these seven "
                       "columns only in a sweep with a population of users"),
        "user_noise_tau": ("float32", "s", "its wandering hand's correlation time"),
        "user_tremor": ("float32", "m", "its tremor amplitude"),
        "user_tremor_hz": ("float32", "Hz", "its tremor frequency"),
        "user_switch": ("float32", "", "its probability of a change of mind"),
        "user_switch_at": ("float32", "", "where in the approach to the first task it turns"),
        "user_mode_switch_s": ("float32", "s", "its joystick's time to switch mode"),
    },
}


def _metadata(table: str, provenance: dict | None) -> dict[bytes, bytes]:
    meta = {b"shacc.table": table.encode(),
            b"shacc.columns": json.dumps({k: {"type": t, "unit": u, "doc": d}
                                          for k, (t, u, d) in COLUMNS[table].items()}).encode()}
    if provenance:
        meta[b"shacc.provenance"] = json.dumps(provenance, default=str).encode()
    return meta


def part_path(out: Path, table: str, index: int) -> Path:
    return out / table / PART.format(index)


# The columns are Arrow arrays made from the NumPy arrays' buffers (no copy), not with
# ``pa.array``: its first call in a process imports pandas (pyarrow's pandas shim looks
# for pandas objects), 0.3-0.6 s of the first chunk a worker encodes, and a sweep's CPU
# workers each encode about one chunk (benchmarks/RESULTS.md).


def numbers_array(values: np.ndarray, valid: np.ndarray | None = None) -> pa.Array:
    """A 1-d NumPy array of integers or floats as an Arrow array; ``valid``: False where
    the value is null."""
    a = np.ascontiguousarray(values)
    if a.ndim != 1 or a.dtype.kind not in "iuf" or not a.dtype.isnative:
        raise TypeError(f"expected a 1-d array of native integers or floats, got {a.dtype} "
                        f"{a.shape}")
    if valid is None:
        return pa.Array.from_buffers(pa.from_numpy_dtype(a.dtype), len(a),
                                     [None, pa.py_buffer(a)], null_count=0)
    valid = np.asarray(valid, bool)
    bitmap = pa.py_buffer(np.packbits(valid, bitorder="little"))
    return pa.Array.from_buffers(pa.from_numpy_dtype(a.dtype), len(a),
                                 [bitmap, pa.py_buffer(a)], null_count=int((~valid).sum()))


def strings_array(values) -> pa.Array:
    """Python strings (None: null) as an Arrow string array."""
    values = list(values)
    data = [b"" if v is None else str(v).encode() for v in values]
    offsets = np.zeros(len(data) + 1, np.int32)
    np.cumsum([len(d) for d in data], out=offsets[1:])
    valid = np.array([v is not None for v in values], bool)
    bitmap = None if valid.all() else pa.py_buffer(np.packbits(valid, bitorder="little"))
    return pa.Array.from_buffers(pa.string(), len(data), [
        bitmap, pa.py_buffer(offsets), pa.py_buffer(b"".join(data))],
        null_count=int((~valid).sum()))


def _dictionary(codes: np.ndarray, names) -> pa.DictionaryArray:
    return pa.DictionaryArray.from_arrays(numbers_array(codes.astype(np.int8, copy=False)),
                                          strings_array(names))


def _lists(rows: list, kind: str) -> pa.Array:
    """Lists of numbers ("int" or "float") or strings ("string"), None for a null
    list, from buffers as the other columns are (no ``pa.array``: see above)."""
    lengths = np.array([0 if r is None else len(r) for r in rows], np.int32)
    offsets = np.zeros(len(rows) + 1, np.int32)
    np.cumsum(lengths, out=offsets[1:])
    flat = [v for r in rows if r is not None for v in r]
    if kind == "string":
        values = strings_array(flat)
    else:
        values = numbers_array(np.array(flat, np.int64 if kind == "int" else np.float64))
    nulls = np.array([r is None for r in rows], bool)
    return pa.ListArray.from_arrays(numbers_array(offsets), values,
                                    mask=numbers_array(nulls.view(np.uint8)).cast(pa.bool_())
                                    if nulls.any() else None)


def _setting_column(spec_kind: str, values: list) -> pa.Array:
    """A ``set.NAME`` column of the setting's own type (null: the default)."""
    if spec_kind == "float":
        v = np.array([np.nan if x is None else float(x) for x in values])
        return numbers_array(v, valid=np.array([x is not None for x in values]))
    if spec_kind == "int":
        v = np.array([0 if x is None else int(x) for x in values], np.int64)
        return numbers_array(v, valid=np.array([x is not None for x in values]))
    if spec_kind in ("int_pair", "float_pair"):
        return _lists([None if x is None else list(x) for x in values],
                      "int" if spec_kind == "int_pair" else "float")
    return strings_array([None if x is None else str(x) for x in values])


def scenes_table(point_index: int, point: dict, setting_names, modes, scene_indices,
                 labels: dict, metrics, populations=()) -> pa.Table:
    """One row per scene of one sweep point: identity, the precompute's numbers
    (``labels``: name, n_tasks, C_init, C_final, d, h per scene), and per mode the
    success rate, mean delta_R and the count of each outcome. ``populations``: the
    settings whose column is text (some point of the sweep gives them a population)."""

    S = len(scene_indices)
    cols = {"point": numbers_array(np.full(S, point_index, np.int64))}
    for k in setting_names:
        cols[f"set.{k}"] = (strings_array([text_of(point.get(k))] * S) if k in populations
                            else _setting_column(SPECS[k].kind, [point.get(k)] * S))
    cols["scene_index"] = numbers_array(np.asarray(scene_indices, np.int64))
    cols["scene"] = strings_array(labels["name"])
    cols["n_tasks"] = numbers_array(np.asarray(labels["n_tasks"], np.int64))
    for name in ("C_init", "C_final", "d", "h"):
        cols[name] = numbers_array(np.asarray(labels[name], np.float64))
    for m, mode in enumerate(modes):
        cols[f"{mode}.success"] = numbers_array(np.asarray(metrics.u_scene[:S, m], np.float64))
        dr = np.asarray(metrics.delta_R_mean[:S, m], np.float64)
        cols[f"{mode}.delta_R_mean"] = numbers_array(dr, valid=np.isfinite(dr))
        for o, outcome in enumerate(OUTCOMES):
            cols[f"{mode}.n_{outcome}"] = numbers_array(
                np.asarray(metrics.outcome_counts[:S, m, o], np.int64))
        for name in ("time_mean", "path_length_mean"):
            v = np.asarray(getattr(metrics, name)[:S, m], np.float64)
            cols[f"{mode}.{name}"] = numbers_array(v, valid=np.isfinite(v))
        for k, kind in enumerate(ASSISTANCE):
            v = np.ascontiguousarray(metrics.assist_fraction[:S, m, k], np.float64)
            cols[f"{mode}.assist_{kind}"] = numbers_array(v, valid=np.isfinite(v))
    return pa.table(cols)


def tasks_table(point_index: int, modes, scene_indices, labels: dict, params: dict,
                outcome: np.ndarray) -> pa.Table:
    """One row per task of each scene of one sweep point: who it is (``labels``:
    task_ids, object_ids, object_kinds, templates, param_names per scene), its
    parameters (``params``: q_min, q_init, q_shrunk and optionally q_optimized, each
    (S, T, P)) and per mode its success rate and outcome counts (from ``outcome``,
    (S, M, N, T))."""
    S = len(scene_indices)
    n_tasks = np.asarray(labels["n_tasks"])
    pairs = [(s, t) for s in range(S) for t in range(int(n_tasks[s]))]
    si = np.array([p[0] for p in pairs], np.int64)
    ti = np.array([p[1] for p in pairs], np.int64)
    names = [labels["param_names"][s][t] for s, t in pairs]

    def q(key):
        if params.get(key) is None:
            return _lists([None] * len(pairs), "float")
        a = np.asarray(params[key], np.float64)
        return _lists([a[s, t, :len(n)].tolist() for (s, t), n in zip(pairs, names,
                                                                     strict=True)], "float")

    cols = {"point": numbers_array(np.full(len(pairs), point_index, np.int32)),
            "scene_index": numbers_array(np.asarray(scene_indices, np.int32)[si]),
            "task": numbers_array(ti.astype(np.int16))}
    for key in ("task_ids", "object_ids", "object_kinds", "templates"):
        cols[key.removesuffix("s") if key != "object_kinds" else "object_kind"] = strings_array(
            labels[key][s][t] for s, t in pairs)
    cols["param_names"] = _lists([list(n) for n in names], "string")
    for key in ("q_min", "q_init", "q_shrunk", "q_optimized"):
        cols[key] = q(key)
    out = np.asarray(outcome)[:S]
    for m, mode in enumerate(modes):
        per = out[si, m, :, ti]  # (rows, N)
        counts = np.stack([np.sum(per == c, axis=1) for c in range(len(OUTCOMES))], 1)
        n = counts.sum(axis=1)
        cols[f"{mode}.success"] = numbers_array(counts[:, 0] / np.maximum(n, 1))
        for o, name in enumerate(OUTCOMES):
            cols[f"{mode}.n_{name}"] = numbers_array(counts[:, o].astype(np.int64))
    return pa.table(cols)


def starts_table(point_index: int, scene_indices, starts: np.ndarray) -> pa.Table:
    """One row per start pose of each scene of one sweep point: position and
    orientation (``starts``: (S, N, 7) [x, y, z, qw, qx, qy, qz])."""
    S = len(scene_indices)
    a = np.asarray(starts, np.float64)[:S]
    N = a.shape[1]
    cols = {"point": numbers_array(np.full(S * N, point_index, np.int32)),
            "scene_index": numbers_array(np.repeat(np.asarray(scene_indices, np.int32), N)),
            "start": numbers_array(np.tile(np.arange(N, dtype=np.int32), S))}
    for k, name in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
        cols[name] = numbers_array(np.ascontiguousarray(a[:, :, k].reshape(-1)))
    return pa.table(cols)


def rollouts_table(point_index: int, modes, scene_indices, rollouts, dt) -> pa.Table:
    """One row per rollout of one sweep point (padding left out), in the order scene,
    mode, start, task: scene, mode, start, intended task, outcome, activated task (-1:
    none), steps, delta_R, the time (steps x the scene's ``dt``), the path length and
    the steps under each kind of assistance; where ``rollouts`` has a ``user`` array (S,
    M, N, T, U), the user settings each rollout drew."""
    S = len(scene_indices)
    outcome = np.asarray(rollouts.outcome)[:S]
    shape = outcome.shape
    keep = (outcome >= 0).reshape(-1)

    def flat(a, dtype):
        return np.asarray(a)[:S].reshape(-1)[keep].astype(dtype, copy=False)

    def index(axis: int, values, dtype):
        along = np.asarray(values, dtype).reshape([-1 if k == axis else 1 for k in range(4)])
        return np.broadcast_to(along, shape).reshape(-1)[keep]

    cols = {
        "point": numbers_array(np.full(int(keep.sum()), point_index, np.int32)),
        "scene_index": numbers_array(index(0, scene_indices, np.int32)),
        "mode": _dictionary(index(1, np.arange(shape[1]), np.int8), modes),
        "start": numbers_array(index(2, np.arange(shape[2]), np.int32)),
        "task": numbers_array(index(3, np.arange(shape[3]), np.int16)),
        "outcome": _dictionary(flat(outcome, np.int8), OUTCOMES),
        "activated": numbers_array(flat(rollouts.activated, np.int16)),
        "steps": numbers_array(flat(rollouts.step, np.int32)),
        "delta_R": numbers_array(dr := flat(rollouts.delta_R, np.float32), valid=np.isfinite(dr)),
        "time": numbers_array(flat(np.asarray(rollouts.step, np.float64)
                                   * np.asarray(dt, np.float64)[:S, None, None, None],
                                   np.float32)),
        "path_length": numbers_array(flat(rollouts.path_length, np.float32)),
    }
    for i, kind in enumerate(ASSISTANCE):
        cols[f"assist_{kind}"] = numbers_array(flat(np.asarray(rollouts.assist)[..., i],
                                                    np.int32))
    user = getattr(rollouts, "user", None)
    if user is not None:
        for i, k in enumerate(POPULATED):
            cols[k] = numbers_array(flat(np.asarray(user)[..., i], np.float32))
    return pa.table(cols)


def parquet_bytes(table: pa.Table, name: str | None = None,
                  provenance: dict | None = None) -> bytes:
    """A table as the bytes of one Parquet file (made where the table is, written by
    the machine that owns the output). Every column but the floating-point ones is
    dictionary-encoded: a float column (delta_R: some 290 000 distinct values in a
    1 000-scene chunk's 1.08 M rows) only fills a dictionary page to give it up. Without
    it, such a chunk's rollouts encode in 0.070 s instead of 0.094 s and take 3.81
    instead of 4.27 MB (the 2-core development machine)."""
    if name is not None:  # the columns' description and the provenance, in the file
        table = table.replace_schema_metadata(_metadata(name, provenance))
    sink = io.BytesIO()
    pq.write_table(table, sink, use_dictionary=[
        f.name for f in table.schema if not pa.types.is_floating(f.type)])
    return sink.getvalue()
