"""How long an approach took and which assistance it got: the per-rollout time to
activation, path length and assisted steps of the one-scene JSON, their per-mode means
and shares (recomputed here from the per-rollout lists), the same numbers from the
device's metrics, and the drawn-user sentences of a population's summary and report."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from geometry_precompute import DEFAULTS
from sweeps.app.cli import main

SCENE = "geometry_precompute/scenes/03_three_mugs_row_tight.toml"
WANDERING = ["--set", "user_noise={uniform = [0.0, 0.6]}", "--set", "user_noise_tau=0.5",
             "--set", "seed=3"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The perfect user's and a wandering population's one-scene JSON objects, and the
    summary the population's evaluate printed."""
    folder = tmp_path_factory.mktemp("how-long")
    out: dict = {"folder": folder}
    for name, extra in (("perfect", []), ("wandering", WANDERING)):
        path = folder / f"{name}.json"
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            assert main(["evaluate", SCENE, "--json", str(path), *extra]) == 0
        out[name] = json.loads(path.read_text())
        out[f"{name}.printed"] = printed.getvalue()
    return out


def test_means_and_shares_are_those_of_the_rollouts(runs):
    dt = DEFAULTS["dt"]
    for d in (runs["perfect"], runs["wandering"]):
        for mode, e in d["modes"].items():
            success = np.array(e["outcome"]) == "success"
            time = np.array(e["time_to_activation"], float)
            steps = np.array(e["assist_steps"], np.int64)  # (N, T, 4)
            # Every step is under exactly one kind of assistance.
            np.testing.assert_allclose(steps.sum(-1) * dt, time, rtol=1e-9)
            assert e["time_to_activation_mean"] == pytest.approx(time[success].mean(), 1e-9)
            assert e["path_length_mean"] == pytest.approx(
                np.array(e["path_length"])[success].mean(), 1e-6)
            share = steps.sum((0, 1)) / steps.sum()
            got = [e["assistance"][k] for k in ("none", "scene", "correct", "wrong")]
            np.testing.assert_allclose(got, share, rtol=1e-9)
            # The paper's modes: only ShaCC's meta skill assists, and always correctly
            # placed in the scene (no intent inferred, nothing to get wrong).
            assert got[2] == got[3] == 0.0
            assert (got[1] > 0) == (mode == "shacc"), mode
    assert runs["perfect"]["modes"]["shacc"]["assistance"]["scene"] > 0.05


def test_the_perfect_users_path_is_its_steps(runs):
    """The perfect user moves v_max dt a step (the last one shorter) on a straight line
    in the baseline: path length = time x v_max, less at most one step."""
    e = runs["perfect"]["modes"]["baseline"]
    v = DEFAULTS["v_max"]
    length = np.array(e["path_length"], float)
    time = np.array(e["time_to_activation"], float)
    done = np.array(e["outcome"]) != "timeout"
    assert (length[done] <= time[done] * v + 1e-6).all()
    assert (length[done] >= (time[done] - DEFAULTS["dt"]) * v - 1e-6).all()


def test_a_wandering_hand_takes_longer_and_walks_further(runs):
    for mode in ("baseline", "shacc"):
        p, w = runs["perfect"]["modes"][mode], runs["wandering"]["modes"][mode]
        assert w["time_to_activation_mean"] > 1.05 * p["time_to_activation_mean"], mode
        assert w["path_length_mean"] > 1.05 * p["path_length_mean"], mode
    assert "users" in runs["wandering"] and "users" not in runs["perfect"]
    assert "wandering hand" in runs["wandering"]["user"]
    assert runs["perfect"]["user"].startswith("perfect")


def test_a_populations_summary_and_report_say_what_the_drawn_values_did(runs):
    """The summary prints, per drawn setting, ShaCC's advantage in its lowest quartile
    and its highest; the report tabulates the bins; a fixed user gets neither."""
    assert "as drawn:" not in runs["perfect.printed"]
    out = runs["wandering.printed"]
    said = [line for line in out.splitlines() if "as drawn:" in line]
    assert len(said) == 1 and said[0].strip().startswith("Direction noise (rad), as drawn:")
    assert "ShaCC's advantage goes" in said[0]  # one scene: no CI over scenes, no verdict
    assert "time (s)" in out and "assisted:" in out
    folder = runs["folder"]
    for name in ("perfect", "wandering"):
        assert main(["report", str(folder / f"{name}.json"), "--out",
                     str(folder / f"{name}.html")]) == 0
    assert "drawn users" not in (folder / "perfect.html").read_text()
    page = (folder / "wandering.html").read_text()
    assert "Success against the drawn users" in page and "How long, and how assisted" in page
    assert page.count("<tr>", page.index("drawn users")) >= 5  # a head and four bins
