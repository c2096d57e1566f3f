"""``shacc compare``: paired differences of two runs of the same scenes, and the exit
status a CI job reads."""

from __future__ import annotations

import json

import numpy as np
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
    assert [r["mode"] for r in result["rows"]][::8] == ["baseline", "shrinking", "shacc"]
    lines_a = [json.loads(x) for x in a.read_text().splitlines()]
    lines_b = [json.loads(x) for x in b.read_text().splitlines()]
    for mode in ("baseline", "shacc"):
        ua = [d["modes"][mode]["success_rate"] for d in lines_a]
        ub = [d["modes"][mode]["success_rate"] for d in lines_b]
        r = rows[(mode, "success")]
        assert r["n_scenes"] == 4 and r["a"] == pytest.approx(sum(ua) / 4)
        assert r["diff"] == pytest.approx(sum(ub) / 4 - sum(ua) / 4)
        assert r["ci"][0] <= r["diff"] <= r["ci"][1]
        ta = [d["modes"][mode]["time_to_activation_mean"] for d in lines_a]
        r = rows[(mode, "time_mean")]
        assert r["a"] == pytest.approx(np.nanmean(np.array(ta, float)))
    # Against itself: nothing changes, and no rule can fail.
    same = compare(a, a, n_boot=500)
    assert all(r["diff"] in (0.0, None) for r in same["rows"]) and not same["tasks_changed"]


def test_fail_if_exit_status(runs, capsys, tmp_path):
    a, b = runs
    out = tmp_path / "c.json"
    # Smaller initial side grasps raise ShaCC's delta_R on these scenes: a rule that it
    # rise by at most 0.02 rad fails, and the verdict and JSON say so.
    status = main(["compare", str(a), str(b), "--bootstrap", "2000", "--json", str(out),
                   "--fail-if", "shacc.delta_R_mean:+0.02"])
    assert status == REGRESSION
    printed = capsys.readouterr().out
    assert "FAIL shacc.delta_R_mean:+0.02 (non-inferiority) point 0 shacc delta_R_mean" \
        in printed
    saved = json.loads(out.read_text())
    assert saved["passed"] is False and saved["verdicts"][0]["worst_scenes"]
    assert parse_fail_if("success:-0.02") == (None, "success", -0.02)
    for bad in ("success", "speed:-1", "success:0", "success:abc"):
        with pytest.raises(InputError, match="--fail-if"):
            parse_fail_if(bad)


def _runs(folder, name: str, success: list[float], time: list[float] | None = None):
    """An evaluate --json file of constructed results: one scene a line, ShaCC only."""
    path = folder / name
    path.write_text("".join(json.dumps({"scene": f"s{i}", "modes": {"shacc": {
        "success_rate": u, "delta_R_mean": 1.0,
        "time_to_activation_mean": None if time is None else time[i],
        "assistance": {"none": 0.8, "scene": 0.2, "correct": 0.0, "wrong": 0.0}}}}) + "\n"
        for i, u in enumerate(success)))
    return path


def readme_gate_command() -> list[str]:
    """The compare command of the README's CI example, as arguments of ``shacc``."""
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    line = next(x for x in readme.splitlines() if "shacc compare before.jsonl" in x)
    return line.split(".venv/bin/shacc ", 1)[1].split()


@pytest.mark.parametrize("case", ["straddles", "improves", "drops"])
def test_the_readme_gate_on_constructed_results(case, tmp_path, capsys, monkeypatch):
    """The README's CI command on paired results built to land where wanted: a drop
    whose interval straddles the margin fails the non-inferiority gate and passes the
    lenient one; a clear rise passes both; a clear drop fails both."""
    rng = np.random.default_rng(5)
    before = np.round(rng.uniform(0.6, 0.9, 12), 4)
    change = {"straddles": np.array([0.06, -0.12, 0.03, -0.09, 0.0, -0.06, 0.05, -0.10,
                                     0.02, -0.05, 0.04, -0.04]),  # mean -0.025, wide
              "improves": rng.normal(0.1, 0.01, 12),
              "drops": rng.normal(-0.1, 0.01, 12)}[case]
    monkeypatch.chdir(tmp_path)
    _runs(tmp_path, "before.jsonl", list(before))
    _runs(tmp_path, "after.jsonl", list(np.round(before + change, 4)))
    args = readme_gate_command()
    assert "--fail-if" in args and args[0] == "compare"
    margin = float(args[args.index("--fail-if") + 1].rsplit(":", 1)[1])
    result = compare("before.jsonl", "after.jsonl", n_boot=10_000)
    row = next(r for r in result["rows"] if r["mode"] == "shacc" and r["metric"] == "success")
    lo, hi = row["ci"]
    status = main(args)
    printed = capsys.readouterr().out
    lenient = main([*args[:args.index("--fail-if")], "--fail-if-shown",
                    args[args.index("--fail-if") + 1]])
    if case == "straddles":
        assert lo < margin < hi  # built so; the gate's reading decides
        assert status == REGRESSION and lenient == 0
        assert "FAIL shacc.success:-0.02 (non-inferiority)" in printed
        assert "scenes would decide" in printed or "itself is past" in printed
        assert "moved most against it: s" in printed
    elif case == "improves":
        assert lo > 0 and status == 0 and lenient == 0
        assert "PASS shacc.success:-0.02 (non-inferiority) point 0 shacc success: " \
            f"B - A = {row['diff']:+.4f} [{lo:+.4f}, {hi:+.4f}], margin -0.02, 12 scenes" \
            in printed
    else:
        assert hi < margin and status == REGRESSION and lenient == REGRESSION


def test_gate_on_time_and_assistance_and_its_faults(tmp_path, capsys):
    """Time to activation and the assistance shares are metrics to gate on; a rule that
    matches no mode, or a single scene (no interval), is not a pass."""
    a = _runs(tmp_path, "a.jsonl", [0.8] * 5, time=[3.0, 3.1, 2.9, 3.2, 3.0])
    b = _runs(tmp_path, "b.jsonl", [0.8] * 5, time=[4.0, 4.2, 3.9, 4.1, 4.0])
    assert main(["compare", str(a), str(b), "--fail-if", "time_mean:+0.2"]) == REGRESSION
    assert "FAIL time_mean:+0.2 (non-inferiority) point 0 shacc time_mean" in \
        capsys.readouterr().out
    assert main(["compare", str(a), str(b), "--fail-if", "assist_scene:-0.05"]) == 0
    assert main(["compare", str(a), str(b), "--fail-if", "baseline.success:-0.02"]) == 2
    one_a, one_b = _runs(tmp_path, "1a.jsonl", [0.8]), _runs(tmp_path, "1b.jsonl", [0.9])
    assert main(["compare", str(one_a), str(one_b), "--fail-if", "success:-0.02"]) == REGRESSION
    assert "no interval (1 scene(s)" in capsys.readouterr().out


def test_different_scenes_are_refused(runs, tmp_path):
    a, _ = runs
    other = tmp_path / "o.jsonl"
    assert main(["evaluate", SCENES[0], "--json", str(other)]) == 0
    with pytest.raises(InputError, match="different scenes"):
        compare(a, other)
    assert main(["compare", str(a), str(tmp_path / "missing.jsonl")]) == 2
