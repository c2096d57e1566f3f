"""One-line help where a user errs: a misspelt setting, scene field, config key, mode or
command names the one it most likely meant (``errors.did_you_mean``), and a name too far
from any gets no guess."""

from __future__ import annotations

import pytest

from geometry_precompute import InputError, scene_from_dict, shipped_scene_paths
from geometry_precompute.errors import did_you_mean
from sweeps.app.cli import main

SCENE = str(shipped_scene_paths()[0])


@pytest.mark.parametrize(("argv", "hint"), [
    (["evaluate", SCENE, "--set", "v_mx=0.2"], "v_mx: unknown setting; did you mean v_max?"),
    (["evaluate", SCENE, "--set", "side_grasp.radius_margn=0.1"],
     "did you mean side_grasp.radius_margin?"),
    (["evaluate", SCENE, "--modes", "shac"], "invalid choice: 'shac'"),
    (["evaluat", SCENE], "invalid choice: 'evaluat'"),
])
def test_the_command_line_names_the_likely_one(argv, hint, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert hint in err and len(err.splitlines()) == 1, err
    if "invalid choice" in hint:
        assert err.split("; did you mean ")[1].startswith("shacc?" if "shac'" in hint
                                                          else "evaluate?")


def test_a_scene_field_and_a_config_key(tmp_path):
    import tomllib

    data = tomllib.loads(open(SCENE).read())
    data["objects"][0]["raduis"] = data["objects"][0].pop("radius", 0.04)
    with pytest.raises(InputError, match=r"raduis: unknown field; did you mean radius\?"):
        scene_from_dict(data, "s.toml")
    from sweeps.config import load_config

    cfg = tmp_path / "c.toml"
    cfg.write_text('nmae = "x"\n[source]\nkind = "random"\ncount = 2\n')
    with pytest.raises(InputError, match=r"nmae: unknown field; did you mean name\?"):
        load_config(cfg)


def test_no_guess_where_nothing_is_close():
    assert did_you_mean("warp_speed", ["v_max", "dt", "seed"]) == ""
    assert did_you_mean("seeds", ["v_max", "dt", "seed"]) == "; did you mean seed?"
