"""What each simulated user does to the paper's modes on the shipped scenes.

    python benchmarks/users_effect.py [USER ...]

Per user kind (perfect, white noise, a wandering hand, tremor, the two-mode joystick, a
change of mind): the mean over the twelve shipped scenes of u_scene in the baseline
and ShaCC modes, ShaCC's paired advantage with a 95 % bootstrap interval over scenes,
and the mean time to activation and path length of the successes. Every user is
evaluated with seed 1; all stepped users share one compiled program. The model page's
table ("Simulated users") comes from this.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np

from geometry_precompute import load_scene, precompute, shipped_scene_paths
from sweeps.analysis.stats import paired_diff_ci
from sweeps.pipeline import evaluate_results

USERS = {"perfect": {}, "white 0.3": {"user_noise": 0.3},
         "wander 0.3 tau 0.5": {"user_noise": 0.3, "user_noise_tau": 0.5},
         "wander 0.3 tau 1.0": {"user_noise": 0.3, "user_noise_tau": 1.0},
         "tremor 0.01": {"user_tremor": 0.01},
         "joystick": {"user_input": "modes"},
         "switch 1.0": {"user_switch": 1.0}}
MODES = ("baseline", "shacc")


def main(names: list[str]) -> None:
    unknown = sorted(set(names) - set(USERS))
    if unknown:
        raise SystemExit(f"unknown user {unknown}; known: {', '.join(USERS)}")
    scenes = [load_scene(p) for p in shipped_scene_paths()]
    results = [precompute(s, s.settings()) for s in scenes]
    max_tasks = max(len(r.spaces) for r in results)
    print(f"{len(results)} scenes; u_scene mean over scenes; time (s) and path (m) of "
          "the successes, baseline / shacc")
    for name in names or list(USERS):
        t0 = time.perf_counter()
        batch = [replace(r, settings=r.settings.with_overrides({**USERS[name], "seed": 1}))
                 for r in results]
        me = evaluate_results(batch, MODES, max_tasks=max_tasks).evaluation.metrics
        u = np.asarray(me.u_scene)
        d = paired_diff_ci(u[:, 0], u[:, 1], 2000, 0)
        tm, pl = np.nanmean(me.time_mean, 0), np.nanmean(me.path_length_mean, 0)
        print(f"{name:20s} baseline {u[:, 0].mean():.3f} shacc {u[:, 1].mean():.3f} "
              f"advantage {100 * d['mean']:+.1f} pp [{100 * d['ci'][0]:+.1f}, "
              f"{100 * d['ci'][1]:+.1f}]  time {tm[0]:.2f} / {tm[1]:.2f}  path "
              f"{pl[0]:.3f} / {pl[1]:.3f}  ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
