"""The evaluation's answers held to a recording (``data/evaluation_reference.npz``, made
by ``data/make_evaluation_reference.py``): every rollout field and metric of the
shipped, extra and 16 random scenes, with collision checks off and on and with an
imperfect user, as the reference promises across processors and JAX versions
(docs/reference/outputs.md, "Reproducibility"): outcomes, activated tasks, steps, the
steps under each assistance and rates exactly, positions and path lengths within 1e-6
m, orientations (per component, up to sign) and delta_R within 1e-5."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).with_name("data")
sys.path.insert(0, str(DATA))
import make_evaluation_reference as recording  # noqa: E402

sys.path.remove(str(DATA))


@pytest.fixture(scope="module")
def reference():
    return dict(np.load(DATA / "evaluation_reference.npz"))


def test_every_rollout_is_the_recorded_one(reference):
    got = recording.evaluate_all()
    assert set(got) == {k for k in reference if not k.startswith("made_with/")}
    broken = recording.compare(got, reference)
    made = {k.split("/", 1)[1]: str(v) for k, v in reference.items()
            if k.startswith("made_with/")}
    here = recording.made_with()
    assert not broken, ("recorded with " + str(made) + "\nevaluated with " + str(here)
                        + "\n" + "\n".join(broken))
    assert (got["files/outcome"] >= 0).any() and (got["files_user/outcome"] == 0).any()


def test_the_promise_is_a_check_that_can_fail(reference):
    """The comparison catches what it promises to: one changed outcome, NaN moved, a
    position off by 2e-6 m; and it forgives what it allows: an orientation's sign and a
    position off by 5e-7 m."""
    key = "files/outcome"
    bad = reference[key].copy()
    bad.flat[0] = (bad.flat[0] + 1) % 4
    assert recording.compare({**reference, key: bad}, reference) == [
        f"{key}: 1 of {bad.size} differ"]
    dr = reference["files/delta_R"].copy()
    dr[np.isnan(dr)] = 0.0
    assert "NaN at other places" in recording.compare({**reference, "files/delta_R": dr},
                                                      reference)[0]
    point = reference["files/point"]
    assert recording.compare({**reference, "files/point": point + 2e-6}, reference)
    assert not recording.compare({**reference, "files/point": point + 5e-7,
                                  "files/orientation": -reference["files/orientation"]},
                                 reference)
