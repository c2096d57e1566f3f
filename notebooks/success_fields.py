# %% [markdown]
# # Success fields: from where does the Automaton reach each task?
#
# For one scene (a shipped one by default), every task is attempted from every point of
# a fine grid of start positions on the start plane, in the three modes. Each panel
# colours a start by the outcome (success, wrong task, ambiguous, timeout); red and blue
# outlines are the initial and shrunk position spaces seen from the start plane. The
# last row is ShaCC's orientation jump delta_R over its successes (the paper's Fig. 7).

# %% tags=["parameters"]
SCENE = None    # a scene file; None: the shipped scene 09_mug_behind_two
GRID = 24       # starts per side of the start plane; 64 or 128 for publication figures
OPTIMIZED = True  # also compare Shrinking with the optimized mode's sizes (a search)
SEARCH = {}     # the search's settings, e.g. {"optimize_population": 16}; {}: the defaults
FIGURES = None  # a folder to save the figures in (success_fields*.png); None: show only

# %%
from pathlib import Path

import numpy as np

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.analysis.plots import success_fields, success_fields_with_spaces
from sweeps.pipeline import evaluate_results, optimized_params

path = SCENE or next(p for p in shipped_scene_paths() if "mug_behind_two" in p.name)
scene = load_scene(path)
r = precompute(scene, scene.settings(overrides={"start_grid": [GRID, GRID], **SEARCH}))
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
if FIGURES:
    fig.savefig(Path(FIGURES) / "success_fields.png", dpi=90, bbox_inches="tight")

# %% [markdown]
# ## Shrinking against the best sizes it could have had
#
# The `optimized` mode searches, within Shrinking's bounds, the sizes of the same spaces
# that make the most rollouts succeed on its own random starts; here both are scored on
# the fine grid above, which the search never saw. The search keeps Shrinking's sizes
# unless its own best beats them on a second, held-out set of starts, so on the grid it
# should not do worse than Shrinking by more than the noise of a finite sample.

# %%
if OPTIMIZED:
    ev_opt = evaluate_results([r], ("shrinking", "optimized"))
    print("Shrinking:", r.shrunk_params())
    print("search:   ", optimized_params(ev_opt, 0))
    rates = dict(zip(ev_opt.modes, ev_opt.evaluation.metrics.u_scene[0].round(3),
                     strict=True))
    print("success on the grid:", rates)
    fig = success_fields(ev_opt.evaluation.rollouts.outcome[0, :, :, :T], (GRID, GRID),
                         (y_c - w, y_c + w), s["start_z_range"], r.task_ids, ev_opt.modes,
                         title=f"{r.scene.name}: shrinking against optimized "
                               f"({GRID} x {GRID})")
    if FIGURES:
        fig.savefig(Path(FIGURES) / "success_fields_optimized.png", dpi=90,
                    bbox_inches="tight")
