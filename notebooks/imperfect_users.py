# %% [markdown]
# # Imperfect users: where does a wandering, trembling user still reach each task?
#
# The paper's Automaton is one perfect user: a straight line at full speed to the
# closest point of its task's space. Here the same scene is attempted from every start
# of a grid twice, by that perfect user and by an imperfect one (a wandering hand whose
# direction error drifts with a correlation time, a tremor, and a change of mind;
# reference/model, "Simulated users"), in the baseline and ShaCC modes (or any others:
# `MODES` may add the intent-inference modes blend, ho and shacc_ho). The panels
# colour each start by its outcome; the last figure marks the starts where the perfect
# user succeeds and the imperfect one does not, per mode, and a table says how long
# the successful approaches took.

# %% tags=["parameters"]
SCENE = None    # a scene file; None: the shipped scene 09_mug_behind_two
GRID = 16       # starts per side of the start plane; 64 for publication figures
NOISE = 0.3     # user_noise, rad: the wandering hand's stationary direction error
TAU = 0.5       # user_noise_tau, s: its correlation time (0: white noise)
TREMOR = 0.01   # user_tremor, m (at user_tremor_hz, 5 Hz by default)
SWITCH = 0.2    # user_switch: the probability of heading for another task first
SEED = 0        # the users' random numbers
MODES = ("baseline", "shacc")  # any of shacc_jax.ALL_MODES but optimized, e.g. "shacc_ho"
FIGURES = None  # a folder to save the figures in (imperfect_users*.png); None: show only

# %%
from dataclasses import replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from shacc_jax import OUTCOMES
from shacc_jax.types import ASSISTANCE
from sweeps.analysis.plots import success_fields
from sweeps.pipeline import evaluate_results

path = SCENE or next(p for p in shipped_scene_paths() if "mug_behind_two" in p.name)
scene = load_scene(path)
perfect = precompute(scene, scene.settings(overrides={"start_grid": [GRID, GRID]}))
user = {"user_noise": NOISE, "user_noise_tau": TAU, "user_tremor": TREMOR,
        "user_switch": SWITCH, "seed": SEED}
imperfect = replace(perfect, settings=perfect.settings.with_overrides(user))
modes = tuple(MODES)
runs = {"perfect": evaluate_results([perfect], modes),
        "imperfect": evaluate_results([imperfect], modes)}
T = len(perfect.spaces)
rates = pd.DataFrame({who: dict(zip(modes, ev.evaluation.metrics.u_scene[0], strict=True))
                      for who, ev in runs.items()}).round(3)
rates.index.name = "success u_scene"
rates

# %%
s = perfect.settings
y_c = float(np.mean([o.position[1] for o in scene.objects]))
w = s["start_y_halfwidth"]
outcome = np.concatenate([runs[who].evaluation.rollouts.outcome[0, :, :, :T]
                          for who in runs])  # (2 users x 2 modes, N, T)
labels = [f"{mode}, {who}" for who in runs for mode in modes]
fig = success_fields(outcome, (GRID, GRID), (y_c - w, y_c + w), s["start_z_range"],
                     perfect.task_ids, labels,
                     title=f"{scene.name}: perfect and imperfect users ({GRID} x {GRID})")
if FIGURES:
    fig.savefig(Path(FIGURES) / "imperfect_users.png", dpi=90, bbox_inches="tight")

# %% [markdown]
# ## Where the imperfect user loses what the perfect one had
#
# A start counts here when the perfect user succeeds from it and the imperfect one does
# not (outcome "lost"); the opposite (an imperfect user's lucky detour) is "won". The
# random numbers are the same in both modes, so the modes compare start by start.

# %%
success = OUTCOMES.index("success")
per = runs["perfect"].evaluation.rollouts.outcome[0, :, :, :T] == success
imp = runs["imperfect"].evaluation.rollouts.outcome[0, :, :, :T] == success
changes = pd.DataFrame({"lost": (per & ~imp).sum(axis=(1, 2)),
                        "won": (~per & imp).sum(axis=(1, 2)),
                        "rollouts": per[0].size}, index=list(modes))
# The same as fields: per mode (rows) and task (columns), each start kept (the
# imperfect user succeeds too), lost, won, or failed by both users.
kinds = ["kept", "lost", "won", "failed by both"]
field = np.select([per & imp, per & ~imp, ~per & imp], [0, 1, 2], 3)
fig, axes = plt.subplots(len(modes), T, figsize=(3.0 * T, 2.6 * len(modes)), squeeze=False)
cmap = ListedColormap(["#2ca02c", "#d62728", "#1f77b4", "#c7c7c7"])
for m, mode in enumerate(modes):
    for t in range(T):
        a = axes[m, t]
        a.imshow(field[m, :, t].reshape(GRID, GRID).T, origin="lower", cmap=cmap, vmin=-0.5,
                 vmax=3.5, extent=(y_c - w, y_c + w, *s["start_z_range"]), aspect="auto")
        a.set_title(f"{mode}: {perfect.task_ids[t]}", fontsize=8)
        a.set_xlabel("y (m)")
    axes[m, 0].set_ylabel("z (m)")
fig.legend(handles=[Patch(color=cmap(i), label=k) for i, k in enumerate(kinds)],
           loc="lower center", ncol=4, fontsize=8)
fig.tight_layout(rect=(0, 0.06, 1, 1))
if FIGURES:
    fig.savefig(Path(FIGURES) / "imperfect_users_lost.png", dpi=90, bbox_inches="tight")
changes

# %% [markdown]
# ## How long the successful approaches took
#
# Per user and mode: the mean time to activation (s) and path length (m) of the
# successes, and the share of all steps under each kind of assistance: none, ShaCC's
# meta skill (scene), and, in the intent-inference modes, assistance towards the
# intended task (correct) or towards another (wrong: a change of mind is where an
# inferred goal is wrong first).

# %%
pd.DataFrame({f"{who}, {mode}": {
    "time (s)": ev.evaluation.metrics.time_mean[0, m],
    "path (m)": ev.evaluation.metrics.path_length_mean[0, m],
    **{f"{kind} share": ev.evaluation.metrics.assist_fraction[0, m, k]
       for k, kind in enumerate(ASSISTANCE)}}
    for who, ev in runs.items() for m, mode in enumerate(modes)}).T.round(3)
