# %% [markdown]
# # Does clutteredness predict failure?
#
# From a `shacc reproduce` output (the one in `docs/reproduce` by default) or a sweep's
# `scenes` dataset (set SHACC_SWEEP to its folder; its first point is used), baseline
# success u_scene is plotted against the three scene measures, C (task-space overlap),
# d (object spread) and h (entropic clutteredness), with least-squares lines and Pearson's
# rho with 95 % bootstrap CIs (the paper's Fig. 6a). The scenes furthest from the line
# for C are shown from above, to see why C misjudges them.

# %%
import json
import os
from pathlib import Path

import numpy as np

from geometry_precompute import load_scene, precompute, random_scene, shipped_scene_paths
from sweeps.plots import correlation_panels, scene_gallery

if os.environ.get("SHACC_SWEEP"):
    import pandas as pd

    from sweeps.stats import pearson_ci

    table = pd.read_parquet(Path(os.environ["SHACC_SWEEP"]) / "scenes")
    table = table[table.point == table.point.min()]
    scenes = [{"name": row.scene, "C_init": row.C_init, "d": row.d, "h": row.h,
               "baseline": {"u_scene": row["baseline.success"]}} for _, row in table.iterrows()]
    u = np.array([s["baseline"]["u_scene"] for s in scenes])
    correlation = {k: pearson_ci([s[key] for s in scenes], u, 2000)
                   for k, key in (("d", "d"), ("h", "h"), ("C", "C_init"))}
else:
    SUMMARY = Path(os.environ.get("SHACC_REPRODUCE", "../docs/reproduce")) / "summary.json"
    summary = json.loads(SUMMARY.read_text())
    scenes, correlation = summary["scenes"], summary["correlation"]
    u = np.array([s["baseline"]["u_scene"] for s in scenes])
measures = {k: np.array([s[key] for s in scenes]) for k, key in
            (("d", "d"), ("h", "h"), ("C", "C_init"))}
print(f"{len(scenes)} scenes; rho:", {k: v["rho"] for k, v in correlation.items()})

# %%
fig = correlation_panels(u, measures, correlation)
if os.environ.get("SHACC_FIGURES"):
    fig.savefig(os.path.join(os.environ["SHACC_FIGURES"], "clutteredness.png"), dpi=90,
                bbox_inches="tight")

# %% [markdown]
# ## Outliers: the scenes furthest from the regression line of u on C

# %%
slope, intercept = np.polyfit(measures["C"], u, 1)
residual = u - (slope * measures["C"] + intercept)
worst = np.argsort(-np.abs(residual))[:3]
by_name = {load_scene(p).name: p for p in shipped_scene_paths()}


def rebuild(entry):
    """The scene behind a row: a shipped scene by name, or a random one from its seed
    (tasks 5 to 10, as reproduce makes them); None where it cannot be rebuilt."""
    if entry["name"] in by_name:
        return precompute(load_scene(by_name[entry["name"]]))
    parts = entry["name"].split("-")
    if len(parts) == 3 and parts[0] == "random":
        return precompute(random_scene(int(parts[2]), parts[1], 5, 10))
    return None


for i in worst:
    s = scenes[i]
    print(f"{s['name']}: C_init {s['C_init']:.2f}, u {u[i]:.2f}, "
          f"predicted {slope * s['C_init'] + intercept:.2f}")
pictures = [r for r in (rebuild(scenes[i]) for i in worst) if r is not None]
if pictures:
    fig = scene_gallery(pictures, columns=3)
