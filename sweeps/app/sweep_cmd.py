"""``shacc sweep CONFIG --out DIR``: a parameter sweep (``sweeps.distributed.runner``);
``--dry-run`` prints its sizes and estimates only."""

from __future__ import annotations

import json
from pathlib import Path

from geometry_precompute import InputError
from sweeps.config import load_config
from sweeps.distributed.runner import dry_run, run_sweep


def cmd_sweep(args) -> int:
    cfg = load_config(args.config)
    if args.dry_run:
        info = dry_run(cfg, args.workers)
        for k, v in info.items():
            print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
        return 0
    if not args.out:
        raise InputError("<arguments>", "--out", "required unless --dry-run")
    summary = run_sweep(cfg, Path(args.out), Path(args.cache) if args.cache else None,
                        args.workers, progress=not args.quiet, scheduler=args.scheduler)
    print(json.dumps(summary))
    return 0
