# %% [markdown]
# # The shipped scenes, from above
#
# Every manual scene that ships with the project, seen from above: objects in black,
# initial position spaces in red, the spaces after Shrinking in blue, and the meta-skill
# clusters (K0, K1, ...). C_init and C_final are in each title.

# %%
import os

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.plots import scene_gallery

results = [precompute(load_scene(p)) for p in shipped_scene_paths()]
for r in results:
    print(f"{r.scene.name:28s} C_init {r.C_init:.3f} -> C_final {r.C_final:.3f}")

# %%
fig = scene_gallery(results, columns=4)
if os.environ.get("SHACC_FIGURES"):
    fig.savefig(os.path.join(os.environ["SHACC_FIGURES"], "scene_gallery.png"), dpi=80,
                bbox_inches="tight")
