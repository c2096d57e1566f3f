"""JAX half of the ShaCC evaluator: SDFs, orientation spaces, the meta skill and
the Automaton, batched in one jitted evaluation. Reads only the bake's arrays
(never imports trimesh, manifold3d or coal)."""

from .evaluation import evaluate, evaluate_on_devices, evaluate_sharded
from .montecarlo import clutteredness_mc
from .types import MODES, OUTCOMES, Evaluation, Rollouts, SceneMetrics, Scenes, Spaces

__all__ = ["MODES", "OUTCOMES", "Evaluation", "Rollouts", "SceneMetrics", "Scenes", "Spaces",
           "clutteredness_mc", "evaluate", "evaluate_on_devices", "evaluate_sharded"]
