# %% [markdown]
# # Success fields: from where does the Automaton reach each task?
#
# For one scene (a shipped one by default), every task is attempted from every point of
# a fine grid of start positions on the start plane, in the three modes. Each panel
# colours a start by the outcome (success, wrong task, ambiguous, timeout); red and blue
# outlines are the initial and optimised position spaces seen from the start plane. The
# last row is ShaCC's orientation jump delta_R over its successes (the paper's Fig. 7).

# %%
import os

import numpy as np

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.pipeline import evaluate_results
from sweeps.plots import success_fields_with_spaces

SCENE = next(p for p in shipped_scene_paths() if "mug_behind_two" in p.name)
GRID = 24  # starts per side; 64 or 128 for publication figures

# %%
scene = load_scene(SCENE)
r = precompute(scene, scene.settings(overrides={"start_grid": [GRID, GRID]}))
ev = evaluate_results([r], ("baseline", "shrinking", "shacc"))
T = len(r.spaces)
outcome = ev.evaluation.rollouts.outcome[0, :, :, :T]
delta_r = ev.evaluation.rollouts.delta_R[0, 2, :, :T]
rates = dict(zip(ev.modes, ev.evaluation.metrics.u_scene[0].round(3), strict=True))
print(r.scene.name, "success rates:", rates)

# %%
s = r.settings
y_c = float(np.mean([o.position[1] for o in scene.objects]))
w = s["start_y_halfwidth"]
fig = success_fields_with_spaces(outcome, delta_r, (GRID, GRID), (y_c - w, y_c + w),
                                 s["start_z_range"], r, ev.modes)
if os.environ.get("SHACC_FIGURES"):
    fig.savefig(os.path.join(os.environ["SHACC_FIGURES"], "success_fields.png"), dpi=90,
                bbox_inches="tight")
