"""JAX half of the ShaCC evaluator: SDFs, orientation spaces, the meta skill and
the Automaton, batched in one jitted evaluation, :func:`evaluate`. Reads only the
bake's arrays, by the bake's schema (never imports trimesh, manifold3d or coal)."""

from .determinism import pin_cpu_codegen

pin_cpu_codegen()  # before JAX starts its CPU backend: determinism.py says why

# ruff: noqa: E402

from .evaluation import evaluate, evaluate_cached, evaluate_on_devices, evaluate_sharded
from .metrics import host_metrics
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

__all__ = ["ALL_MODES", "MODES", "OPTIMIZED", "OUTCOMES", "Evaluation", "Geometry", "Layout",
           "Params", "Rollouts", "SceneMetrics", "Search", "SearchProblem", "Spaces",
           "clutteredness_mc", "evaluate", "evaluate_cached",
           "evaluate_on_devices", "evaluate_sharded", "host_metrics", "inputs"]
