# %% [markdown]
# # What do the Automaton's speed and the Shrinking step change?
#
# Loads a sweep's Parquet tables (by default it runs a small sweep first: 8 random
# scenes x 3 speeds x 2 shrink steps on a 3 x 3 start grid) and plots success rate and
# delta_R against each swept setting per mode, with bootstrap CIs over scenes, and a
# heat map for the two-axis grid.

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
[axes]
v_max = [0.1, 0.15, 0.3]
shrink_step = [0.05, 0.2]
start_grid = [[3, 3]]
""")
    run_sweep(load_config(tmp / "small.toml"), tmp / "out", tmp / "cache", workers=1,
              progress=False)
    SWEEP = tmp / "out"
scenes = pd.read_parquet(Path(SWEEP) / "scenes.parquet")
rollouts = pd.read_parquet(Path(SWEEP) / "rollouts.parquet")
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
    sweep_heatmap(scenes, axes[0], axes[1], "success", "shacc")
    sweep_heatmap(scenes, axes[0], axes[1], "delta_R_mean", "shacc")

# %%
# Outcome mix per mode from the per-rollout table.
rollouts.groupby(["mode", "outcome"], observed=True).size().unstack(fill_value=0)
