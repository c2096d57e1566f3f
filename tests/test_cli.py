"""The command line: output, the documented JSON keys, and bad input."""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

from conftest import write_scene

from geometry_precompute import load_scene, shipped_scene_paths
from sweeps.app.cli import main

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
    # The first documented keys, in order; then the keys added since (the object only grows).
    assert list(d)[:8] == ["scene", "tasks", "clutteredness", "clusters", "shrinking",
                           "metrics", "starts", "modes"]
    assert list(d)[8:] == ["tasks_detail", "user", "settings", "provenance"]
    assert list(d["modes"]) == ["baseline", "shrinking", "shacc"]
    m = d["modes"]["shacc"]
    assert list(m)[:5] == ["success_rate", "delta_R_mean", "outcome", "activated", "delta_R"]
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
    assert m["success_rate"] == n_success / 18  # an exact fraction, in double precision
    assert m["outcome_counts"]["success"] == n_success and m["n_rollouts"] == 18
    # Per task: who it is, its parameters, and per mode its own rate and counts.
    assert [t["id"] for t in d["tasks_detail"]] == d["tasks"]
    for t, task_id in enumerate(d["tasks"]):
        detail = d["tasks_detail"][t]
        assert detail["template"] == "side_grasp" and detail["params"]["names"] == ["radius"]
        assert detail["params"]["shrinking"] == [d["shrinking"]["params"][task_id]["radius"]]
        ok = sum(row[t] == "success" for row in m["outcome"])
        assert detail["modes"]["shacc"]["success_rate"] == ok / 6
        assert sum(detail["modes"]["shacc"]["outcome_counts"].values()) == 6
    assert "per task:" in text and d["tasks"][0] in text.split("per task:")[1]
    # Every setting used, and what produced it.
    assert d["settings"]["start_grid"] == [3, 2] and d["settings"]["v_max"] == 0.15
    prov = d["provenance"]
    assert prov["backend"] == "cpu" and prov["versions"]["jax"] and prov["command"]


