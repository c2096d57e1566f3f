"""The plotting code the notebooks and reproduce call: each function draws what it says."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from sweeps.analysis import plots


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def test_correlation_panels():
    rng = np.random.default_rng(0)
    u = rng.uniform(size=10)
    measures = {"d": rng.uniform(size=10), "C": np.linspace(0, 0.5, 10)}
    corr = {"d": {"rho": 0.1, "ci": [-0.5, 0.6]}, "C": {"rho": -0.7, "ci": [-0.9, -0.4]}}
    fig = plots.correlation_panels(u, measures, corr)
    assert len(fig.axes) == 2
    assert "rho = -0.70 [-0.90, -0.40]" in fig.axes[1].get_title()
    assert len(fig.axes[1].lines) == 1  # the regression line


def test_category_bars_with_error_bars():
    entry = {"mean": 0.5, "ci": [0.4, 0.6]}
    cats = {c: {"n_scenes": 3, **{m: {"u_scene": entry} for m in ("baseline", "shacc")}}
            for c in ("cluttered", "all")}
    fig = plots.category_bars(cats, "u_scene", ("baseline", "shacc"))
    ax = fig.axes[0]
    assert len(ax.patches) == 4  # 2 categories x 2 modes
    assert [t.get_text() for t in ax.get_xticklabels()] == ["cluttered", "all"]


def test_success_fields_and_shadows(shipped_results):
    r = shipped_results[8]
    grid = (4, 3)
    outcome = np.random.default_rng(1).integers(0, 4, size=(2, 12, 3))
    fig = plots.success_fields(outcome, grid, (-0.45, 0.45), (0.02, 0.3), r.task_ids,
                               ("baseline", "shacc"))
    assert len(fig.axes) == 6 and len(fig.axes[0].images) == 1
    np.testing.assert_array_equal(fig.axes[0].images[0].get_array(),
                                  outcome[0, :, 0].reshape(4, 3).T)
    shadows = plots.space_shadows_yz(r.shapes_init)
    assert len(shadows) == 3
    # A side-grasp cylinder of radius 0.2 seen from the front spans 0.4 m in y.
    span = shadows[0][:, 0].max() - shadows[0][:, 0].min()
    assert span == pytest.approx(0.4, rel=0.02)
    fig = plots.success_fields_with_spaces(outcome, np.zeros((12, 3)), grid, (-0.45, 0.45),
                                           (0.02, 0.3), r, ("baseline", "shacc"))
    assert sum(len(ax.images) for ax in fig.axes) == 9


def test_scene_views(shipped_results):
    fig = plots.scene_gallery(shipped_results[:5], columns=3)
    drawn = [ax for ax in fig.axes if ax.axison]
    assert len(drawn) == 5
    assert shipped_results[0].scene.name in drawn[0].get_title()


def test_sweep_plots():
    rows = []
    for v in (0.1, 0.2):
        for k in (0.05, 0.1):
            for s in range(4):
                rows.append({"set.v_max": str(v), "set.shrink_step": str(k), "scene_index": s,
                             "shacc.success": v + k, "baseline.success": v})
    df = pd.DataFrame(rows)
    fig = plots.sweep_lines(df, "v_max", "success", ("baseline", "shacc"))
    assert fig.axes[0].get_xlabel() == "v_max"
    # The other swept setting is never pooled: a line per mode and value of shrink_step...
    labels = sorted(t.get_text() for t in fig.axes[0].get_legend().get_texts())
    assert labels == ["baseline, shrink_step=0.05", "baseline, shrink_step=0.1",
                      "shacc, shrink_step=0.05", "shacc, shrink_step=0.1"]
    # ... or, asked for, averaged within each scene and said so.
    fig = plots.sweep_lines(df, "v_max", "success", ("shacc",), others="marginalise")
    assert "mean over shrink_step" in fig.axes[0].get_title()
    line = fig.axes[0].lines[0]
    np.testing.assert_allclose(line.get_ydata(), [0.175, 0.275])
    fig = plots.sweep_heatmap(df, "v_max", "shrink_step", "success", "shacc")
    np.testing.assert_allclose(fig.axes[0].images[0].get_array(), [[0.15, 0.25], [0.2, 0.3]])
    # Every helper draws into a caller's axes (panels of one figure).
    import matplotlib.pyplot as plt

    panel, axes = plt.subplots(1, 2)
    plots.sweep_lines(df, "v_max", "success", ("shacc",), ax=axes[0])
    plots.sweep_heatmap(df, "v_max", "shrink_step", "success", "shacc", ax=axes[1])
    assert axes[0].lines and axes[1].images and len(panel.axes) == 3  # + the colour bar
