"""The simulated users' failures on hand-built geometry (shacc_jax.user_models): a
two-mode joystick walks an L through a space a straight path misses, and a switch of
mode costs its time; a change of mind heads for the other task first and activates it
where it lies on the way; the withdrawn lag is refused wherever it is named."""

from __future__ import annotations

import json

import numpy as np
import pytest

import shacc_jax
from geometry_precompute import InputError, bake, precompute, scene_from_dict
from sweeps.app.cli import main

ONE_START = {"start_grid": [1, 1], "start_plane_offset": 0.45, "start_y_halfwidth": 0.0,
             "start_z_range": [0.35, 0.35], "start_orientation": "forward"}
# A mug's top grasp: a disk 0.15 m in radius, z in [0.18, 0.22], centred at x = 0.3. The
# start (-0.15, 0, 0.35) sees its nearest point (0.15, 0, 0.22): 0.30 m ahead, 0.13 m
# down.
TARGET = {"id": "target", "kind": "mug", "position": [0.30, 0.0, 0.0]}
TOP = {"id": "top", "object": "target", "template": "top_grasp"}


def _rollout(doc: dict, **settings):
    """Baseline's rollout of task 0 from the one start: (outcome, activated, step,
    point, path length)."""
    scene = scene_from_dict(doc, "hand-built.toml")
    r = precompute(scene, scene.settings().with_overrides(settings))
    ro = shacc_jax.run(bake([r]), ("baseline",)).evaluation.rollouts
    return (shacc_jax.OUTCOMES[int(ro.outcome[0, 0, 0, 0])], int(ro.activated[0, 0, 0, 0]),
            int(ro.step[0, 0, 0, 0]), np.asarray(ro.point[0, 0, 0, 0]),
            float(ro.path_length[0, 0, 0, 0]))


def test_the_joystick_walks_an_l_and_a_switch_costs_its_time():
    """The command (0.30, 0, -0.13) is longer across than down: the joystick starts in
    the horizontal mode and moves 3 mm a step along x; it switches when the horizontal
    part (0.15 - x) falls under half the vertical one (0.065), i.e. at x > 0.085: after
    79 steps (x = 0.087). Without a switch time the 80th step goes down; with 0.5 s it
    waits 25 steps first. The path is the L's (0.30 + 0.13 m, not the straight 0.327
    m), and every switch costs its 25 steps."""
    doc = {"name": "joystick-l", "objects": [TARGET], "tasks": [TOP], "settings": ONE_START}
    straight = _rollout(doc)
    assert straight[:3] == ("success", 0, 109) and straight[4] == pytest.approx(0.327, abs=1e-3)
    horizontal = _rollout(doc, user_input="modes", user_mode_switch_s=0.0, max_steps=79)
    np.testing.assert_allclose(horizontal[3], [0.087, 0.0, 0.35], atol=1e-6)
    down = _rollout(doc, user_input="modes", user_mode_switch_s=0.0, max_steps=80)
    np.testing.assert_allclose(down[3], [0.087, 0.0, 0.347], atol=1e-6)
    for steps, z in ((80, 0.35), (104, 0.35), (105, 0.347)):  # 25 steps without motion
        waited = _rollout(doc, user_input="modes", max_steps=steps)
        np.testing.assert_allclose(waited[3], [0.087, 0.0, z], atol=1e-6)
    quick = _rollout(doc, user_input="modes", user_mode_switch_s=0.0)
    slow = _rollout(doc, user_input="modes")
    assert quick[0] == slow[0] == "success"
    np.testing.assert_allclose(quick[3], [0.15, 0.0, 0.22], atol=1e-4)
    assert quick[4] == pytest.approx(0.43, abs=1e-4) == slow[4]
    switches, rest = divmod(slow[2] - quick[2], 25)
    assert rest == 0 and switches >= 2  # down, then across again (and more near the end)


