"""Tables from Python: ``Evaluated.tables()`` gives the four long tables of a sweep's
Parquet dataset for the same scenes (same columns, types and values), and
``Evaluated.start_extent`` the start grid's extent for the success-field plots."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.config import load_config
from sweeps.distributed.runner import run_sweep
from sweeps.pipeline import evaluate_results

SETTINGS = {"start_grid": [2, 3], "user_noise": {"uniform": [0.0, 0.4]}}


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("tables")
    folder = tmp / "scenes"
    folder.mkdir()
    for p in shipped_scene_paths()[:3]:
        shutil.copy(p, folder / p.name)
    (tmp / "sweep.toml").write_text(
        'name = "tables"\nmodes = ["baseline", "shacc"]\nchunk = 3\n'
        '[source]\nkind = "files"\npath = "scenes"\n'
        '[settings]\nstart_grid = [2, 3]\nuser_noise = { uniform = [0.0, 0.4] }\n')
    out = tmp / "out"
    summary = run_sweep(load_config(tmp / "sweep.toml"), out, tmp / "cache", workers=1,
                        progress=False)
    assert summary["status"] == "complete"
    scenes = [load_scene(p) for p in sorted(folder.glob("*.toml"))]
    ev = evaluate_results([precompute(s, s.settings(overrides=SETTINGS)) for s in scenes],
                          ("baseline", "shacc"))
    return ev, {name: pd.read_parquet(out / name) for name in ("scenes", "tasks", "starts",
                                                                 "rollouts")}


@pytest.mark.parametrize("name", ["scenes", "tasks", "starts", "rollouts"])
def test_the_tables_are_the_sweeps(both, name):
    ev, swept = both
    mine = ev.tables()[name]
    theirs = swept[name].drop(columns=[c for c in swept[name].columns
                                       if c.startswith("set.")])
    keys = [c for c in ("point", "scene_index", "mode", "start", "task") if c in mine]
    theirs = theirs.sort_values(keys, ignore_index=True)
    mine = mine.sort_values(keys, ignore_index=True)
    assert list(mine.columns) == list(theirs.columns)
    pd.testing.assert_frame_equal(mine, theirs, check_exact=False, rtol=0, atol=1e-5)
    if name == "rollouts":  # the population's draws are there, and outcomes are exact
        assert mine["user_noise"].between(0.0, 0.4).all() and mine["user_noise"].nunique() > 9
        assert (mine["outcome"] == theirs["outcome"]).all()


def test_the_start_extent_is_the_grid(both):
    ev, swept = both
    (y0, y1), (z0, z1) = ev.start_extent(0)
    st = swept["starts"][swept["starts"]["scene_index"] == 0]
    assert (y0, y1) == pytest.approx((st["y"].min(), st["y"].max()))
    assert (z0, z1) == pytest.approx((st["z"].min(), st["z"].max()))
    assert y0 < y1 and z0 < z1 and np.isfinite([y0, y1, z0, z1]).all()
