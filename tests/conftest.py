"""Shared fixtures: the shipped scenes, precomputed and baked once per session."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import settings

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("MUJOCO_GL", "egl")  # before anything imports mujoco
# Compiled programs go to a folder of this run, not the user's cache (tests that study
# the cache set their own). The folder is made by the first process (pytest-xdist's
# workers inherit it) and removed by that process at the end.
_COMPILED = None
if "SHACC_COMPILE_CACHE" not in os.environ:
    _COMPILED = tempfile.mkdtemp(prefix="shacc-test-compiled-")
    os.environ["SHACC_COMPILE_CACHE"] = _COMPILED
sys.path.insert(0, str(Path(__file__).parent))  # the NumPy reference lives beside the tests
# Each evaluation program is compiled with the options the commands would give it
# (shacc_jax.program_cache.quick: LLVM's passes off for a small CPU program, XLA's
# defaults for a large one); tests that call shacc_jax.evaluate directly go through
# programs.evaluate for the same rule. Forcing level 0 on every program made the large
# ones run ten times slower than they took to compile (the collision test's 104-scene
# batch: 61 s of running at level 0). Every assertion holds a float to a tolerance and
# only exact things exactly, and the answers are the same bits at either level
# (test_quick_compile).

# Strict JAX, as the anchors' test suites run: no implicit rank promotion, no implicit
# dtype promotion, and two CPU devices so that the multi-device paths run on a CI
# machine without accelerators.
import jax  # noqa: E402

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")
if os.environ.get("JAX_PLATFORMS", "cpu") == "cpu":
    jax.config.update("jax_num_cpu_devices", 2)

# The runtime the commands set up (the pinned CPU code generation), as an entry point
# does: before anything starts JAX.
from shacc_jax import configure_runtime  # noqa: E402

configure_runtime()

# Every process of the run shares compiled and traced programs through the run's cache
# folder, as the commands do: a program the other worker (or a command) built is loaded,
# not built again (the suite compiles far more than it runs: 960 -> 888 s on 2 cores).
from sweeps import compile_cache  # noqa: E402

compile_cache.enable()


def pytest_unconfigure(config):
    if _COMPILED is not None and not hasattr(config, "workerinput"):
        shutil.rmtree(_COMPILED, ignore_errors=True)


# A test process's memory maps past which its programs are released (Linux allows
# 65 530; one test compiles at most a few programs of about 800 each).
MAPS_TO_RELEASE = 30_000


def memory_maps() -> int:
    """This process's memory maps (0 where /proc has none)."""
    try:
        with open(f"/proc/{os.getpid()}/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:  # not Linux: no such limit to keep under
        return 0


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Every module's compiled programs are freed after it, and within a module once
    the process holds MAPS_TO_RELEASE memory maps: a worker process that kept the
    suite's programs passed Linux's limit of maps per process and crashed inside XLA's
    compiler (``shacc_jax.program_cache.release_compiled``). A later test that needs
    a program again loads it from the run's compilation cache."""
    yield
    from shacc_jax import program_cache

    program_cache.release_compiled()


@pytest.fixture(autouse=True)
def _release_when_maps_are_many():
    yield
    if memory_maps() > MAPS_TO_RELEASE:
        from shacc_jax import program_cache

        program_cache.release_compiled()


settings.register_profile("shacc", deadline=None, max_examples=40, derandomize=True)
settings.load_profile("shacc")


@pytest.fixture(scope="session")
def shipped_results():
    from geometry_precompute import load_scene, precompute, shipped_scene_paths

    return [precompute(load_scene(p)) for p in shipped_scene_paths()]


@pytest.fixture(scope="session")
def shipped_bake(shipped_results):
    from geometry_precompute import bake

    return bake(shipped_results)


KITCHEN_MESHES = Path(__file__).parents[1] / "sweeps" / "configs" / "kitchen_meshes"
# Robot parts from mujoco-mjx's test data (CAD meshes no one on the team made) that fit a
# side or top grasp: a watertight handle, and three that are not (their convex hulls).
MJX_ASSETS = ("handle.stl", "abduction.stl", "upper_left_1.stl", "powercable.stl")


@pytest.fixture(scope="session")
def mesh_scenes(tmp_path_factory):
    """``mesh_scenes(count, tasks=(3, 6), seed=0, **overrides)``: precomputed random
    scenes of the kitchen's meshes (a bowl, a jar, a kettle: revolved profiles), robot
    parts from mujoco-mjx's test data and primitives, each with at least one mesh, with
    the settings' ``overrides`` (collision checks on unless they say otherwise)."""
    import warnings

    import mujoco

    from geometry_precompute import precompute, random_scene
    from geometry_precompute.errors import SceneWarning
    from geometry_precompute.generate import check_generator

    parts = tmp_path_factory.mktemp("mjx_parts")
    assets = Path(mujoco.__file__).parent / "mjx" / "test_data" / "barkour_v0" / "assets"
    for name in MJX_ASSETS:
        shutil.copy(assets / name, parts / name)
    # A compact table: cluttered scenes, short paths (the stepped tests run to the end).
    gen = check_generator({"table": [0.7, 0.7], "sigma": 0.12, "objects": [
        {"kind": "mesh", "folder": str(KITCHEN_MESHES), "weight": 3,
         "templates": {"side_grasp": 2, "top_grasp": 1}},
        {"kind": "mesh", "folder": str(parts), "weight": 2, "origin": "base",
         "templates": {"side_grasp": 1, "top_grasp": 1}},
        {"kind": "mug", "radius": [0.035, 0.05]}, {"kind": "cup"},
        {"kind": "box", "half_extents": [[0.03, 0.05], [0.06, 0.1], [0.05, 0.12]],
         "templates": {"drawer_pull": 1, "top_grasp": 1}}]}, "<test>")

    def make(count: int, tasks=(3, 6), seed: int = 0, **overrides):
        overrides = {"collision": "on", **overrides}
        out, k = [], seed
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SceneWarning)  # the hulls of open meshes
            while len(out) < count:
                scene = random_scene(k, ("uniform", "gaussian")[k % 2], *tasks, generator=gen)
                k += 1
                if any(o.kind == "mesh" for o in scene.objects):
                    out.append(precompute(scene, scene.settings().with_overrides(overrides)))
        return out

    return make


