"""JAX half of the ShaCC evaluator: SDFs, orientation spaces, the meta skill and
the Automaton, batched in one jitted evaluation, :func:`evaluate`. Reads only the
bake's arrays, by the bake's schema (never imports trimesh, manifold3d or coal)."""

import jax

from .evaluation import evaluate, evaluate_cached, evaluate_on_devices, evaluate_sharded
from .metrics import batch_metrics as _batch_metrics
from .montecarlo import clutteredness_mc
from .types import (
    ALL_MODES,
    MODES,
    OPTIMIZED,
    OUTCOMES,
    Evaluation,
    Geometry,
    Layout,
    Params,
    Rollouts,
    SceneMetrics,
    Search,
    SearchProblem,
    Spaces,
    inputs,
)

# Per-scene metrics of rollouts joined from pieces (sweeps.memory), as one program.
batch_metrics = jax.jit(_batch_metrics)

__all__ = ["ALL_MODES", "MODES", "OPTIMIZED", "OUTCOMES", "Evaluation", "Geometry", "Layout",
           "Params", "Rollouts", "SceneMetrics", "Search", "SearchProblem", "Spaces",
           "batch_metrics", "clutteredness_mc", "evaluate", "evaluate_cached",
           "evaluate_on_devices", "evaluate_sharded", "inputs"]