def test_bad_input_one_line_no_output(tmp_path):
    bad = write_scene(tmp_path, 'name = "x"\n[[objects]]\nid = "a"\nkind = "mug"\n'
                      'position = [0, 0, 0]\nradius = -1\n[[tasks]]\nid = "t"\nobject = "a"\n'
                      'template = "side_grasp"\n')
    out = tmp_path / "never.json"
    for cmd in (["precompute"], ["evaluate"]):
        proc = subprocess.run([sys.executable, "-m", "sweeps", *cmd, str(bad),
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


def _one_line_error(capsys, argv, *words):
    """``argv`` fails with exit 2 and one stderr line holding ``words``."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    return err


def test_path_arguments_that_are_not_what_they_should_be(tmp_path, capsys):
    """Every command and every kind of path argument: missing, a folder where a file is
    expected, not UTF-8 text, a file where a folder is expected, a folder holding
    something else. One line, exit 2, nothing written."""
    folder = tmp_path / "folder"
    folder.mkdir()
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"name = \"\xff\xfe\x00\"\n")
    missing = tmp_path / "missing.toml"
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder\n")
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("a colleague's file\n")
    before = sorted(p.name for p in tmp_path.rglob("*"))

    for cmd in (["precompute"], ["export-mjcf"], ["render", "--out", str(tmp_path / "r.png")]):
        tail = [str(tmp_path / "x.xml")] if cmd == ["export-mjcf"] else []
        _one_line_error(capsys, [*cmd, str(folder), *tail], str(folder), "is a folder")
        _one_line_error(capsys, [*cmd, str(binary), *tail], str(binary), "not UTF-8")
        _one_line_error(capsys, [*cmd, str(missing), *tail], str(missing), "no such file")
    _one_line_error(capsys, ["evaluate", str(binary)], str(binary), "not UTF-8")
    _one_line_error(capsys, ["evaluate", str(folder)], str(folder), "no *.toml")
    for cfg in (folder, binary, missing):
        _one_line_error(capsys, ["sweep", str(cfg), "--out", str(tmp_path / "o")], str(cfg))

    # outputs: a folder where a file is expected, a file where a folder is expected
    _one_line_error(capsys, ["precompute", SCENE, "--json", str(folder)], "--json", "is a folder")
    _one_line_error(capsys, ["evaluate", SCENE, "--json", str(a_file / "x.json")], "--json",
                    "is a file, not a folder")
    _one_line_error(capsys, ["render", SCENE, "--out", str(folder)], "--out", "is a folder")
    _one_line_error(capsys, ["export-mjcf", SCENE, str(folder)], "OUT", "is a folder")
    _one_line_error(capsys, ["reproduce", "--out", str(a_file)], "--out", "is a file")
    _one_line_error(capsys, ["reproduce", "--out", str(other)], "--out", "notes.txt")
    sweep_cfg = str(Path(__file__).parents[1] / "sweeps" / "configs" / "laptop.toml")
    _one_line_error(capsys, ["sweep", sweep_cfg, "--out", str(a_file)], "--out", "is a file")
    _one_line_error(capsys, ["sweep", sweep_cfg, "--out", str(other)], "--out", "notes.txt")
    _one_line_error(capsys, ["sweep", sweep_cfg, "--out", str(tmp_path / "new"), "--cache",
                             str(a_file)], "--cache", "is a file")
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written


def test_damaged_sweep_marker_is_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "config.json").write_text("{ not json")
    sweep_cfg = str(Path(__file__).parents[1] / "sweeps" / "configs" / "laptop.toml")
    _one_line_error(capsys, ["sweep", sweep_cfg, "--out", str(out), "--cache",
                             str(tmp_path / "c")], "config.json", "damaged")


def test_several_scenes_one_batch_json_lines(tmp_path, capsys):
    paths = [str(p) for p in shipped_scene_paths()[:2]]
    folder = tmp_path / "more"
    folder.mkdir()
    for p in shipped_scene_paths()[8:10]:
        (folder / Path(p).name).write_text(Path(p).read_text())
    out = tmp_path / "all.jsonl"
    assert main(["evaluate", *paths, str(folder), "--set", "start_grid=[2,2]",
                 "--modes", "baseline", "shacc", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    lines = out.read_text().splitlines()
    objs = [json.loads(line) for line in lines]
    expected = [load_scene(p).name for p in [*paths, *sorted(folder.glob("*.toml"))]]
    assert [o["scene"] for o in objs] == expected
    assert "4 scenes" in text and "one batch" in text
    for o in objs:
        assert list(o["modes"]) == ["baseline", "shacc"] and len(o["starts"]) == 4
        # one table row per scene and mode
        # A row per mode in the outcome table and in the time and assistance table.
        assert sum(line.split()[:2] == [o["scene"], m] for line in text.splitlines()
                   for m in ("baseline", "shacc")) == 2 * 2


def test_one_scene_alone_equals_the_same_scene_in_a_batch(tmp_path):
    a, b = str(shipped_scene_paths()[8]), str(shipped_scene_paths()[10])
    one, two = tmp_path / "one.json", tmp_path / "two.jsonl"
    assert main(["evaluate", a, "--set", "start_grid=[3,2]", "--json", str(one)]) == 0
    assert main(["evaluate", b, a, "--set", "start_grid=[3,2]", "--json", str(two)]) == 0
    alone = json.loads(one.read_text())
    batched = [json.loads(x) for x in two.read_text().splitlines()][1]
    # Everything but the record of the command that produced it.
    assert alone.pop("provenance")["command"] == shlex.join(
        ["shacc", "evaluate", a, "--set", "start_grid=[3,2]", "--json", str(one)])
    assert batched.pop("provenance")["command"].startswith(f"shacc evaluate {shlex.quote(b)}")
    assert alone == batched


def test_several_scenes_need_one_start_grid(tmp_path, capsys):
    small = write_scene(tmp_path, Path(SCENE).read_text() + "\n[settings]\nstart_grid = [2, 2]\n")
    _one_line_error(capsys, ["evaluate", SCENE, str(small), "--json", str(tmp_path / "x")],
                    str(small), "start_grid", "same number of start poses")
    assert not (tmp_path / "x").exists()


def test_duplicate_modes_rejected(capsys):
    _one_line_error(capsys, ["evaluate", SCENE, "--modes", "baseline", "baseline"], "--modes")


def test_compilation_cache_is_written_then_reused(tmp_path):
    """A second `shacc evaluate` of the same shapes compiles nothing new: every program
    the first run stored is found, so the cache folder gains no file."""
    cache = tmp_path / "jax-cache"
    env = {**__import__("os").environ, "SHACC_COMPILE_CACHE": str(cache),
           "JAX_PLATFORMS": "cpu"}
    cmd = [sys.executable, "-m", "sweeps", "evaluate", SCENE, "--set", "start_grid=[2,2]"]
    first = subprocess.run(cmd, capture_output=True, text=True, env=env)
    assert first.returncode == 0, first.stderr
    stored = sorted(str(p.relative_to(cache)) for p in cache.rglob("*"))
    assert any(name.startswith("programs/export-evaluate-") for name in stored), stored
    assert any(name.startswith("xla/") for name in stored), stored
    second = subprocess.run(cmd, capture_output=True, text=True, env=env)
    assert second.returncode == 0, second.stderr
    assert sorted(str(p.relative_to(cache)) for p in cache.rglob("*")) == stored
    assert second.stdout.split("time:")[0] == first.stdout.split("time:")[0]  # same results
    off = subprocess.run(cmd, capture_output=True, text=True,
                         env={**env, "SHACC_COMPILE_CACHE": "off"})
    assert off.returncode == 0
    assert sorted(str(p.relative_to(cache)) for p in cache.rglob("*")) == stored


def test_cli_mode_names_are_the_evaluators():
    import shacc_jax
    from sweeps.app import cli

    assert cli.modes() == (shacc_jax.ALL_MODES, shacc_jax.MODES)


def test_cli_module_imports_nothing_heavy():
    """`shacc sweep` starts its local cluster's fork server before NumPy, dask and the
    rest are imported (sweeps.app.cli.main): importing the command line's module, and the
    cluster's, or the Ctrl-C handler and the fault reports, imports none of them (of the
    CPU half only the light modules: geometry_precompute loads its names lazily)."""
    heavy = ("numpy", "dask", "distributed", "jax", "pyarrow", "geometry_precompute.scene",
             "geometry_precompute.settings", "geometry_precompute.baking")
    # The parser too: a sweep's fork server starts once its arguments are parsed, before
    # this process imports NumPy and dask (sweeps.app.cli._run).
    code = (f"import sys, sweeps.app.cli, sweeps.distributed.cluster, "
            f"sweeps.distributed.interrupt, sweeps.distributed.faults; "
            f"sweeps.app.cli.build_parser().parse_args(['sweep', 'c.toml', '--out', 'o']); "
            f"print([m for m in {heavy!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_evaluate_command_does_not_import_scipy_stats():
    """`shacc evaluate` without a population of users never imports scipy.stats (its
    import is about a second, a third of a warm evaluate; the statistics serve reports
    and drawn users)."""
    code = ("import sys; from sweeps.app.cli import main; "
            f"main(['evaluate', {SCENE!r}]); print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "False"


def test_precompute_command_does_not_import_jax(tmp_path):
    code = ("import sys; from sweeps.app.cli import main; "
            f"main(['precompute', {SCENE!r}]); print('jax' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "False"