def write_scene(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def process_group_members(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group, read from /proc: what a command
    started in its own session left behind."""
    found = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                found.append(int(d.name))
    return found


@pytest.fixture
def count_compiles(caplog):
    """``with count_compiles("evaluate") as found:`` collects the log lines of JAX's
    compilations of that jitted function within the block (``jax.log_compiles``)."""
    import contextlib
    import logging

    import jax

    @contextlib.contextmanager
    def counting(name: str):
        found: list[str] = []
        with jax.log_compiles(True), caplog.at_level(logging.WARNING):
            start = len(caplog.records)
            yield found
            found.extend(r.getMessage() for r in caplog.records[start:]
                         if f"Compiling jit({name})" in r.getMessage())
    return counting


class StartedCluster:
    """A Dask scheduler and two workers started apart, as on other hosts (one takes the
    precompute, one the evaluation), on 127.0.0.1; :meth:`stop` kills them all."""

    def __init__(self, folder: Path):
        sched_file = folder / "scheduler.json"
        self.scheduler = subprocess.Popen(
            [*self._dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
             "--scheduler-file", str(sched_file)], env=self._env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True)
        self.procs = [self.scheduler]
        self.workers: dict[str, subprocess.Popen] = {}  # the latest of each kind
        try:
            deadline = time.time() + 60
            while True:  # the file may exist before it is whole
                try:
                    self.address = json.loads(sched_file.read_text())["address"]
                    break
                except (OSError, ValueError, KeyError):
                    if time.time() > deadline:
                        raise
                    time.sleep(0.1)
            for kind in ("precompute", "evaluate"):
                self.add_worker(kind)
        except BaseException:
            self.stop()
            raise

    _dask = (sys.executable, "-m", "dask")

    @property
    def _env(self) -> dict:
        return {**os.environ, "JAX_PLATFORMS": "cpu"}

    def add_worker(self, kind: str) -> None:
        """One more worker (with its nanny) that offers the ``kind`` resource."""
        self.workers[kind] = subprocess.Popen(
            [*self._dask, "worker", self.address, "--host", "127.0.0.1", "--nthreads", "1",
             "--nworkers", "1", "--resources", f"{kind}=1", "--no-dashboard"],
            env=self._env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True)
        self.procs.append(self.workers[kind])

    def wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout=60) as client:
            client.wait_for_workers(n, timeout=120)

    @staticmethod
    def kill(proc: subprocess.Popen) -> None:
        """SIGKILL to a process and its group (a worker and its nanny)."""
        for pid in [proc.pid, *process_group_members(proc.pid)]:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.wait()

    def stop(self) -> None:
        for p in self.procs:
            self.kill(p)


@pytest.fixture
def started_cluster(tmp_path):
    """The address of a :class:`StartedCluster`, stopped afterwards."""
    cluster = StartedCluster(tmp_path)
    try:
        yield cluster.address
    finally:
        cluster.stop()
