# %% [markdown]
# # How do the task spaces' initial size and the ambiguity rule change success?
#
# Loads a sweep's Parquet tables (by default it runs a small sweep first: 8 random
# scenes x 4 initial side-grasp radii x 2 ambiguity rules on a 4 x 4 start grid; set
# SHACC_SWEEP to a finished sweep's folder, e.g. the laptop sweep's) and plots success
# rate and delta_R against each swept setting per mode, with bootstrap CIs over scenes,
# and heat maps over the first two axes: larger initial spaces overlap more, so the
# baseline loses success as the radius grows, unless ambiguous activations go to the
# nearest task; Shrinking and ShaCC keep most of it.

# %%
import os
import tempfile
from pathlib import Path

import pandas as pd

from sweeps.config import load_config
from sweeps.plots import sweep_heatmap, sweep_lines
from sweeps.runner import run_sweep

SWEEP = os.environ.get("SHACC_SWEEP")  # a finished sweep's --out folder, if you have one
if SWEEP is None:
    tmp = Path(tempfile.mkdtemp())
    (tmp / "small.toml").write_text("""
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
""")
    run_sweep(load_config(tmp / "small.toml"), tmp / "out", tmp / "cache", workers=1,
              progress=False)
    SWEEP = tmp / "out"
scenes = pd.read_parquet(Path(SWEEP) / "scenes")
rollouts = pd.read_parquet(Path(SWEEP) / "rollouts")
axes = [c[4:] for c in scenes.columns if c.startswith("set.") and scenes[c].nunique() > 1]
modes = [c.split(".")[0] for c in scenes.columns if c.endswith(".success")]
print(len(scenes), "scene rows,", len(rollouts), "rollouts; swept:", axes)

# %%
for axis in axes:
    fig = sweep_lines(scenes, axis, "success", modes)
    if os.environ.get("SHACC_FIGURES") and axis == axes[0]:
        fig.savefig(os.path.join(os.environ["SHACC_FIGURES"], "sweep_analysis.png"), dpi=90,
                    bbox_inches="tight")
    sweep_lines(scenes, axis, "delta_R_mean", modes)

# %%
if len(axes) >= 2:
    for mode in modes:
        sweep_heatmap(scenes, axes[0], axes[1], "success", mode)
    sweep_heatmap(scenes, axes[0], axes[1], "delta_R_mean", "shacc")

# %%
# Outcome mix per mode from the per-rollout table.
rollouts.groupby(["mode", "outcome"], observed=True).size().unstack(fill_value=0)
