"""Outputs that behave like files should, and a command line that explains itself:
symlinks, pipes and devices, file modes, stdout kept for results, a lock on a sweep's
folder, `shacc settings` and `--version`, arguments checked before any work, Ctrl-C,
and the Python API's errors."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import pytest
from conftest import process_group_members

from geometry_precompute import SPECS, InputError, load_scene, precompute, shipped_scene_paths
from geometry_precompute.scene import SceneWarning
from sweeps.app.cli import main
from sweeps.output import write_atomic

SCENE = str(shipped_scene_paths()[8])
ROOT = Path(__file__).parents[1]


def _shacc(*args, **kw):
    return subprocess.run([sys.executable, "-m", "sweeps", *args], capture_output=True,
                          text=True, **kw)


def test_regular_file_gets_the_umask_mode(tmp_path):
    old = os.umask(0o022)
    try:
        write_atomic(tmp_path / "a.json", b"{}\n")
        write_atomic(tmp_path / "a.json", b"{}\n")  # replacing keeps the umask mode too
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.json").stat().st_mode) == 0o644


def test_symlink_is_followed_not_replaced(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old\n")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_atomic(link, b"new\n")
    assert link.is_symlink() and target.read_text() == "new\n"


def test_fifo_and_device_are_written_directly(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    write_atomic(fifo, b"through the pipe\n")
    reader.join(10)
    assert got == [b"through the pipe\n"] and stat.S_ISFIFO(fifo.stat().st_mode)
    write_atomic("/dev/null", b"nothing\n")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
    assert not list(tmp_path.glob(".*.tmp")) and not list(Path("/dev").glob(".null.*.tmp"))


def test_json_to_stdout_parses_and_the_summary_goes_to_stderr():
    out = _shacc("evaluate", SCENE, "--set", "start_grid=[2,2]", "--modes", "baseline",
                 "--json", "-")
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["scene"] == "mug-behind-two" and "baseline" in out.stderr
    pre = _shacc("precompute", SCENE, "--json", "-")
    assert json.loads(pre.stdout)["scene"] == "mug-behind-two" and "C_init" in pre.stderr


def test_settings_command_version_and_help_defaults():
    out = _shacc("settings", "--json")
    rows = json.loads(out.stdout)
    assert [r["name"] for r in rows] == list(SPECS)
    assert all(r["meaning"] and r["rule"] and r["default"] for r in rows)
    table = _shacc("settings").stdout
    assert "side_grasp.radius_init" in table and "0.2" in table
    assert _shacc("--version").stdout.startswith("shacc ")
    helps = {cmd: " ".join(_shacc(cmd, "--help").stdout.split())
             for cmd in ("render", "evaluate", "reproduce")}
    assert "(default: 1280)" in helps["render"] and "(default: shacc)" in helps["render"]
    assert "default: ['baseline', 'shrinking', 'shacc']" in helps["evaluate"]
    assert "(default: reproduce_out)" in helps["reproduce"]
    assert all("shacc settings" in h for h in helps.values())


@pytest.mark.parametrize("argv,words", [
    (["reproduce", "--seed", "-1"], ["--seed", "[0, 2147483647]", "got -1"]),
    (["reproduce", "--workers", "0"], ["--workers", "[1, 1024]"]),
    (["reproduce", "--random-scenes", "-3"], ["--random-scenes"]),
    (["render", SCENE, "--out", "x.png", "--width", "100000"], ["--width", "8192"]),
    (["evaluate", SCENE, "--modes", "baseline", "baseline"], ["--modes", "once"]),
])
def test_bad_arguments_one_line(argv, words, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    try:
        code = main(argv)  # checked by the command: InputError, exit 2
    except SystemExit as e:  # checked by the parser
        code = e.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0 and "Traceback" not in err, err
    assert all(w in err for w in words), err
    assert not list(tmp_path.iterdir())


def test_sweep_bad_workers_leaves_nothing(tmp_path):
    out = tmp_path / "o"
    res = _shacc("sweep", str(ROOT / "sweeps" / "configs" / "laptop.toml"), "--out", str(out),
                 "--workers", "-1")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and not out.exists()


def test_second_sweep_into_a_locked_folder_is_refused(tmp_path):
    from sweeps.config import load_config
    from sweeps.distributed.runner import folder_lock, run_sweep

    cfg_path = tmp_path / "s.toml"
    cfg_path.write_text('name = "l"\n[source]\nkind = "random"\ncount = 1\ntasks = [2, 2]\n'
                        "[settings]\nstart_grid = [2, 2]\n")
    out = tmp_path / "out"
    out.mkdir()
    with folder_lock(out), pytest.raises(InputError, match="another shacc sweep"):
        run_sweep(load_config(cfg_path), out, tmp_path / "cache", workers=1, progress=False)
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_sweep_stdout_is_its_json_summary(tmp_path):
    cfg_path = tmp_path / "s.toml"
    cfg_path.write_text('name = "j"\n[source]\nkind = "random"\ncount = 2\ntasks = [2, 3]\n'
                        "[settings]\nstart_grid = [2, 2]\n")
    res = _shacc("sweep", str(cfg_path), "--out", str(tmp_path / "o"), "--cache",
                 str(tmp_path / "c"), "--workers", "1")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["status"] == "complete"  # nothing else on stdout


def test_scene_folder_with_two_start_grids_is_refused_before_any_file(tmp_path):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    text = Path(SCENE).read_text()
    (scenes / "a.toml").write_text(text)
    (scenes / "b.toml").write_text(text + "\n[settings]\nstart_grid = [3, 3]\n")
    cfg = tmp_path / "s.toml"
    cfg.write_text('name = "g"\n[source]\nkind = "files"\npath = "scenes"\n')
    res = _shacc("sweep", str(cfg), "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "different start grids" in res.stderr
    assert not (tmp_path / "o").exists()


def test_dry_run_does_not_build_random_scenes():
    from sweeps.config import parse_config
    from sweeps.distributed.runner import dry_run

    cfg = parse_config({"name": "big", "source": {"kind": "random", "count": 10_000_000}},
                       "<test>", ROOT)
    t = time.perf_counter()
    info = dry_run(cfg, workers=16)
    assert time.perf_counter() - t < 30
    assert info["scenes"] == 10_000_000 and info["estimated_total_seconds"] > 0
    assert 5 * 10_000_000 * 108 <= info["rollouts"] <= 10 * 10_000_000 * 108


def test_dry_run_of_a_million_points_is_refused_in_one_line(tmp_path, capsys):
    """Axes whose product is 10^6 points: one line, exit 2, before anything is built."""
    cfg = tmp_path / "big.toml"
    values = lambda lo: ", ".join(f"{lo + 0.01 * i:.2f}" for i in range(10))  # noqa: E731
    cfg.write_text('name = "big"\n[source]\nkind = "random"\ncount = 10\n[axes]\n'
                   + "".join(f"{k} = [{values(lo)}]\n" for k, lo in (
                       ("v_max", 0.1), ("omega_max", 1.0), ("dt", 0.01),
                       ("shrink_step", 0.01), ("activation_tol", 0.001), ("user_noise", 0.0))))
    assert main(["sweep", str(cfg), "--dry-run"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1, out.err
    assert "give 1000000 points, more than 100000" in out.err


def test_dry_run_budgets_collision_checks(tmp_path):
    """The per-chunk memory estimate follows the memory model: a point with collision
    checks needs more than the same point without, for random and for file sources."""
    from shacc_jax.runplan import bytes_per_rollout
    from sweeps.config import parse_config
    from sweeps.distributed.cluster import local_gpus
    from sweeps.distributed.runner import dry_run

    platform = "gpu" if local_gpus() else "cpu"
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "a.toml").write_text(Path(SCENE).read_text())
    sources = {"random": {"kind": "random", "count": 4},
               "files": {"kind": "files", "path": str(scenes)}}
    for kind, source in sources.items():
        mb = {c: dry_run(parse_config({"name": "c", "source": source,
                                       "settings": {"collision": c}}, "<test>", ROOT),
                         workers=1)["estimated_memory_per_chunk_MB"]
              for c in ("off", "on")}
        assert mb["off"] > 0, kind
        assert mb["on"] / mb["off"] == pytest.approx(
            bytes_per_rollout(True, platform) / bytes_per_rollout(False, platform)
        ), kind


def test_generator_range_is_checked(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('name = "t"\n[source]\nkind = "random"\ncount = 3\ntasks = [5, 200]\n')
    res = _shacc("sweep", str(cfg), "--dry-run")
    assert res.returncode == 2 and "source.tasks" in res.stderr and "<= 30" in res.stderr


def test_ctrl_c_ends_with_one_line_and_no_process_left(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('name = "c"\n[source]\nkind = "random"\ncount = 400\ntasks = [8, 10]\n')
    proc = subprocess.Popen([sys.executable, "-m", "sweeps", "sweep", str(cfg), "--out",
                             str(tmp_path / "o"), "--cache", str(tmp_path / "c"),
                             "--workers", "2"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and not list((tmp_path / "c").glob("*.json")):
        time.sleep(0.2)  # wait until the precompute workers are at work
    assert list((tmp_path / "c").glob("*.json")), "the sweep never started precomputing"
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "interrupted" and "Traceback" not in err, err
    time.sleep(1)
    assert process_group_members(proc.pid) == []


def test_public_precompute_raises_input_error():
    scene = load_scene(SCENE)
    with pytest.raises(InputError, match=r"v_max: must be in \(0, 100\]"):
        precompute(scene, {"v_max": -1})
    with pytest.raises(InputError, match="unknown setting"):
        precompute(scene, {"nope": 1})
    assert precompute(scene, {"side_grasp": {"radius_init": 0.18}}).settings[
        "side_grasp.radius_init"] == 0.18


def test_legal_oddities_are_warned_once(tmp_path):
    p = tmp_path / "odd.toml"
    p.write_text("""name = "odd"
[[objects]]
id = "m"
kind = "mug"
position = [0, 0, 0]
[[objects]]
id = "c"
kind = "cup"
position = [0.2, 0, 0]
yaw = 3.14159
[[objects]]
id = "m2"
kind = "mug"
position = [0.105, 0.0, 0]
[[tasks]]
id = "a"
object = "m"
template = "side_grasp"
[[tasks]]
id = "b"
object = "m"
template = "side_grasp"
[[tasks]]
id = "h"
object = "c"
template = "handle_grasp"
""")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(p)
    msgs = [str(w.message) for w in caught if issubclass(w.category, SceneWarning)]
    assert len(msgs) == 2
    assert "tasks[b]" in msgs[0] and "'a'" in msgs[0] and "ambiguous" in msgs[0]
    assert "tasks[h]" in msgs[1] and "inside object 'm2'" in msgs[1]
    res = _shacc("precompute", str(p))
    assert res.returncode == 0
    assert [line for line in res.stderr.splitlines() if line.startswith("warning:")] == \
        [f"warning: {m}" for m in msgs]
