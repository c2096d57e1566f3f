"""JAX half of the ShaCC evaluator: SDFs, orientation spaces, the meta skill and
the Automaton, batched in one jitted evaluation, :func:`evaluate`, which :func:`run`
plans and runs for a bake (pieces, devices, fields). Reads only the bake's arrays, by
the bake's schema (never imports trimesh, manifold3d or coal)."""

from .determinism import pin_cpu_codegen

pin_cpu_codegen()  # before JAX starts its CPU backend: determinism.py says why

# ruff: noqa: E402

from .runplan import split_cpu

split_cpu()  # several CPU devices, before JAX starts its CPU backend: runplan.cpu_devices

from .evaluation import evaluate
from .metrics import host_metrics
from .montecarlo import clutteredness_mc
from .runplan import Run, RunPlan, budget, execute, plan, run
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
           "Params", "Rollouts", "Run", "RunPlan", "SceneMetrics", "Search", "SearchProblem",
           "Spaces", "budget", "clutteredness_mc", "evaluate", "execute", "host_metrics",
           "inputs", "plan", "run"]
