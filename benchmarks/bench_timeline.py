"""Where a sweep's wall time goes: one ``shacc sweep`` run with Dask's task stream
recorded, printed as a timeline in seconds since the command's start.

    python benchmarks/bench_timeline.py CONFIG --out DIR [--cache C] [--workers N]
        [--scheduler ADDRESS]

For each kind of task (precompute, warm-up, evaluate, encode): when the first one
started, when the last one ended, and their busy time summed over workers; the
evaluations chunk by chunk; when the worker processes were started and ready; and the
summary's phases. Run it twice with the same ``--cache`` (into new folders) to see a
warm sweep.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import time
from collections import defaultdict
from pathlib import Path

T0 = time.time()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("config")
    ap.add_argument("--out", required=True)
    ap.add_argument("--cache")
    ap.add_argument("--workers", type=int)
    ap.add_argument("--scheduler")
    args = ap.parse_args()
    if not args.scheduler:  # first thing, as ``shacc sweep`` does
        from sweeps.distributed.cluster import start_fork_server

        start_fork_server()
    from sweeps.config import load_config
    from sweeps.distributed import runner
    from sweeps.distributed.runner import run_sweep

    seen: dict = {}
    connect = runner.connect

    @contextlib.contextmanager
    def recorded(*a, **k):
        with connect(*a, **k) as pool:
            # Imported here: the command imports distributed in connect.
            from distributed import get_task_stream

            seen["ready"] = time.time()  # the precompute workers
            with get_task_stream(pool.client) as ts:
                yield pool
            seen["tasks"] = ts.data
            seen["workers"] = pool.client.run(_process_times)
            seen["evaluators"] = [a for a, w in pool.client.scheduler_info(
                n_workers=-1)["workers"].items() if "evaluate" in w["resources"]]
            seen["marks"] = pool.client.run(_warm_up_marks, workers=seen["evaluators"])

    runner.connect = recorded  # the name the runner calls
    summary = run_sweep(load_config(args.config), Path(args.out),
                        Path(args.cache) if args.cache else None, args.workers,
                        progress=False, scheduler=args.scheduler)
    end = time.time()
    print(json.dumps(summary))
    _report(seen, end)


def _warm_up_marks() -> dict:
    from sweeps.distributed.evaluation_worker import WARM_UP_MARKS

    return dict(WARM_UP_MARKS)


def _process_times() -> dict:
    """When this process was created, on the wall clock, to 10 ms: its start in clock
    ticks since boot (/proc/self/stat) against the seconds since boot now
    (/proc/uptime). (psutil's create_time adds the boot time in whole seconds, so it
    read up to 1 s early.)"""
    import os

    now, uptime = time.time(), float(Path("/proc/uptime").read_text().split()[0])
    ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
    return {"created": now - uptime + ticks / os.sysconf("SC_CLK_TCK"), "imported": now}


def _report(seen: dict, end: float) -> None:
    def t(x: float) -> str:
        return f"{x - T0:7.3f}"

    for name, mine in (("precompute", False), ("evaluation", True)):
        created = [w["created"] for a, w in seen["workers"].items()
                   if (a in seen["evaluators"]) == mine]
        if created:
            print(f"{name} worker processes created {t(min(created))} .. {t(max(created))}")
    print(f"precompute workers ready {t(seen['ready'])}; command ended {t(end)}")
    for marks in seen["marks"].values():
        if marks:
            print("evaluation worker's last warm-up: " + ", ".join(
                f"{k} {t(v).strip()}" for k, v in marks.items()))
    kinds: dict[str, list] = defaultdict(list)
    for task in seen["tasks"]:
        kind = task["key"].split("-")[0] if not task["key"].startswith("warm-up") \
            else "warm-up"
        for ss in task["startstops"]:
            if ss["action"] == "compute":
                kinds[kind].append((ss["start"], ss["stop"], task["key"]))
    for kind, spans in sorted(kinds.items(), key=lambda kv: min(s for s, _, _ in kv[1])):
        busy = sum(b - a for a, b, _ in spans)
        print(f"{kind:>10}: {len(spans):4d} tasks, first start {t(min(a for a, _, _ in spans))}, "
              f"last end {t(max(b for _, b, _ in spans))}, busy {busy:7.3f} s")
    for a, b, key in sorted(kinds.get("evaluate", [])):
        print(f"  {key.rsplit('-', 1)[-1]:>4}: evaluate {t(a)} .. {t(b)} ({b - a:.3f} s)")
    for a, b, _ in sorted(kinds.get("warm-up", [])):
        print(f"  warm-up {t(a)} .. {t(b)} ({b - a:.3f} s)")


if __name__ == "__main__":
    from shacc_jax import configure_runtime

    configure_runtime()  # as the commands do, before anything starts JAX
    main()
