"""The local cluster's Dask scheduler, in a process of its own (``sweeps.cluster``).

``shacc sweep`` starts it first thing, beside the fork server, so that its start
(importing distributed and the dashboard's bokeh: 1.1 and 1.2 s on the H100 hosts we
measured) runs while the command imports its own modules, instead of after them; and
its event loop no longer shares the command's process with the nannies and the
writing of parts.

    python -m sweeps.scheduler_process

Prints one JSON line, ``{"address": ..., "dashboard": port}``, once it listens on
127.0.0.1. Ends when the cluster is closed (the scheduler's ``terminate``), or when its
stdin reaches end of file: the command that started it ended, SIGKILL included.
Ignores SIGINT: Ctrl-C reaches the whole process group, and the command closes the
cluster.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import sys
import threading


def _exit_when_the_command_ends() -> None:
    sys.stdin.buffer.read()  # returns at end of file: the write end closed
    os._exit(0)


async def _serve() -> None:
    from distributed import Scheduler

    async with Scheduler(host="127.0.0.1", port=0, dashboard_address=":0") as s:
        dashboard = s.services.get("dashboard")
        print(json.dumps({"address": s.address,
                          "dashboard": dashboard.port if dashboard is not None else None}),
              flush=True)
        await s.finished()


def main() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_when_the_command_ends, name="shacc-parent-watch",
                     daemon=True).start()
    asyncio.run(_serve())
    os._exit(0)  # no interpreter teardown (about a second with bokeh loaded): nothing to keep


if __name__ == "__main__":
    main()
