"""The ``shacc`` console script.

Its only job is to handle Ctrl-C before anything else happens: the wrapper that pip
writes imports this small module, which installs :mod:`sweeps.distributed.interrupt` and only then
imports the command line (on a fresh install Python compiles every module it imports
the first time, which took long enough for a Ctrl-C to land in the middle of it and
print a traceback).
"""

from __future__ import annotations

import sys


def entry() -> None:
    """Install the Ctrl-C handling (``interrupt``), then run :func:`sweeps.app.cli.main`."""
    from sweeps.distributed import faults, interrupt  # deferred: 18 ms to import

    faults.guard_standard_streams()  # before anything may print (Ctrl-C's line too)
    interrupt.install()
    from sweeps.app.cli import main  # deferred: 29 ms to import

    sys.exit(main())
