"""Rollout throughput of the jitted evaluation (reference/index).

Two steps, so the accelerator machine needs only JAX and ``shacc_jax``:

    # on any machine with the project installed: precompute and bake random scenes
    python benchmarks/bench_rollouts.py bake --scenes 10000 --out bake.npz
    # where the timing happens (CPU or GPU)
    python benchmarks/bench_rollouts.py run --bake bake.npz --sizes 1000 10000

``run`` reports the compile time apart from the run time (median of --repeat timed
calls after a warm-up), rollouts per second, and the device. ``points`` times a sweep
over rollout settings (v_max) both ways: one call with a points axis on Params, and a
loop of one call per point. ``reference`` times the plain NumPy Automaton of tests/ on
a sample of the same rollouts, for the ratio. Nothing here asserts a speed.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

# The bake's fields as the JAX side reads them (the schema imports no mesh library, which
# the GPU machine does not have).
from geometry_precompute import schema

FIELDS = schema.names(schema.GEOMETRY + schema.PARAMS)


def _precompute_one(seed: int):
    from geometry_precompute import precompute, random_scene

    kind = "uniform" if seed % 2 == 0 else "gaussian"
    return precompute(random_scene(seed, kind, 10, 10))


KITCHEN = Path(__file__).resolve().parents[1] / "sweeps" / "configs" / "kitchen_meshes"


def _mesh_pair(seed: int):
    """A random 10-task scene whose objects are all the kitchen's meshes (a bowl, a jar,
    a kettle; side and top grasps), collision checks on, and its twin: every mesh a mug
    of the mesh's bounding upright cylinder, at the same place (the same spaces, so the
    same rollouts but for the bodies the gripper is checked against)."""
    from geometry_precompute import precompute, random_scene
    from geometry_precompute.generate import check_generator
    from geometry_precompute.scene import Scene, SceneObject

    gen = check_generator({"objects": [{"kind": "mesh", "folder": str(KITCHEN),
                                        "templates": {"side_grasp": 2, "top_grasp": 1}}]},
                          "<bench>")
    scene = random_scene(seed, "uniform" if seed % 2 == 0 else "gaussian", 10, 10,
                         generator=gen)
    twin = Scene(scene.name, tuple(
        SceneObject(o.id, "mug", (o.base[0], o.base[1], o.base[2]), 0.0,
                    radius=o.body_radius, height=o.body_height) for o in scene.objects),
        scene.tasks, scene.settings_overrides, scene.description, scene.source)
    on = {"collision": "on"}
    return (precompute(scene, scene.settings().with_overrides(on)),
            precompute(twin, twin.settings().with_overrides(on)))


def _save(b, out: str) -> None:
    arrays = {k: getattr(b, k) for k in FIELDS}
    arrays = {k: (v.astype(np.float32) if v.dtype == np.float64 else v) for k, v in arrays.items()}
    np.savez_compressed(out, **arrays)


def cmd_bake(args) -> None:
    from concurrent.futures import ProcessPoolExecutor

    from geometry_precompute import bake

    t0 = time.perf_counter()
    if args.meshes:
        with ProcessPoolExecutor(args.workers) as pool:
            pairs = list(pool.map(_mesh_pair, range(args.scenes), chunksize=8))
        t1 = time.perf_counter()
        _save(bake([m for m, _ in pairs]), args.out)
        _save(bake([t for _, t in pairs]), args.meshes)
        print(f"precomputed {args.scenes} mesh scenes and their twins in {t1 - t0:.1f} s; "
              f"wrote {args.out} (meshes) and {args.meshes} (primitives)")
        return
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(_precompute_one, range(args.scenes), chunksize=64))
    t1 = time.perf_counter()
    _save(bake(results), args.out)
    print(f"precomputed {args.scenes} scenes in {t1 - t0:.1f} s with {args.workers} workers; "
          f"wrote {args.out}")


def user_setting(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` of a simulated user's baked parameter (``user_noise=0.3``,
    ``user_input_modes=1``), for ``--user``."""
    name, _, value = text.partition("=")
    known = [f.name for f in schema.PARAMS if f.name.startswith("user_") and f.shape == ("S",)]
    if name not in known or not value:
        raise argparse.ArgumentTypeError(f"--user takes NAME=VALUE, NAME one of "
                                         f"{', '.join(known)}; got {text!r}")
    return name, float(value)


