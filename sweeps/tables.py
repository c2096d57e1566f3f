"""A sweep's results as Arrow tables and a Parquet dataset (SPEC section 12).

``OUT/scenes/`` (one row per sweep point and scene) and ``OUT/rollouts/`` (one row
per rollout) hold one part file per chunk, ``part-000123.parquet``, written atomically
(a temporary name starting with ``.`` that every reader skips, then a rename). Read
either folder as one table with ``pyarrow.dataset.dataset(DIR)``,
``pandas.read_parquet(DIR)``, ``polars.read_parquet(f"{DIR}/*.parquet")`` or DuckDB's
``read_parquet('DIR/*.parquet')``.

The tables are built from the evaluation's arrays with pyarrow directly, with one
schema for every part of a sweep: a ``set.NAME`` column (the value as text, null
where the point leaves it at its default) for every setting any point sets.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from geometry_precompute.schema import OUTCOMES

PART = "part-{:06d}.parquet"


def part_path(out: Path, table: str, index: int) -> Path:
    return out / table / PART.format(index)


# The columns are Arrow arrays made from the NumPy arrays' buffers (no copy), not with
# ``pa.array``: its first call in a process imports pandas (pyarrow's pandas shim looks
# for pandas objects), 0.3-0.6 s of the first chunk a worker encodes, and a sweep's CPU
# workers each encode about one chunk (benchmarks/RESULTS.md).


def _numbers(values: np.ndarray, valid: np.ndarray | None = None) -> pa.Array:
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


def _strings(values) -> pa.Array:
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
    return pa.DictionaryArray.from_arrays(_numbers(codes.astype(np.int8, copy=False)),
                                          _strings(names))


def scenes_table(point_index: int, point: dict, setting_names, modes, scene_indices,
                 labels: dict, metrics) -> pa.Table:
    """One row per scene of one sweep point: identity, the precompute's numbers
    (``labels``: name, n_tasks, C_init, C_final, d, h per scene), and per mode the
    success rate, mean delta_R and the count of each outcome."""
    S = len(scene_indices)
    cols = {"point": _numbers(np.full(S, point_index, np.int64))}
    for k in setting_names:
        cols[f"set.{k}"] = _strings([str(point[k]) if k in point else None] * S)
    cols["scene_index"] = _numbers(np.asarray(scene_indices, np.int64))
    cols["scene"] = _strings(labels["name"])
    cols["n_tasks"] = _numbers(np.asarray(labels["n_tasks"], np.int64))
    for name in ("C_init", "C_final", "d", "h"):
        cols[name] = _numbers(np.asarray(labels[name], np.float64))
    for m, mode in enumerate(modes):
        cols[f"{mode}.success"] = _numbers(np.asarray(metrics.u_scene[:S, m], np.float64))
        dr = np.asarray(metrics.delta_R_mean[:S, m], np.float64)
        cols[f"{mode}.delta_R_mean"] = _numbers(dr, valid=np.isfinite(dr))
        for o, outcome in enumerate(OUTCOMES):
            cols[f"{mode}.n_{outcome}"] = _numbers(
                np.asarray(metrics.outcome_counts[:S, m, o], np.int64))
    return pa.table(cols)


def rollouts_table(point_index: int, modes, scene_indices, rollouts) -> pa.Table:
    """One row per rollout of one sweep point (padding left out), in the order scene,
    mode, start, task: scene, mode, start, intended task, outcome, activated task (-1:
    none), steps and delta_R."""
    S = len(scene_indices)
    outcome = np.asarray(rollouts.outcome)[:S]
    shape = outcome.shape
    keep = (outcome >= 0).reshape(-1)

    def flat(a, dtype):
        return np.asarray(a)[:S].reshape(-1)[keep].astype(dtype, copy=False)

    def index(axis: int, values, dtype):
        along = np.asarray(values, dtype).reshape([-1 if k == axis else 1 for k in range(4)])
        return np.broadcast_to(along, shape).reshape(-1)[keep]

    return pa.table({
        "point": _numbers(np.full(int(keep.sum()), point_index, np.int32)),
        "scene_index": _numbers(index(0, scene_indices, np.int32)),
        "mode": _dictionary(index(1, np.arange(shape[1]), np.int8), modes),
        "start": _numbers(index(2, np.arange(shape[2]), np.int32)),
        "task": _numbers(index(3, np.arange(shape[3]), np.int16)),
        "outcome": _dictionary(flat(outcome, np.int8), OUTCOMES),
        "activated": _numbers(flat(rollouts.activated, np.int16)),
        "steps": _numbers(flat(rollouts.step, np.int32)),
        "delta_R": _numbers(flat(rollouts.delta_R, np.float32)),
    })


def parquet_bytes(table: pa.Table) -> bytes:
    """A table as the bytes of one Parquet file (made where the table is, written by
    the machine that owns the output). Every column but the floating-point ones is
    dictionary-encoded: a float column (delta_R: some 290 000 distinct values in a
    1 000-scene chunk's 1.08 M rows) only fills a dictionary page to give it up. Without
    it, such a chunk's rollouts encode in 0.070 s instead of 0.094 s and take 3.81
    instead of 4.27 MB (the 2-core development machine)."""
    sink = io.BytesIO()
    pq.write_table(table, sink, use_dictionary=[
        f.name for f in table.schema if not pa.types.is_floating(f.type)])
    return sink.getvalue()
