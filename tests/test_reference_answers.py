"""The evaluation's answers held to a recording (``data/evaluation_reference.npz``, made
by ``data/make_evaluation_reference.py`` before the host side was rebuilt): every
rollout field and metric of the shipped, extra and 16 random scenes, collisions off and
on, bit for bit."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).with_name("data")


@pytest.fixture(scope="module")
def reference():
    return dict(np.load(DATA / "evaluation_reference.npz"))


def test_every_rollout_is_the_recorded_one(reference):
    sys.path.insert(0, str(DATA))
    try:
        from make_evaluation_reference import FIELDS, batches
    finally:
        sys.path.remove(str(DATA))
    from sweeps.pipeline import evaluate_results

    for name, results in batches():
        ev = evaluate_results(results, ("baseline", "shrinking", "shacc"))
        got = {f: getattr(ev.evaluation.rollouts, f) for f in FIELDS}
        got.update(u_scene=ev.evaluation.metrics.u_scene,
                   delta_R_mean=ev.evaluation.metrics.delta_R_mean)
        for field, value in got.items():
            want = reference[f"{name}/{field}"]
            value = np.asarray(value)
            assert value.shape == want.shape and value.dtype == want.dtype, (name, field)
            # Bit for bit: NaNs where the recording has them, every other value equal.
            np.testing.assert_array_equal(value, want, err_msg=f"{name}/{field}")
        assert (got["outcome"] >= 0).any(), name  # the batch really ran