def _load_bake(path: str, n: int, collision: bool = False, user=None,
               population: bool = False):
    """The first n scenes of a bake file (repeated if it holds fewer), as an object with
    the bake's arrays as attributes; ``user``: [(name, value)] user parameters set in
    every scene (an imperfect simulated user, stepped); with ``population`` each of them
    that a population may draw is drawn per rollout, uniform on [0, twice the value]
    (the same mean)."""
    from types import SimpleNamespace

    from geometry_precompute.population import POPULATED
    from geometry_precompute.settings import SPECS

    data = dict(np.load(path))
    # A rollout setting newer than the bake file takes its default in every scene.
    for spec in SPECS.values():
        if spec.param is not None and spec.param.field not in data and "task_mask" in data:
            data[spec.param.field] = np.full(data["task_mask"].shape[0],
                                             spec.param.encode(spec.default))
    missing = [k for k in FIELDS if k not in data]
    if missing:
        raise SystemExit(f"{path}: bake lacks {missing}; bake it again with this version")
    total = data["task_mask"].shape[0]
    reps = -(-n // total)
    arrays = {}
    given = dict(user or [])
    for k in FIELDS:
        a = data[k]
        if k == "collision":
            a = np.full_like(a, collision)
        if k in given:
            a = np.full_like(a, given[k])
        arrays[k] = np.concatenate([a] * reps)[:n] if reps > 1 else a[:n]
    if population:
        for name, value in given.items():
            if name in POPULATED:
                i = POPULATED.index(name)
                arrays["user_dist"][:, i] = 1  # uniform
                arrays["user_dist_args"][:, i] = [0.0, 2 * value, 0.0, 2 * value]
    return SimpleNamespace(**arrays)


def _load(path: str, n: int, collision: bool = False, modes=schema.MODES, block=None,
          chunk: int = 16, user=None, population: bool = False):
    """(geometry, params, layout) of the first n scenes of a bake file (repeated if it
    holds fewer)."""
    import shacc_jax

    return shacc_jax.inputs(_load_bake(path, n, collision, user, population), modes,
                            lanes_per_block=block, samples_per_block=chunk)


def _regrid(geometry, ny: int, nz: int):
    """The same scenes with an ny x nz start grid over the baked grid's y and z range
    (seeded random orientations), for start-grid scaling."""
    import jax.numpy as jnp

    st = np.asarray(geometry.starts)
    S = st.shape[0]
    y = np.linspace(st[:, :, 1].min(1), st[:, :, 1].max(1), ny, axis=1)  # (S, ny)
    z = np.linspace(st[:, :, 2].min(1), st[:, :, 2].max(1), nz, axis=1)
    yy = np.repeat(y, nz, axis=1)
    zz = np.tile(z, (1, ny))
    xx = np.repeat(st[:, :1, 0], ny * nz, axis=1)
    q = np.random.default_rng(0).normal(size=(ny * nz, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    quats = np.broadcast_to(q, (S, ny * nz, 4))
    new = np.concatenate([np.stack([xx, yy, zz], -1), quats], -1).astype(st.dtype)
    index = np.broadcast_to(np.arange(ny * nz, dtype=np.int32), (S, ny * nz))
    return geometry._replace(starts=jnp.asarray(new), start_index=jnp.asarray(index))


def cmd_run(args) -> None:
    import dataclasses

    import jax

    import shacc_jax

    modes = tuple(args.modes)
    rows = []
    dev = jax.devices()[0]
    if args.devices:
        return _run_devices(args, modes)
    for n in args.sizes:
        geometry, params, layout = _load(args.bake, n, args.collision, modes, args.block,
                                         args.chunk, args.user, args.population)
        if args.grid:
            geometry = _regrid(geometry, *args.grid)
            layout = dataclasses.replace(layout, n_starts=geometry.starts.shape[1])
        if args.stepping:  # tuning: the stepped kernel's scheme (stepping.STEPPING)
            layout = dataclasses.replace(layout, stepping=tuple(args.stepping))
        if args.meta:  # "general" on yaw-only scenes: the Markley path
            layout = dataclasses.replace(layout, meta_formula=args.meta)
        S, T = geometry.task_mask.shape
        N = geometry.starts.shape[1]
        rollouts = S * T * N * len(modes)
        t0 = time.perf_counter()
        compiled = shacc_jax.evaluate.lower(geometry, params, layout).compile()
        t1 = time.perf_counter()
        jax.block_until_ready(compiled(geometry, params))  # warm-up
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            jax.block_until_ready(compiled(geometry, params))
            times.append(time.perf_counter() - t)
        med = statistics.median(times)
        row = {"device": str(dev), "platform": dev.platform, "scenes": S, "tasks": T,
               "starts": N, "modes": len(modes), "rollouts": rollouts,
               "block": layout.lanes_per_block or schema.lanes_per_block_default(
                   jax.default_backend(), layout.collision_checks, layout.stepped_users),
               "chunk": layout.samples_per_block, "collision": args.collision,
               "user": args.user, "stepped": layout.stepped_users,
               "population": layout.populations,
               "meta": layout.meta_formula, "stepping": args.stepping,
               "compile_s": t1 - t0, "run_s_median": med, "run_s_min": min(times),
               "rollouts_per_s": rollouts / med}
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


def cmd_kernels(args) -> None:
    """Count the device kernels one compiled evaluation launches: a JAX profiler trace
    (Perfetto JSON) of one call after a warm-up; the events on the device's streams,
    their summed duration against the call's wall time (how busy the device was)."""
    import gzip
    import tempfile

    import jax

    import shacc_jax

    geometry, params, layout = _load(args.bake, args.scenes, modes=tuple(args.modes),
                                     block=args.block, user=args.user)
    compiled = shacc_jax.evaluate.lower(geometry, params, layout).compile()
    jax.block_until_ready(compiled(geometry, params))
    with tempfile.TemporaryDirectory() as folder:
        t = time.perf_counter()
        with jax.profiler.trace(folder, create_perfetto_trace=True):
            jax.block_until_ready(compiled(geometry, params))
        wall = time.perf_counter() - t
        [trace] = Path(folder).rglob("*.trace.json.gz")
        events = json.loads(gzip.decompress(trace.read_bytes()))["traceEvents"]
    device = {e["pid"] for e in events if e.get("ph") == "M" and e.get("name") == "process_name"
              and str(e.get("args", {}).get("name", "")).startswith("/device:")}
    spans = [e for e in events if e.get("ph") == "X" and e.get("pid") in device]
    kernels = [e for e in spans if not str(e.get("name", "")).lower().startswith("mem")]
    busy = sum(float(e.get("dur", 0)) for e in kernels) * 1e-6
    names: dict[str, int] = {}
    spent: dict[str, float] = {}
    for e in kernels:
        names[e["name"]] = names.get(e["name"], 0) + 1
        spent[e["name"]] = spent.get(e["name"], 0.0) + float(e.get("dur", 0)) * 1e-3
    row = {"device": str(jax.devices()[0]), "scenes": args.scenes, "user": args.user,
           "stepped": layout.stepped_users, "block": args.block, "wall_s": wall,
           "kernels": len(kernels), "copies_and_sets": len(spans) - len(kernels),
           "kernel_busy_s": busy, "mean_kernel_us": 1e6 * busy / max(len(kernels), 1),
           "top": sorted(names.items(), key=lambda kv: -kv[1])[:8],
           "top_ms": [(k, names[k], round(v, 2)) for k, v in
                      sorted(spent.items(), key=lambda kv: -kv[1])[:25]]}
    print(json.dumps(row), flush=True)


def cmd_points(args) -> None:
    """A sweep of P v_max values over one geometry: one call with Params (P, S), against
    P calls with Params (S,) (the loop a sweep ran before Params had a points axis)."""
    import jax

    import shacc_jax

    geometry, params, layout = _load(args.bake, args.scenes)
    scale = np.linspace(0.5, 1.5, args.points).astype(np.asarray(params.v_max).dtype)
    stacked = jax.tree.map(lambda a: jax.numpy.stack([a] * args.points), params)
    stacked = stacked._replace(v_max=stacked.v_max * scale[:, None])
    singles = [jax.tree.map(lambda a, i=i: a[i], stacked) for i in range(args.points)]
    t0 = time.perf_counter()
    mapped = shacc_jax.evaluate.lower(geometry, stacked, layout).compile()
    one = shacc_jax.evaluate.lower(geometry, singles[0], layout).compile()
    t1 = time.perf_counter()

    def timed(fn):
        jax.block_until_ready(fn())
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            jax.block_until_ready(fn())
            times.append(time.perf_counter() - t)
        return statistics.median(times)

    t_mapped = timed(lambda: mapped(geometry, stacked))
    t_loop = timed(lambda: [one(geometry, p) for p in singles])
    a = mapped(geometry, stacked).rollouts.outcome
    b = np.stack([np.asarray(one(geometry, p).rollouts.outcome) for p in singles])
    S, T = geometry.task_mask.shape
    rollouts = args.points * S * T * geometry.starts.shape[1] * len(layout.modes)
    print(json.dumps({"device": str(jax.devices()[0]), "points": args.points, "scenes": S,
                      "rollouts": rollouts, "compile_s_both": t1 - t0,
                      "mapped_s_median": t_mapped, "loop_s_median": t_loop,
                      "speedup": t_loop / t_mapped,
                      "same_outcomes": bool(np.array_equal(np.asarray(a), b))}), flush=True)


def _run_devices(args, modes) -> None:
    """Wall time of ``shacc_jax.execute`` of a plan over 1..K devices (an accelerator's
    devices one host thread each, CPU devices one program), results back on the host;
    0 devices: the plan's own default (on a CPU, every CPU device for stepped users,
    ``runplan.plan``)."""
    import jax

    from shacc_jax.runplan import execute, plan

    for n in args.sizes:
        baked = _load_bake(args.bake, n, args.collision, args.user, args.population)
        S, T = baked.task_mask.shape
        rollouts = S * T * baked.starts.shape[1] * len(modes)
        for k in args.devices:
            p = plan(baked, modes, devices=jax.local_devices()[:k] if k else None)
            t = time.perf_counter()
            execute(p, baked)  # compile and warm up
            first = time.perf_counter() - t
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                execute(p, baked)
                times.append(time.perf_counter() - t)
            med = statistics.median(times)
            print(json.dumps({"devices": list(p.devices), "scenes": S, "rollouts": rollouts,
                              "user": args.user, "stepped": p.layout.stepped_users,
                              "first_s": first, "wall_s_median": med, "wall_s_min": min(times),
                              "rollouts_per_s": rollouts / med}), flush=True)


def cmd_reference(args) -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from reference_automaton import rollout

    from geometry_precompute import bake

    results = [_precompute_one(s) for s in range(args.scenes)]
    b = bake(results)
    rng = np.random.default_rng(0)
    modes = ("baseline", "shrinking", "shacc")
    picks = [(int(rng.integers(b.n_scenes)), modes[int(rng.integers(3))],
              int(rng.integers(b.n_starts)), int(rng.integers(10))) for _ in range(args.samples)]
    t0 = time.perf_counter()
    for s, m, n, t in picks:
        rollout(b, s, m, n, t)
    dt = time.perf_counter() - t0
    print(json.dumps({"reference_rollouts": len(picks), "seconds": dt,
                      "rollouts_per_s": len(picks) / dt}))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("bake")
    b.add_argument("--scenes", type=int, default=1000)
    b.add_argument("--workers", type=int, default=os.cpu_count())
    b.add_argument("--out", required=True)
    b.add_argument("--meshes", metavar="TWIN", help="scenes of the kitchen's meshes, collision "
                   "checks on, in --out; their twins with each mesh a mug of its bounding "
                   "cylinder in TWIN (the cost of mesh objects against primitives)")
    b.set_defaults(func=cmd_bake)
    r = sub.add_parser("run")
    r.add_argument("--bake", required=True)
    r.add_argument("--sizes", type=int, nargs="+", default=[1000])
    r.add_argument("--repeat", type=int, default=5)
    r.add_argument("--modes", nargs="+", default=["baseline", "shrinking", "shacc"])
    r.add_argument("--block", type=int, default=None)
    r.add_argument("--chunk", type=int, default=16)
    r.add_argument("--meta", choices=["yaw", "general"], default=None,
                   help="force the meta-target formula (default: what the scenes need)")
    r.add_argument("--grid", type=int, nargs=2, metavar=("NY", "NZ"),
                   help="replace the baked 6 x 6 start grid")
    r.add_argument("--devices", type=int, nargs="+",
                   help="time shacc_jax.execute planned over these device counts (0: the "
                   "plan's default)")
    r.add_argument("--collision", action="store_true",
                   help='collision = "on" for every scene (the bake holds the objects)')
    r.add_argument("--user", type=user_setting, nargs="+", metavar="NAME=VALUE",
                   help="an imperfect simulated user in every scene (stepped rollouts), "
                   "e.g. user_noise=0.3 user_noise_tau=0.5 user_tremor=0.01")
    r.add_argument("--population", action="store_true",
                   help="with --user: each rollout draws its user, uniform on [0, 2 x]")
    r.add_argument("--stepping", type=int, nargs=2, metavar=("SHARE", "UNROLL"),
                   help="stepped users: check 1/SHARE of the lanes in full per step, "
                   "UNROLL steps per loop iteration (stepping.STEPPING)")
    r.add_argument("--json")
    r.set_defaults(func=cmd_run)
    k = sub.add_parser("kernels", help="count the device kernels of one evaluation")
    k.add_argument("--bake", required=True)
    k.add_argument("--scenes", type=int, default=10000)
    k.add_argument("--modes", nargs="+", default=["baseline", "shrinking", "shacc"])
    k.add_argument("--block", type=int, default=None)
    k.add_argument("--user", type=user_setting, nargs="+", metavar="NAME=VALUE")
    k.set_defaults(func=cmd_kernels)
    q = sub.add_parser("points")
    q.add_argument("--bake", required=True)
    q.add_argument("--scenes", type=int, default=1000)
    q.add_argument("--points", type=int, default=5)
    q.add_argument("--repeat", type=int, default=3)
    q.set_defaults(func=cmd_points)
    f = sub.add_parser("reference")
    f.add_argument("--scenes", type=int, default=20)
    f.add_argument("--samples", type=int, default=300)
    f.set_defaults(func=cmd_reference)
    args = p.parse_args()
    args.func(args)


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
