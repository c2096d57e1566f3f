"""Writing results: atomic files and the JSON of SPEC section 12a."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from geometry_precompute.precompute import PrecomputeResult


def _clean(x: Any) -> Any:
    """JSON-safe: NaN/inf become null, numpy scalars plain Python."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    if hasattr(x, "tolist"):
        return _clean(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write to a temporary file beside ``path``, then rename: never a half-written file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_json(path: str | Path, obj: Any) -> None:
    write_atomic(path, (json.dumps(_clean(obj), indent=1) + "\n").encode())


def precompute_json(r: PrecomputeResult) -> dict[str, Any]:
    """The precompute keys of SPEC section 12a."""
    ids = r.task_ids
    return {
        "scene": r.scene.name,
        "tasks": ids,
        "clutteredness": {"init": r.C_init, "final": r.C_final},
        "clusters": [[ids[i] for i in c] for c in r.meta_clusters()],
        "shrinking": {"iterations": r.iterations, "params": r.shrunk_params()},
        "metrics": {"d": r.d, "h": r.h},
    }
