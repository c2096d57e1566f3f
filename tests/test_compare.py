"""``shacc compare``: paired differences of two runs of the same scenes, and the exit
status a CI job reads."""

from __future__ import annotations

import json

import pytest

from geometry_precompute import InputError, shipped_scene_paths
from sweeps.analysis.compare import REGRESSION, compare, parse_fail_if
from sweeps.app.cli import main

SCENES = [str(p) for p in shipped_scene_paths()[2:6]]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The same four scenes, before and after making the side grasps' spaces smaller."""
    tmp = tmp_path_factory.mktemp("compare")
    a, b = tmp / "a.jsonl", tmp / "b.jsonl"
    assert main(["evaluate", *SCENES, "--json", str(a)]) == 0
    assert main(["evaluate", *SCENES, "--set", "side_grasp.radius_init=0.16",
                 "--json", str(b)]) == 0
    return a, b


def test_paired_rows_per_mode_and_metric(runs, capsys):
    a, b = runs
    result = compare(a, b, n_boot=2000)
    rows = {(r["mode"], r["metric"]): r for r in result["rows"]}
    assert [r["mode"] for r in result["rows"]][::2] == ["baseline", "shrinking", "shacc"]
    lines_a = [json.loads(x) for x in a.read_text().splitlines()]
    lines_b = [json.loads(x) for x in b.read_text().splitlines()]
    for mode in ("baseline", "shacc"):
        ua = [d["modes"][mode]["success_rate"] for d in lines_a]
        ub = [d["modes"][mode]["success_rate"] for d in lines_b]
        r = rows[(mode, "success")]
        assert r["n_scenes"] == 4 and r["a"] == pytest.approx(sum(ua) / 4)
        assert r["diff"] == pytest.approx(sum(ub) / 4 - sum(ua) / 4)
        assert r["ci"][0] <= r["diff"] <= r["ci"][1]
    # Against itself: nothing changes, and no rule can fail.
    same = compare(a, a, n_boot=500)
    assert all(r["diff"] in (0.0, None) for r in same["rows"]) and not same["tasks_changed"]


def test_fail_if_exit_status(runs, capsys, tmp_path):
    a, b = runs
    out = tmp_path / "c.json"
    # Smaller initial side grasps raise the baseline's success on these scenes: a drop
    # rule does not fire, a rule on the rise of ShaCC's delta_R does.
    assert main(["compare", str(a), str(b), "--bootstrap", "2000",
                 "--fail-if", "baseline.success:-0.02"]) == 0
    status = main(["compare", str(a), str(b), "--bootstrap", "2000", "--json", str(out),
                   "--fail-if", "shacc.delta_R_mean:+0.02"])
    assert status == REGRESSION
    printed = capsys.readouterr().out
    assert "FAILED: point 0 shacc delta_R_mean" in printed
    assert json.loads(out.read_text())["failed"]
    assert parse_fail_if("success:-0.02") == (None, "success", -0.02)
    for bad in ("success", "speed:-1", "success:0", "success:abc"):
        with pytest.raises(InputError, match="--fail-if"):
            parse_fail_if(bad)


def test_different_scenes_are_refused(runs, tmp_path):
    a, _ = runs
    other = tmp_path / "o.jsonl"
    assert main(["evaluate", SCENES[0], "--json", str(other)]) == 0
    with pytest.raises(InputError, match="different scenes"):
        compare(a, other)
    assert main(["compare", str(a), str(tmp_path / "missing.jsonl")]) == 2
