"""The command line: output, JSON keys of SPEC section 12a, and bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import write_scene

from geometry_precompute import shipped_scene_paths
from sweeps.cli import main

SCENE = str(shipped_scene_paths()[8])  # mug-behind-two


def test_precompute_prints_and_writes_json(tmp_path, capsys):
    out = tmp_path / "p.json"
    assert main(["precompute", SCENE, "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for word in ("C_init", "C_final", "clusters", "radius", "time:"):
        assert word in text
    d = json.loads(out.read_text())
    assert list(d) == ["scene", "tasks", "clutteredness", "clusters", "shrinking", "metrics"]
    assert set(d["shrinking"]) == {"iterations", "params"}
    assert d["clutteredness"]["final"] <= d["clutteredness"]["init"]


def test_evaluate_json_has_exactly_spec_keys(tmp_path, capsys):
    out = tmp_path / "e.json"
    assert main(["evaluate", SCENE, "--set", "start_grid=[3,2]", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "baseline" in text and "shacc" in text and "success" in text
    d = json.loads(out.read_text())
    assert list(d) == ["scene", "tasks", "clutteredness", "clusters", "shrinking", "metrics",
                       "starts", "modes"]
    assert list(d["modes"]) == ["baseline", "shrinking", "shacc"]
    m = d["modes"]["shacc"]
    assert list(m) == ["success_rate", "delta_R_mean", "outcome", "activated", "delta_R"]
    assert len(d["starts"]) == 6 and len(d["starts"][0]) == 7
    assert len(m["outcome"]) == 6 and len(m["outcome"][0]) == 3
    for row_o, row_a, row_d in zip(m["outcome"], m["activated"], m["delta_R"], strict=True):
        for o, a, dr in zip(row_o, row_a, row_d, strict=True):
            assert o in ("success", "wrong", "ambiguous", "timeout")
            assert (dr is not None) == (o == "success")
            assert (a is None) == (o == "timeout")
            if o == "success":
                assert a in d["tasks"]
    n_success = sum(o == "success" for row in m["outcome"] for o in row)
    assert m["success_rate"] == pytest.approx(n_success / 18)


def test_bad_input_one_line_no_output(tmp_path):
    bad = write_scene(tmp_path, 'name = "x"\n[[objects]]\nid = "a"\nkind = "mug"\n'
                      'position = [0, 0, 0]\nradius = -1\n[[tasks]]\nid = "t"\nobject = "a"\n'
                      'template = "side_grasp"\n')
    out = tmp_path / "never.json"
    for cmd in (["precompute"], ["evaluate"]):
        proc = subprocess.run([sys.executable, "-m", "sweeps.cli", *cmd, str(bad),
                               "--json", str(out)], capture_output=True, text=True)
        assert proc.returncode == 2
        err = proc.stderr.strip()
        assert err.count("\n") == 0 and "Traceback" not in err
        assert str(bad) in err and "objects[a].radius" in err and "> 0" in err
        assert not out.exists()


def test_bad_set_value(capsys):
    assert main(["precompute", SCENE, "--set", "v_max=-1"]) == 2
    assert "v_max" in capsys.readouterr().err
    assert main(["precompute", SCENE, "--set", "bogus=1"]) == 2