def test_the_joystick_passes_through_a_space_a_straight_path_misses():
    """A tower's top-grasp disk (z in [0.33, 0.37], x in [-0.063, 0.237]) lies where the
    joystick's horizontal leg runs at z = 0.35, above the straight path (which is at z
    = 0.31 by x = -0.063): the straight user reaches its mug, the joystick activates the
    tower's task first, after 29 steps."""
    tower = {"id": "tower", "kind": "box", "position": [0.087, 0.0, 0.0],
             "half_extents": [0.03, 0.03, 0.125]}
    doc = {"name": "joystick-tower", "objects": [TARGET, tower],
           "tasks": [TOP, {"id": "tower-top", "object": "tower", "template": "top_grasp"}],
           "settings": {**ONE_START, "start_plane_offset": 0.237}}
    assert _rollout(doc)[:2] == ("success", 0)
    joystick = _rollout(doc, user_input="modes")
    assert joystick[:3] == ("wrong", 1, 29)
    np.testing.assert_allclose(joystick[3], [-0.063, 0.0, 0.35], atol=1e-5)


def test_a_change_of_mind_activates_the_task_on_the_way():
    """At z = 0.08 m, the start (-0.15, 0, 0.08), a mug's side grasp ahead (radius 0.2
    about x = 0.6) and another's to the side (about (0.15, 0.25)): the straight path
    along y = 0 passes 0.05 m clear of the side one. A user who first heads for the
    side task and turns only when 90 % of the way there cuts through that space on its
    way back (wrong, task 1); one who turns at 10 % of the way still passes it
    (success, later); at user_switch_at near 0 the rollout is the one without a change
    of mind."""
    side = {"id": "side", "kind": "mug", "position": [0.15, 0.25, 0.0]}
    ahead = {"id": "ahead", "kind": "mug", "position": [0.6, 0.0, 0.0]}
    ballast = {"id": "ballast", "kind": "mug", "position": [0.6, -0.25, 0.0]}  # mean y 0
    doc = {"name": "change-of-mind", "objects": [ahead, side, ballast],
           "tasks": [{"id": "ahead-side", "object": "ahead", "template": "side_grasp"},
                     {"id": "side-side", "object": "side", "template": "side_grasp"}],
           "settings": {**ONE_START, "start_plane_offset": 0.3, "start_z_range": [0.08, 0.08]}}
    alone = _rollout(doc)
    assert alone[:2] == ("success", 0)
    late = _rollout(doc, user_switch=1.0, user_switch_at=0.9)
    assert late[:2] == ("wrong", 1)
    early = _rollout(doc, user_switch=1.0, user_switch_at=0.1)
    assert early[:2] == ("success", 0) and early[2] > alone[2]
    # Near 0, in float32 (1 - 1e-9) is 1: turned at the start, the same rollout as a user
    # without a change of mind (both stepped, by the same small noise).
    never = _rollout(doc, user_switch=0.0, user_noise=0.01)
    at_once = _rollout(doc, user_switch=1.0, user_switch_at=1e-9, user_noise=0.01)
    assert never[:3] == at_once[:3]
    np.testing.assert_array_equal(never[3], at_once[3])


WITHDRAWN = "user_lag: withdrawn: repeating the previous step is the same step"


def test_the_withdrawn_lag_is_refused_in_python():
    from geometry_precompute import DEFAULTS

    for value in (0.3, {"uniform": [0, 0.5]}):
        with pytest.raises(InputError, match="user_lag: withdrawn") as e:
            DEFAULTS.with_overrides({"user_lag": value})
        assert "user_noise_tau" in str(e.value) and "user_switch" in str(e.value)


@pytest.mark.parametrize("where", ["scene", "set", "config", "population"])
def test_the_withdrawn_lag_is_one_line_and_writes_nothing(tmp_path, capsys, where):
    scene = tmp_path / "s.toml"
    text = ('name = "s"\n[[objects]]\nid = "m"\nkind = "mug"\nposition = [0.0, 0.0, 0.0]\n'
            '[[tasks]]\nid = "g"\nobject = "m"\ntemplate = "side_grasp"\n')
    if where == "scene":
        text += "[settings]\nuser_lag = 0.3\n"
    scene.write_text(text)
    out = tmp_path / "out"
    if where in ("scene", "set"):
        argv = ["evaluate", str(scene), "--json", str(out / "e.json")]
        if where == "set":
            argv += ["--set", "user_lag=0.3"]
    else:
        value = "0.3" if where == "config" else "{uniform = [0.0, 0.5]}"
        cfg = tmp_path / "c.toml"
        cfg.write_text(f'name = "c"\n[source]\nkind = "files"\npath = "."\n[axes]\n'
                       f"user_lag = [{value}]\n")
        argv = ["sweep", str(cfg), "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and WITHDRAWN in err, err
    assert not out.exists()
    json.dumps(err)  # one plain line
