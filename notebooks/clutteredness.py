# %% [markdown]
# # Does clutteredness predict failure?
#
# From a `shacc reproduce` output (the one in `docs/reproduce` by default) or a sweep's
# `scenes` dataset (`SWEEP`; its first point is used), baseline success u_scene is
# plotted against the three scene measures, C (task-space overlap), d (object spread)
# and h (entropic clutteredness), with least-squares lines and Pearson's rho with 95 %
# scene-bootstrap CIs (the paper's Fig. 6a). The task count predicts failure too, so C
# is also correlated with success with the task count held fixed (a partial
# correlation). The scenes furthest from the line for C are shown from above, to see
# why C misjudges them.

# %% tags=["parameters"]
REPRODUCE = "../docs/reproduce"  # a `shacc reproduce --out` folder (its summary.json)
SWEEP = None      # or a sweep's --out folder; used instead of REPRODUCE when set
RESAMPLES = 2000  # bootstrap resamples per CI
FIGURES = None    # a folder to save the figure in as clutteredness.png; None: show only

# %%
import json
from pathlib import Path

import numpy as np

from geometry_precompute import load_scene, precompute, random_scene, shipped_scene_paths
from sweeps.analysis.plots import correlation_panels, scene_gallery
from sweeps.analysis.stats import partial_corr_ci, pearson_ci

if SWEEP:
    import pandas as pd

    table = pd.read_parquet(Path(SWEEP) / "scenes")
    table = table[table.point == table.point.min()]
    scenes = [{"name": row.scene, "C_init": row.C_init, "d": row.d, "h": row.h,
               "n_tasks": row.n_tasks, "baseline": {"u_scene": row["baseline.success"]}}
              for _, row in table.iterrows()]
else:
    summary = json.loads((Path(REPRODUCE) / "summary.json").read_text())
    scenes = summary["scenes"]
u = np.array([s["baseline"]["u_scene"] for s in scenes])
measures = {k: np.array([s[key] for s in scenes]) for k, key in
            (("d", "d"), ("h", "h"), ("C", "C_init"))}
correlation = {k: pearson_ci(v, u, RESAMPLES) for k, v in measures.items()}
print(f"{len(scenes)} scenes; rho:", {k: round(v["rho"], 3) for k, v in correlation.items()})

# %%
fig = correlation_panels(u, measures, correlation)
if FIGURES:
    fig.savefig(Path(FIGURES) / "clutteredness.png", dpi=90, bbox_inches="tight")

# %% [markdown]
# ## C with the task count held fixed

# %%
n_tasks = np.array([s.get("n_tasks", np.nan) for s in scenes], dtype=float)
if np.isfinite(n_tasks).all() and np.ptp(n_tasks) > 0:
    print("rho(u, task count):", pearson_ci(n_tasks, u, RESAMPLES))
    print("rho(u, C | task count):", partial_corr_ci(measures["C"], u, n_tasks, RESAMPLES))
else:
    print("every scene has the same task count (or none is recorded): nothing to hold fixed")

# %% [markdown]
# ## Outliers: the scenes furthest from the regression line of u on C

# %%
slope, intercept = np.polyfit(measures["C"], u, 1)
residual = u - (slope * measures["C"] + intercept)
worst = np.argsort(-np.abs(residual))[:3]
by_name = {load_scene(p).name: p for p in shipped_scene_paths()}


def rebuild(entry):
    """The scene behind a row: a shipped scene by name, or a random one from its name
    (random-[PRESET-]KIND-SEED, tasks 5 to 10 as reproduce makes them); None where it
    cannot be rebuilt."""
    if entry["name"] in by_name:
        return precompute(load_scene(by_name[entry["name"]]))
    parts = entry["name"].split("-")
    if parts[0] == "random" and len(parts) in (3, 4) and parts[-1].isdigit():
        preset = parts[1] if len(parts) == 4 else "compact"
        return precompute(random_scene(int(parts[-1]), parts[-2], 5, 10, preset))
    return None


for i in worst:
    s = scenes[i]
    print(f"{s['name']}: C_init {s['C_init']:.2f}, u {u[i]:.2f}, "
          f"predicted {slope * s['C_init'] + intercept:.2f}")
pictures = [r for r in (rebuild(scenes[i]) for i in worst) if r is not None]
if pictures:
    fig = scene_gallery(pictures, columns=3)
