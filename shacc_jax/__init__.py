"""JAX half of the ShaCC evaluator: SDFs, orientation spaces, the meta skill and
the Automaton, batched in one jitted evaluation, :func:`evaluate`, which :func:`run`
plans and runs for a bake (pieces, devices, fields). Reads only the bake's arrays, by
the bake's schema (never imports trimesh, manifold3d or coal). Importing it changes
nothing; :func:`configure_runtime` sets up JAX for it, and :func:`run` calls it."""

from .evaluation import evaluate
from .metrics import host_metrics
from .montecarlo import clutteredness_mc
from .runplan import Run, RunPlan, budget, execute, plan, run
from .runtime import Runtime, configure_runtime
from .types import (
    ALL_MODES,
    INTENT_MODES,
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

__all__ = ["ALL_MODES", "INTENT_MODES", "MODES", "OPTIMIZED", "OUTCOMES", "Evaluation",
           "Geometry", "Layout", "Params", "Rollouts", "Run", "RunPlan", "Runtime",
           "SceneMetrics", "Search", "SearchProblem", "Spaces", "budget", "clutteredness_mc",
           "configure_runtime",
           "evaluate", "execute", "host_metrics", "inputs", "plan", "run"]
