# %% [markdown]
# # How do the task spaces' initial size and the ambiguity rule change success?
#
# Loads a sweep's Parquet dataset (by default it first runs the small sweep of
# `CONFIG`: 8 random scenes x 4 initial side-grasp radii x 2 ambiguity rules on a
# 4 x 4 start grid; set `SWEEP` to a finished sweep's folder to analyse yours) and plots
# success rate and delta_R against each swept setting per mode, with 95 % bootstrap CIs
# over scenes: one line per value of the other settings (never rows of different
# settings pooled as if they were independent scenes), heat maps over the first two
# axes, and paired differences between modes, scene by scene. Larger initial spaces
# overlap more, so the baseline loses success as the radius grows, unless ambiguous
# activations go to the nearest task; Shrinking and ShaCC keep most of it.

# %% tags=["parameters"]
SWEEP = None     # a finished sweep's --out folder; None: run CONFIG first (a minute)
CONFIG = """
name = "notebook-small"
chunk = 8
[source]
kind = "random"
count = 8
tasks = [5, 8]
seed = 3
[settings]
start_grid = [4, 4]
[axes]
side_grasp.radius_init = [0.10, 0.14, 0.18, 0.22]
ambiguity = ["fail", "nearest"]
"""
RESAMPLES = 2000  # bootstrap resamples per CI
FIGURES = None    # a folder to save the first figure in as sweep_analysis.png

# %%
import tempfile
from pathlib import Path

import pandas as pd

from sweeps.analysis.plots import sweep_heatmap, sweep_lines, swept_axes
from sweeps.analysis.stats import paired_diff_ci
from sweeps.config import load_config
from sweeps.distributed.runner import run_sweep

if SWEEP is None:
    tmp = Path(tempfile.mkdtemp())
    (tmp / "sweep.toml").write_text(CONFIG)
    run_sweep(load_config(tmp / "sweep.toml"), tmp / "out", tmp / "cache", workers=1,
              progress=False)
    SWEEP = tmp / "out"
scenes = pd.read_parquet(Path(SWEEP) / "scenes")
rollouts = pd.read_parquet(Path(SWEEP) / "rollouts")
tasks = pd.read_parquet(Path(SWEEP) / "tasks")
axes = swept_axes(scenes)
modes = [c.split(".")[0] for c in scenes.columns if c.endswith(".success")]
print(len(scenes), "scene rows,", len(rollouts), "rollouts; swept:", axes)

# %%
for axis in axes:
    fig = sweep_lines(scenes, axis, "success", modes, n_resamples=RESAMPLES)
    if FIGURES and axis == axes[0]:
        fig.savefig(Path(FIGURES) / "sweep_analysis.png", dpi=90, bbox_inches="tight")
    sweep_lines(scenes, axis, "delta_R_mean", modes, n_resamples=RESAMPLES)

# %%
if len(axes) >= 2:
    for mode in modes:
        sweep_heatmap(scenes, axes[0], axes[1], "success", mode)

# %% [markdown]
# ## Shrinking and ShaCC against the baseline, scene by scene, at every point

# %%
rows = []
for point, group in scenes.groupby("point"):
    for mode in [m for m in modes if m != "baseline"]:
        d = paired_diff_ci(group["baseline.success"], group[f"{mode}.success"], RESAMPLES)
        rows.append({"point": point, **{a: group[f"set.{a}"].iloc[0] for a in axes},
                     "mode": mode, "difference": d["mean"], "ci": d["ci"]})
pd.DataFrame(rows)

# %% [markdown]
# ## The hardest tasks: the lowest baseline success rate at any point

# %%
named = tasks.merge(scenes[["point", "scene_index", "scene"]], on=["point", "scene_index"])
cols = ["point", "scene", "task_id", "template", "object_kind", "q_init", "q_shrunk",
        *[f"{m}.success" for m in modes]]
named[cols].sort_values("baseline.success").head(10)

# %%
# Outcome mix per mode from the per-rollout table.
rollouts.groupby(["mode", "outcome"], observed=True).size().unstack(fill_value=0)
