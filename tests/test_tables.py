"""The sweep's Arrow columns, made from NumPy buffers: the same arrays as ``pa.array``
gives, and no pandas imported on the way (its import cost each CPU worker's first
chunk 0.3-0.6 s)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from sweeps.analysis import tables

DTYPES = [np.int8, np.int16, np.int32, np.int64, np.uint8, np.float32, np.float64]


@given(data=st.data(), dtype=st.sampled_from(DTYPES), nulls=st.booleans(),
       n=st.integers(0, 70))
def test_numbers_equal_pa_array(data, dtype, nulls, n):
    values = data.draw(hnp.arrays(dtype, n))
    valid = data.draw(hnp.arrays(bool, n)) if nulls else None
    got = tables.numbers_array(values, valid)
    want = pa.array(values, mask=None if valid is None else ~valid)
    got.validate(full=True)
    assert got.type == want.type and got.null_count == want.null_count
    # NaN != NaN: compare the valid values' bytes and where the nulls are.
    assert got.is_null().to_pylist() == want.is_null().to_pylist()
    keep = np.ones(n, bool) if valid is None else valid
    np.testing.assert_array_equal(
        got.to_numpy(zero_copy_only=False)[keep].view(np.uint8),
        want.to_numpy(zero_copy_only=False)[keep].view(np.uint8))


@given(st.lists(st.one_of(st.none(), st.text()), max_size=40))
def test_strings_equal_pa_array(values):
    got = tables.strings_array(values)
    got.validate(full=True)
    assert got.equals(pa.array(values, pa.string()))


def test_numbers_refuse_what_they_cannot_copy():
    for bad in (np.zeros((2, 2)), np.array([True]), np.array([1], ">i4"),
                np.array(["a"])):
        with pytest.raises(TypeError, match="1-d array"):
            tables.numbers_array(bad)


def test_a_chunks_tables_import_no_pandas():
    code = textwrap.dedent("""
        import sys
        from types import SimpleNamespace
        import numpy as np
        from sweeps.analysis import tables
        S, M, N, T = 4, 3, 2, 3
        rng = np.random.default_rng(0)
        ro = SimpleNamespace(outcome=rng.integers(-1, 5, (S, M, N, T)).astype(np.int8),
                             activated=rng.integers(-1, T, (S, M, N, T)),
                             step=rng.integers(0, 99, (S, M, N, T)),
                             delta_R=rng.random((S, M, N, T)),
                             path_length=rng.random((S, M, N, T)),
                             assist=rng.integers(0, 50, (S, M, N, T, 4)))
        me = SimpleNamespace(u_scene=rng.random((S, M)),
                             delta_R_mean=np.where(rng.random((S, M)) < .5, np.nan, 1.0),
                             outcome_counts=rng.integers(0, 9, (S, M, 5)),
                             time_mean=rng.random((S, M)), path_length_mean=rng.random((S, M)),
                             assist_fraction=rng.random((S, M, 4)))
        labels = {"name": [f"s{i}" for i in range(S)], "n_tasks": [T] * S,
                  **{k: rng.random(S) for k in ("C_init", "C_final", "d", "h")},
                  **{k: [[f"{k}{t}" for t in range(T)]] * S for k in
                     ("task_ids", "object_ids", "object_kinds", "templates")},
                  "param_names": [[["radius"], ["length", "half_angle"], ["depth"]]] * S}
        params = {k: rng.random((S, T, 2)) for k in ("q_min", "q_init", "q_shrunk")}
        modes = ("baseline", "shrinking", "shacc")
        s = tables.scenes_table(0, {"v_max": 0.2, "start_grid": [2, 1]},
                                ("v_max", "omega_max", "start_grid"), modes, range(S),
                                labels, me)
        t = tables.tasks_table(0, modes, range(S), labels, params, ro.outcome)
        st = tables.starts_table(0, range(S), rng.random((S, N, 7)))
        r = tables.rollouts_table(0, modes, range(S), ro, np.full(S, 0.02))
        assert all(len(tables.parquet_bytes(x, n)) for x, n in
                   ((s, "scenes"), (t, "tasks"), (st, "starts"), (r, "rollouts")))
        assert s.column("set.omega_max").null_count == S
        assert s.column("shacc.assist_wrong").to_pylist() == list(me.assist_fraction[:, 2, 3])
        steps = np.array(r.column("steps").to_pylist())  # to_numpy() would import pandas
        np.testing.assert_allclose(r.column("time").to_pylist(), steps * 0.02, rtol=1e-6)
        assert s.column("set.start_grid").to_pylist() == [[2, 1]] * S
        assert t.column("q_optimized").null_count == S * T
        assert t.column("param_names").to_pylist()[:3] == [["radius"], ["length", "half_angle"],
                                                          ["depth"]]
        print("pandas" in sys.modules)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_parts_dictionary_encode_all_but_the_floats():
    """A part file keeps its values (floats and NaN included) and dictionary-encodes
    every column but the floating-point ones."""
    import io

    import pyarrow.parquet as pq

    rng = np.random.default_rng(1)
    t = pa.table({"steps": rng.integers(0, 300, 5000).astype(np.int32),
                  "mode": pa.DictionaryArray.from_arrays(
                      pa.array(rng.integers(0, 3, 5000).astype(np.int8)),
                      pa.array(["baseline", "shrinking", "shacc"])),
                  "delta_R": np.where(rng.random(5000) < .3, np.nan,
                                      rng.random(5000)).astype(np.float32)})
    data = tables.parquet_bytes(t)
    back = pq.read_table(io.BytesIO(data))
    assert back.select(["steps", "mode"]).equals(t.select(["steps", "mode"]))
    np.testing.assert_array_equal(back["delta_R"].to_numpy(), t["delta_R"].to_numpy())
    meta = pq.ParquetFile(io.BytesIO(data)).metadata.row_group(0)
    enc = {meta.column(i).path_in_schema: meta.column(i).encodings for i in range(3)}
    assert any("DICTIONARY" in e for e in enc["steps"]), enc
    assert any("DICTIONARY" in e for e in enc["mode"]), enc
    assert not any("DICTIONARY" in e for e in enc["delta_R"]), enc
