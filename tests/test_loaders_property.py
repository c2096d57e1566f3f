"""Property tests that generate the classes of bad input, run through the loaders in
process: a valid scene, config or setting, or the one-line error, and nothing else.

The documents start valid (a shipped scene with every optional key, the laptop sweep
config) and are mutated field by field: wrong types, numbers too large for a float or
an int64, tiny and non-finite numbers, unicode and control characters, deep nesting,
missing and extra keys. Whatever the loader accepts must also precompute.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from geometry_precompute import (
    SPECS,
    InputError,
    load_scene,
    precompute,
    scene_from_dict,
    shipped_scene_paths,
)
from geometry_precompute.fileio import MAX_DEPTH, MAX_TEXT_BYTES
from sweeps.app.inputs import parse_sets
from sweeps.config import load_config, parse_config

SCENE = tomllib.loads((shipped_scene_paths()[11]).read_text())  # a box, a mug and a cup
SCENE["objects"][1]["radius"] = 0.05
SCENE["objects"][1]["height"] = 0.12
SCENE["objects"][2]["yaw"] = 0.5
SCENE["tasks"][1]["bounds"] = {"radius": [0.1, 0.18]}
SCENE["tasks"][1]["fixed"] = {"height": 0.2}
SCENE["settings"] = {"v_max": 0.2, "side_grasp": {"radius_margin": 0.05}}
CONFIG_PATH = Path(__file__).parents[1] / "sweeps" / "configs" / "laptop.toml"
CONFIG = tomllib.loads(CONFIG_PATH.read_text())
CONFIG["settings"] = {"start_grid": [4, 4]}
CONFIG["points"] = [{"v_max": 0.3}]

# Values of every kind a TOML document (or a Python caller) can hold, the awkward ones
# first among equals.
huge_ints = st.sampled_from([2**63, -(2**63) - 1, 10**400, -(10**400), 2**31, 2**53 + 1])
odd_floats = st.sampled_from([math.inf, -math.inf, math.nan, 1e308, -1e308, 5e-324, -0.0,
                              1e-300, 1e30])
texts = st.text(max_size=12) | st.sampled_from(["", " ", "a\nb", "\x1b[31m", "é€😀", "\0",
                                               "mug", "side_grasp", "box", "-1"])
scalars = (st.integers(-10**6, 10**6) | huge_ints | st.floats(allow_nan=True) | odd_floats
           | st.booleans() | texts)


def deep(value, levels: int):
    for _ in range(levels):
        value = [value]
    return value


nums = st.floats(-1.0, 1.0) | st.integers(-3, 3) | st.sampled_from([0.045, 0.2, 0.5236, 3.2])
containers = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                          | st.dictionaries(texts, inner, max_size=3), max_leaves=6)
values = st.one_of(scalars, nums, nums, containers,
                   st.builds(deep, scalars, st.sampled_from([MAX_DEPTH - 3, MAX_DEPTH + 5])))


def paths_of(doc, prefix=()):
    """Every (path, value) of a nested document, tables and arrays included, down to
    six levels (not into a deep value inserted by an earlier mutation)."""
    yield prefix, doc
    if len(prefix) >= 6:
        return
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from paths_of(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from paths_of(v, (*prefix, i))


@st.composite
def mutated(draw, doc):
    """``doc`` with one to three fields replaced, deleted or added."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        spots = [p for p, _ in paths_of(doc) if p]
        if not spots:  # everything deleted already
            break
        path = draw(st.sampled_from(spots))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        action = draw(st.sampled_from(["replace", "replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(values)
        elif action == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(texts)] = draw(values)
        else:
            parent.append(draw(values))
    return doc


def one_line_error(e: InputError, source: str | None = None) -> None:
    text = str(e)
    assert "\n" not in text and "\r" not in text and len(text) <= 2000, text
    if source is not None:
        assert text.startswith(source), text


@settings(max_examples=400, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(SCENE))
def test_mutated_scene_is_a_scene_or_one_line_error(doc):
    try:
        scene = scene_from_dict(doc, "mutated.toml")
    except InputError as e:
        one_line_error(e, "mutated.toml")
        return
    try:  # accepted: it must run
        precompute(scene)
    except InputError as e:  # objects that interpenetrate are found here
        one_line_error(e, "mutated.toml")


@settings(max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(SCENE))
def test_mutated_scene_file_is_a_scene_or_one_line_error(tmp_path_factory, doc):
    """The same through a TOML file, for the documents TOML can hold."""
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError, RecursionError):
        return  # not a TOML document (None, a NaN key...): the in-process test covers it
    path = tmp_path_factory.mktemp("scene") / "s.toml"
    path.write_text(text, encoding="utf-8")
    try:
        load_scene(path)
    except InputError as e:
        one_line_error(e, str(path))


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(mutated(CONFIG))
def test_mutated_sweep_config_is_a_config_or_one_line_error(doc):
    try:
        cfg = parse_config(doc, "sweep.toml", CONFIG_PATH.parent)
    except InputError as e:
        one_line_error(e, "sweep.toml")
        return
    assert cfg.points and cfg.chunk >= 1
    from sweeps.distributed.runner import dry_run

    plan = dry_run(cfg, workers=2)  # accepted: its plan and estimates can be made
    assert plan["points"] == len(cfg.points)


@settings(max_examples=200)
@given(st.sampled_from(sorted(SPECS)), texts
       | st.from_regex(r"-?[0-9]{1,400}(\.[0-9]*)?(e-?[0-9]{1,4})?", fullmatch=True)
       | st.sampled_from(["[1, 2]", "[1e400, 2]", "inf", "nan", "1e400", "[]", "[[", "0x10",
                          "true", "forward", "[4,4,4]", "2**70"]))
def test_every_setting_from_the_command_line(name, text):
    try:
        from geometry_precompute import DEFAULTS

        DEFAULTS.with_overrides(parse_sets([f"{name}={text}"]), "<--set>")
    except InputError as e:
        one_line_error(e)


@pytest.mark.parametrize("what", ["objects", "settings", "array"])
def test_toml_nested_3000_levels_is_refused_with_the_limit(tmp_path, what):
    deep_array = "[" * 3000 + "]" * 3000
    text = {"objects": f'name = "x"\nobjects = {deep_array}\n',
            "settings": 'name = "x"\n[settings]\n' + "a = {" * 3000 + "}" * 3000 + "\n",
            "array": f'name = "x"\n[[objects]]\nid = "a"\nkind = "mug"\n'
                     f'position = {deep_array}\n'}[what]
    path = tmp_path / "deep.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=rf"nested deeper than {MAX_DEPTH} levels"):
        load_scene(path)
    cfg = tmp_path / "deep_sweep.toml"
    cfg.write_text(text.replace('name = "x"', 'name = "x"\n[source]\nkind = "random"\ncount = 1'))
    with pytest.raises(InputError, match=rf"nested deeper than {MAX_DEPTH} levels"):
        load_config(cfg)


def test_endless_and_huge_files_are_refused_with_the_limit(tmp_path):
    limit = f"{MAX_TEXT_BYTES // 2**20} MiB"
    with pytest.raises(InputError, match=f"larger than {limit}"):
        load_scene("/dev/zero")
    big = tmp_path / "big.toml"
    with big.open("wb") as f:  # sparse: no disk used
        f.truncate(3 * 2**30)
    with pytest.raises(InputError, match=f"larger than {limit}"):
        load_scene(big)
    with pytest.raises(InputError, match=f"larger than {limit}"):
        load_config(big)


def test_a_sweep_of_too_many_points_is_refused_before_it_is_built(tmp_path):
    from sweeps.config import MAX_POINTS

    cfg = tmp_path / "many.toml"
    axes = "\n".join(f"{name} = [{', '.join(['0.1'] * 100)}]"
                     for name in ("v_max", "dt", "omega_max", "activation_tol"))
    cfg.write_text(f'[source]\nkind = "random"\ncount = 1\n[axes]\n{axes}\n')
    with pytest.raises(InputError, match=f"100000000 points, more than {MAX_POINTS}"):
        load_config(cfg)
