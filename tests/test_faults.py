"""Every fault ends in one line: writes that fail, signals, slow refusals, caches that
are damaged or read-only, sweep folders of the wrong kind. The commands run as a user
runs them (the console script, in its own process group)."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import process_group_members

from geometry_precompute import DEFAULTS, InputError, load_scene, random_scene
from geometry_precompute.cache import cached, random_key, scene_key

ROOT = Path(__file__).parents[1]
SCENE = str(ROOT / "geometry_precompute" / "scenes" / "09_mug_behind_two.toml")
SHACC = str(Path(sys.executable).parent / "shacc")


def shacc(*args, env=None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([SHACC, *args], capture_output=True, text=True, timeout=600,
                          env={**os.environ, **(env or {})}, **kw)


def assert_one_line(res, status: int, *words: str) -> str:
    err = res.stderr.strip()
    assert res.returncode == status, (res.returncode, err)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    line = err.splitlines()[-1]
    assert line.startswith("error: ") and all(w in line for w in words), err
    return line


# --- writes that fail ---------------------------------------------------------------

@pytest.mark.parametrize("command", [
    ["precompute", SCENE, "--json", "{out}"],
    ["export-mjcf", SCENE, "{out}"],
    ["render", SCENE, "--out", "{out}"],
])
def test_a_full_disk_is_one_line_naming_the_path(command):
    res = shacc(*[a.replace("{out}", "/dev/full") for a in command])
    assert_one_line(res, 1, "/dev/full", "cannot write", "No space left on device")


def test_stdout_to_a_full_disk_is_one_line():
    with open("/dev/full", "w") as full:
        res = subprocess.run([SHACC, "settings"], stdout=full, stderr=subprocess.PIPE,
                             text=True, timeout=120)
    assert_one_line(res, 1, "<stdout>", "No space left on device")


@pytest.mark.parametrize("args", [["settings"], ["settings", "--json"], ["--version"],
                                  ["--help"], ["precompute", SCENE, "--json", "-"]])
def test_a_closed_stdout_is_one_line(args):
    """``shacc settings >&-``: stdout closed before the command began (Python's
    sys.stdout is None) is the machine's fault, in one line, not an internal error (or,
    for --version and --help, a silent success)."""
    res = subprocess.run([SHACC, *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True, timeout=120, preexec_fn=lambda: os.close(1))
    assert_one_line(res, 1, "<stdout>: cannot write (standard output is closed)")


def test_a_closed_stderr_keeps_the_exit_status(tmp_path):
    bad = tmp_path / "missing.toml"
    res = subprocess.run([SHACC, "precompute", str(bad)], capture_output=True, timeout=120,
                         preexec_fn=lambda: os.close(2))
    assert res.returncode == 2 and res.stdout == b""
    res = subprocess.run([SHACC, "settings"], capture_output=True, timeout=120,
                         preexec_fn=lambda: os.close(2))
    assert res.returncode == 0 and b"v_max" in res.stdout


def test_files_opened_with_stdout_closed_do_not_take_its_place(tmp_path):
    """With fd 1 closed, the first file a command opens would get number 1, and what
    the command prints would land in it: the written JSON stays the JSON."""
    out = tmp_path / "p.json"
    res = subprocess.run([SHACC, "precompute", SCENE, "--json", str(out)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                         timeout=120, preexec_fn=lambda: os.close(1))
    assert res.returncode == 1 and "standard output is closed" in res.stderr
    if out.exists():  # written before the summary failed: it is whole, and only JSON
        json.loads(out.read_text())


def test_a_full_stderr_loses_the_summary_not_the_json():
    """``--json -`` puts the summary on stderr; a stderr that cannot be written loses
    the summary, and the JSON on stdout is still whole."""
    with open("/dev/full", "w") as full:
        res = subprocess.run([SHACC, "precompute", SCENE, "--json", "-"], stdout=subprocess.PIPE,
                             stderr=full, text=True, timeout=120)
    assert res.returncode == 0 and json.loads(res.stdout)["scene"] == "mug-behind-two"


def test_log_lines_go_to_stderr(tmp_path):
    """stdout holds results only: "wrote FILE" is a log line."""
    res = shacc("export-mjcf", SCENE, str(tmp_path / "m.xml"))
    assert res.returncode == 0 and res.stdout == "" and "wrote" in res.stderr


@pytest.mark.parametrize("name", ["/dev/stdout", "/dev/fd/1"])
def test_json_to_dev_stdout_is_json_to_stdout(name):
    """``--json /dev/stdout`` (or ``/dev/fd/1``) is ``--json -``: the JSON alone on
    stdout, the summary on stderr."""
    res = shacc("precompute", SCENE, "--json", name)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["scene"] == "mug-behind-two"
    assert "C_init" in res.stderr


def test_a_symlink_loop_is_one_line(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    res = shacc("precompute", SCENE, "--json", str(tmp_path / "a"))
    assert_one_line(res, 1, "cannot write", "symbolic links")


def test_process_substitution_and_empty_names(tmp_path):
    # What `--json >(cat)` hands over: a /dev/fd/N path to a pipe, written in place.
    r, w = os.pipe()
    res = subprocess.run([SHACC, "precompute", SCENE, "--json", f"/dev/fd/{w}"],
                         capture_output=True, text=True, pass_fds=(w,), timeout=120)
    os.close(w)
    with os.fdopen(r) as f:
        assert json.loads(f.read())["scene"] == "mug-behind-two"
    assert res.returncode == 0, res.stderr
    res = shacc("precompute", SCENE, "--json", "")
    assert res.returncode == 2 and "empty string" in res.stderr


@contextlib.contextmanager
def mounted(path: Path, options: str):
    """A tmpfs at ``path`` (``mount -o options``), or a skip that says why not."""
    path.mkdir(exist_ok=True)
    if not shutil.which("mount"):
        pytest.skip("no mount command: the tmpfs write-fault tests need one")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({res.stderr.strip() or 'not permitted'}); "
                    "the test needs root or a user namespace")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def test_a_full_tmpfs_leaves_the_old_file_and_no_temporary_file(tmp_path):
    with mounted(tmp_path / "small", "size=16k") as disk:
        target = disk / "old.json"
        target.write_text("the previous result\n")
        with contextlib.suppress(OSError), (disk / "filler").open("wb") as f:
            while True:  # until the disk is full
                f.write(b"x" * 1024)
                f.flush()
        res = shacc("precompute", SCENE, "--json", str(target))
        assert_one_line(res, 1, str(target), "No space left on device")
        assert target.read_text() == "the previous result\n"
        assert sorted(p.name for p in disk.iterdir()) == ["filler", "old.json"]


def test_a_read_only_folder_is_one_line(tmp_path):
    with mounted(tmp_path / "ro", "ro,size=64k") as disk:
        res = shacc("precompute", SCENE, "--json", str(disk / "out.json"))
        assert_one_line(res, 2, str(disk), "not writable")  # found before any work
        res = shacc("export-mjcf", SCENE, str(disk / "sub" / "scene.xml"))
        assert res.returncode in (1, 2) and "Traceback" not in res.stderr, res.stderr
        assert list(disk.iterdir()) == []


# --- Ctrl-C -------------------------------------------------------------------------

CTRL_C = {
    # command, seconds from its Ctrl-C handling's install to Ctrl-C (imports of the
    # command line; start-up; a cold compilation; the run)
    "precompute": (["precompute", SCENE, "--json", "{tmp}/out.json"], (0.06, 0.1)),
    "evaluate": (["evaluate", SCENE, "--json", "{tmp}/out.json"], (0.3, 2.0, 4.0)),
    "optimize": (["optimize", SCENE, "--json", "{tmp}/out.json"], (3.0,)),
    "render": (["render", SCENE, "--out", "{tmp}/out.png"], (1.0,)),
    "sweep": (["sweep", "{tmp}/s.toml", "--out", "{tmp}/out", "--workers", "1"], (1.0, 4.0)),
    "reproduce": (["reproduce", "--quick", "--out", "{tmp}/out"], (2.0, 8.0)),
}


def ctrl_c_during_import(when: str, then: str) -> subprocess.CompletedProcess:
    """Run the Python lines ``then`` in a fresh interpreter whose import system sends it
    SIGINT, and pauses, the first time a module is looked up while the expression
    ``when`` (of ``name``, the module looked up) is true: the moment is certain."""
    program = (
        "import os, signal, sys, time\n"
        "class Finder:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        f"        if {when}:\n"
        "            os.kill(os.getpid(), signal.SIGINT)\n"
        "            time.sleep(5)\n"
        "        return None\n"
        f"{then}")
    return subprocess.run([sys.executable, "-c", program], capture_output=True, text=True,
                          timeout=60)


def test_ctrl_c_while_the_command_line_is_imported():
    """The console script handles Ctrl-C before it imports the command line: a fresh
    install compiles every module on its first import, long enough for a Ctrl-C to land
    there (it did, in CI: a KeyboardInterrupt traceback)."""
    res = ctrl_c_during_import("name == 'sweeps.app.cli'",
                               "sys.meta_path.insert(0, Finder())\n"
                               "from sweeps.app.launch import entry\n"
                               "entry()\n")
    assert res.returncode == 130, res.stderr
    assert res.stderr.splitlines() == ["interrupted"], res.stderr


def test_ctrl_c_while_the_file_writer_is_half_imported():
    """A Ctrl-C that lands while the module that writes files is being imported finds
    it in sys.modules without its lock (in CI: an exception in the Ctrl-C thread, and
    the command ran on to exit 0 and wrote its output). Here the import is paused in
    its first lines."""
    res = ctrl_c_during_import("name == 'geometry_precompute.errors' and "
                               "'geometry_precompute.fileio' in sys.modules",
                               "from sweeps.distributed import interrupt\n"
                               "interrupt.install()\n"
                               "sys.meta_path.insert(0, Finder())\n"
                               "import geometry_precompute.fileio\n"
                               "print('imported')\n")
    assert res.returncode == 130, res.stderr
    assert res.stderr.splitlines() == ["interrupted"], res.stderr
    assert res.stdout == ""


def wait_until_ctrl_c_is_handled(pid: int, timeout: float = 60.0) -> None:
    """Until the process has installed its Ctrl-C handling (``interrupt.install``
    blocks SIGINT in its main thread: bit SIGINT of SigBlk in /proc). Before that the
    interpreter is starting, where nothing is promised (README, "Ctrl-C"); on a loaded
    machine that took longer than the 0.06 s this test once waited in total."""
    bit = 1 << (signal.SIGINT - 1)
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            return  # it has ended; the test's checks say how
        blocked = re.search(r"^SigBlk:\s*([0-9a-f]+)", status, re.M)
        if blocked and int(blocked.group(1), 16) & bit:
            return
        time.sleep(0.002)
    raise AssertionError(f"process {pid} did not install its Ctrl-C handling in {timeout} s")


@pytest.mark.parametrize("name,moment", [(n, t) for n, (_, ts) in CTRL_C.items() for t in ts])
def test_ctrl_c_at_any_moment(tmp_path, name, moment):
    """Exactly `interrupted`, status 130, no crash, no output, no process left."""
    (tmp_path / "s.toml").write_text('[source]\nkind = "random"\ncount = 200\n'
                                     'tasks = [8, 10]\n')
    args = [a.replace("{tmp}", str(tmp_path)) for a in CTRL_C[name][0]]
    # A cold compilation: no compiled program may be loaded instead.
    env = {**os.environ, "SHACC_COMPILE_CACHE": "off", "XDG_CACHE_HOME": str(tmp_path / "c")}
    proc = subprocess.Popen([SHACC, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env, start_new_session=True)
    wait_until_ctrl_c_is_handled(proc.pid)
    time.sleep(moment)
    os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C reaches the whole group
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (proc.returncode, err[-2000:])
    assert err.splitlines()[-1] == "interrupted", err[-2000:]
    assert "Traceback" not in err and "Segmentation" not in err and "Exception" not in err
    outputs = [p.name for p in tmp_path.glob("out*")]
    if name == "sweep" and outputs:  # its folder holds only what a resume needs
        assert not list((tmp_path / "out").rglob("*.tmp"))
    else:
        assert outputs == [], outputs
    deadline = time.time() + 20  # workers notice their parent's end, then exit
    while process_group_members(proc.pid) and time.time() < deadline:
        time.sleep(0.2)
    assert process_group_members(proc.pid) == []


# --- refusals before work, and fast ---------------------------------------------------

def test_a_refused_scheduler_is_reported_at_once_and_nothing_is_made(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('[source]\nkind = "random"\ncount = 2\n')
    t0 = time.perf_counter()
    res = shacc("sweep", str(cfg), "--out", str(tmp_path / "o"), "--scheduler",
                "tcp://127.0.0.1:9")
    assert time.perf_counter() - t0 < 10  # the interpreter's start included; the probe <2 s
    assert_one_line(res, 2, "--scheduler", "connection refused")
    res = shacc("sweep", str(cfg), "--out", str(tmp_path / "o"), "--scheduler", "not an address")
    assert_one_line(res, 2, "--scheduler", "not a Dask scheduler address")
    assert not (tmp_path / "o").exists()


def test_scheduler_probe_is_quick():
    from sweeps.distributed.cluster import check_scheduler

    t0 = time.perf_counter()
    with pytest.raises(InputError, match="connection refused"):
        check_scheduler("tcp://127.0.0.1:9")
    assert time.perf_counter() - t0 < 2


@pytest.mark.parametrize("make", [
    lambda o: (o / ".lock").mkdir(),
    lambda o: (o / "scenes").write_text("x"),
    lambda o: (o / "config.json").mkdir(),
    lambda o: (o / "config.json").write_text("{damaged"),
])
def test_a_sweep_folder_of_the_wrong_kind_is_refused_before_anything_is_made(tmp_path, make):
    cfg = tmp_path / "s.toml"
    cfg.write_text('[source]\nkind = "random"\ncount = 2\n')
    out = tmp_path / "o"
    out.mkdir()
    make(out)
    before = sorted(p.name for p in out.iterdir())
    res = shacc("sweep", str(cfg), "--out", str(out))
    assert_one_line(res, 2, str(out))
    assert sorted(p.name for p in out.iterdir()) == before


def test_an_axis_with_min_above_init_is_refused_before_the_folder(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('[source]\nkind = "random"\ncount = 2\n[axes]\n'
                   'handle_grasp.length_min = [0.5]\n')
    res = shacc("sweep", str(cfg), "--out", str(tmp_path / "o"))
    assert_one_line(res, 2, "point 0", "bounds.length", "min 0.5 > init 0.3")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value", ["inf", "1e400", "9" * 400, "nan", "-3"])
def test_memory_budget_values_python_cannot_hold(value):
    res = shacc("evaluate", SCENE, env={"SHACC_MEMORY_BUDGET": value})
    assert_one_line(res, 2, "SHACC_MEMORY_BUDGET", "from 1 to 2^60")


# --- caches -------------------------------------------------------------------------

def _same_result(a, b) -> None:
    assert a.scene == b.scene and a.clusters == b.clusters
    assert [q.tolist() for q in a.q_opt] == [q.tolist() for q in b.q_opt]
    assert (a.C_init, a.C_final, a.iterations, a.d, a.h) == \
        (b.C_init, b.C_final, b.iterations, b.d, b.h)


def test_precompute_cache_is_data_checked_on_read(tmp_path):
    """Entries hold JSON, never code; a damaged, foreign, out-of-bounds or pickled entry
    is computed again and rewritten, with the same result."""
    import pickle

    ref = (3, "gaussian", 5, 6)
    fresh, hit, _ = cached(ref, DEFAULTS, tmp_path)
    assert not hit
    path = tmp_path / f"{random_key(ref, DEFAULTS)}.json"
    good = path.read_bytes()
    again, hit, _ = cached(ref, DEFAULTS, tmp_path)
    assert hit
    _same_result(again, fresh)
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    entry = json.loads(good)
    outside = json.loads(good)
    outside["q_opt"][0] = [9.0]
    other = json.loads(good)
    other["key"] = "0" * 64
    for bad in (good[:len(good) // 2], b"7", b'{"a": 1}', pickle.dumps(Evil()),
                json.dumps(outside).encode(), json.dumps(other).encode(), b"\xff" * 64,
                json.dumps({**entry, "version": 0}).encode()):
        path.write_bytes(bad)
        r, hit, _ = cached(ref, DEFAULTS, tmp_path)
        assert not hit and not marker.exists()
        _same_result(r, fresh)
        rewritten = json.loads(path.read_bytes())
        assert {**rewritten, "seconds": 0} == {**entry, "seconds": 0}
    # Another scene's entry under this scene's name is not this scene's result.
    scene = load_scene(SCENE)
    key = scene_key(scene, DEFAULTS)
    (tmp_path / f"{key}.json").write_bytes(good.replace(random_key(ref, DEFAULTS).encode(),
                                                        key.encode()))
    r, hit, _ = cached(scene, DEFAULTS, tmp_path)
    assert not hit and r.scene.name == "mug-behind-two"


def test_an_unwritable_precompute_cache_is_used_without_storing(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    r, hit, why = cached(random_scene(1, "uniform", 3, 3), DEFAULTS, blocker / "cache")
    assert not hit and r.C_init >= 0 and "cannot" in why and str(blocker) in why


def test_compiled_programs_are_verified_before_they_are_loaded(tmp_path):
    """A truncated or foreign entry in either compile cache is compiled again, never
    loaded; the answers stay those of a cold run."""
    folder = tmp_path / "compiled"
    env = {"SHACC_COMPILE_CACHE": str(folder)}
    # One mode: the cache's checks do not depend on the program (suite time).
    cold = shacc("evaluate", SCENE, "--modes", "baseline", "--json", str(tmp_path / "cold.json"),
                 env=env)
    assert cold.returncode == 0, cold.stderr
    entries = sorted(p for p in folder.rglob("*") if p.is_file())
    assert entries and all(p.name.endswith("-sealed") or p.suffix == ".bin" for p in entries)
    for i, p in enumerate(entries):  # truncate half of them, swap the others' contents
        data = p.read_bytes()
        p.write_bytes(data[:len(data) // 3] if i % 2 else entries[i - 1].read_bytes())
    warm = shacc("evaluate", SCENE, "--modes", "baseline", "--json", str(tmp_path / "warm.json"),
                 env=env)
    assert warm.returncode == 0 and "Error reading" not in warm.stderr, warm.stderr
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("cold.json", "warm.json"))
    assert a["modes"] == b["modes"]


def test_a_read_only_compile_cache_costs_time_not_the_run(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = shacc("evaluate", SCENE, "--modes", "baseline",
                env={"SHACC_COMPILE_CACHE": str(blocker / "sub")})
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr


def test_a_sweep_with_a_read_only_cache_says_so_once_and_runs(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text('[source]\nkind = "random"\ncount = 3\ntasks = [3, 3]\n'
                   '[settings]\nstart_grid = [2, 2]\n')
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = shacc("sweep", str(cfg), "--out", str(tmp_path / "o"), "--workers", "1",
                env={"XDG_CACHE_HOME": str(blocker)})
    assert res.returncode == 0, res.stderr
    warnings = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "store precomputed scenes" in warnings[0], res.stderr
    assert json.loads(res.stdout)["status"] == "complete"
    import pandas as pd

    assert len(pd.read_parquet(tmp_path / "o" / "scenes")) == 3
    assert np.all(pd.read_parquet(tmp_path / "o" / "scenes")["n_tasks"] == 3)
