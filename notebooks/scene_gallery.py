# %% [markdown]
# # The shipped scenes, from above
#
# Every manual scene that ships with the project (or the scene files you list in
# `SCENES`), seen from above: objects in black, initial position spaces in red, the
# spaces after Shrinking in blue, and the meta-skill clusters (K0, K1, ...). C_init and
# C_final are in each title.

# %% tags=["parameters"]
SCENES = None   # scene files (TOML or JSON) to draw; None: every shipped scene
COLUMNS = 4     # panels per row
FIGURES = None  # a folder to save the figure in as scene_gallery.png; None: show only

# %%
from pathlib import Path

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.analysis.plots import scene_gallery

paths = shipped_scene_paths() if SCENES is None else [Path(p) for p in SCENES]
results = [precompute(load_scene(p)) for p in paths]
for r in results:
    print(f"{r.scene.name:28s} C_init {r.C_init:.3f} -> C_final {r.C_final:.3f}")

# %%
fig = scene_gallery(results, columns=COLUMNS)
if FIGURES:
    fig.savefig(Path(FIGURES) / "scene_gallery.png", dpi=80, bbox_inches="tight")
