"""Populations of simulated users (geometry_precompute.population, shacc_jax.populations): the
tables and their one-line errors, their JSON Schema, the draws' distributions against
scipy's, and a sweep over populations whose tables carry the draws."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pyarrow.dataset as ds
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from jsonschema import Draft202012Validator
from scipy import stats

from geometry_precompute import DEFAULTS, SPECS, InputError, bake
from geometry_precompute.file_schema import settings_schema
from geometry_precompute.population import POPULATED, Population, encode, text_of
from geometry_precompute.settings import parse_cli_value, population_range
from shacc_jax import streams
from shacc_jax.populations import population_values
from shacc_jax.types import Params

BAD = [
    ({"user_noise": {"gauss": [0, 1]}}, "user_noise", "one key of uniform, normal, values"),
    ({"user_noise": {"uniform": [0, 0.1], "values": [0]}}, "user_noise", "one key"),
    ({"user_noise": {"uniform": [0.3, 0.1]}}, "user_noise.uniform", "low <= high"),
    ({"user_noise": {"uniform": [0, 3.0]}}, "user_noise.uniform", "must be in [0, 1.5708]"),
    ({"user_switch_at": {"uniform": [0, 1]}}, "user_switch_at.uniform", "must be in (0, 1)"),
    ({"user_switch": {"normal": [0.2, 0]}}, "user_switch.normal", "sd must be > 0"),
    ({"user_switch": {"normal": [0.2]}}, "user_switch.normal", "two numbers [mean, sd]"),
    ({"user_tremor": {"values": []}}, "user_tremor.values", "1 to 16 values"),
    ({"user_tremor": {"values": list(np.linspace(0, 0.01, 17))}}, "user_tremor.values",
     "1 to 16 values"),
    ({"user_tremor": {"values": [0.01, "a"]}}, "user_tremor.values", "list of numbers"),
    ({"user_tremor": {"values": [float("nan")]}}, "user_tremor.values", "finite"),
    ({"user_tremor_hz": {"values": [0.0]}}, "user_tremor_hz.values", "must be in (0, 50]"),
    ({"user_tremor_hz": "fast"}, "user_tremor_hz", "a number or a population table"),
]


@pytest.mark.parametrize("overrides, field, rule", BAD)
def test_bad_populations_are_refused_in_one_line(overrides, field, rule):
    """A bad population table: one line naming the file, the field and the rule; the
    settings' JSON Schema refuses it too (all of these are rules a schema can state but
    the uniform's low <= high, which it lists as the loader's, and NaN, which JSON has
    not)."""
    with pytest.raises(InputError) as e:
        DEFAULTS.with_overrides(overrides, "scene.toml")
    assert str(e.value).startswith(f"scene.toml: {field}: ") and rule in str(e.value)
    assert "\n" not in str(e.value)
    if "low <= high" not in rule and "finite" not in rule:
        assert not Draft202012Validator(settings_schema()).is_valid(
            {k: (list(v) if isinstance(v, tuple) else v) for k, v in overrides.items()})


def test_populations_are_settings_as_files_and_the_command_line_write_them():
    """A population is read from a settings table (also nested, which TOML makes of a
    dotted key), from ``--set NAME={...}``, and written back as the same table; the
    schema accepts what the loader does; the other settings refuse tables."""
    table = {"user_noise": {"uniform": [0, 0.4]}, "user_switch": {"normal": [0.2, 0.1]},
             "user_tremor": {"values": [0, 0.01]}, "user_tremor_hz": 4}
    s = DEFAULTS.with_overrides(table)
    assert s["user_noise"] == Population("uniform", (0.0, 0.4))
    assert s.to_dict()["user_switch"] == {"normal": [0.2, 0.1]}
    assert Draft202012Validator(settings_schema()).is_valid(table)
    assert parse_cli_value("user_tremor", "{values = [0, 0.01]}") == {"values": [0, 0.01]}
    with pytest.raises(InputError, match="<--set>: user_noise: a population is an inline"):
        parse_cli_value("user_noise", "{uniform = [0, ")
    with pytest.raises(InputError, match="unknown setting"):
        DEFAULTS.with_overrides({"v_max": {"uniform": [0.1, 0.2]}})
    assert text_of({"normal": [0.2, 0.1]}) == "normal(0.2, 0.1)"


numbers = st.floats(0, 1, allow_nan=False)


@st.composite
def populations(draw):
    name = draw(st.sampled_from(POPULATED))
    lo, hi = population_range(name)
    scale = st.floats(lo, hi, allow_nan=False).filter(SPECS[name].check)
    kind = draw(st.sampled_from(["uniform", "normal", "values"]))
    if kind == "uniform":
        numbers = sorted([draw(scale), draw(scale)])
    elif kind == "normal":
        numbers = [draw(scale), draw(st.floats(1e-6, 10, allow_nan=False))]
    else:
        numbers = draw(st.lists(scale, min_size=1, max_size=16))
    return name, {kind: numbers}


@settings(max_examples=200, deadline=None)
@given(populations())
def test_any_valid_population_is_read_encoded_and_described(case):
    """Every valid table is accepted by the loader and the schema, written back as
    itself, and encoded with its code, numbers and the setting's range."""
    name, table = case
    value = DEFAULTS.with_overrides({name: table})[name]
    assert value.to_json() == {k: [float(v) for v in vs] for k, vs in table.items()}
    assert Draft202012Validator(settings_schema()).is_valid({name: table})
    code, args, values = encode(value, *population_range(name))
    kind = next(iter(table))
    assert code == ("", "uniform", "normal", "values").index(kind)
    if kind == "values":
        assert args[0] == len(table["values"]) and values[:len(table["values"])] == \
            [float(v) for v in table["values"]]
    if kind == "normal":
        assert args[2:] == list(population_range(name))


def _draws(kind: str, numbers, name: str, n: int = 4000) -> np.ndarray:
    """``n`` rollouts' draws of one setting's population, by the kernel's function."""
    i = POPULATED.index(name)
    code, args, values = encode(Population(kind, tuple(numbers)), *population_range(name))
    U = len(POPULATED)
    dist = np.zeros(U, np.int32)
    dist[i] = code
    a, v = np.zeros((U, 4), np.float32), np.zeros((U, 16), np.float32)
    a[i], v[i] = args, values
    x = Params._make(jnp.zeros(()) for _ in Params._fields)._replace(
        user_dist=jnp.asarray(dist), user_dist_args=jnp.asarray(a),
        user_dist_values=jnp.asarray(v))
    keys = jax.vmap(lambda k: streams.rollout_key(jnp.int32(0), jnp.int32(77), jnp.int32(1),
                                                  k))(jnp.arange(n, dtype=jnp.int32))
    return np.asarray(jax.vmap(lambda k: population_values(k, x, jnp.float32))(keys))[:, i]


def test_draws_follow_their_distributions():
    """Across rollouts (keys of the rollout stream): a uniform's draws are uniform on
    [low, high], a normal's follow scipy's truncnorm on the setting's range, a list's
    values each come up as often (Kolmogorov-Smirnov, chi-square)."""
    got = _draws("uniform", (0.1, 0.4), "user_noise")
    assert got.min() >= 0.1 and got.max() < 0.4
    assert stats.kstest(got, stats.uniform(0.1, 0.3).cdf).pvalue > 1e-3
    lo, hi = population_range("user_switch")
    mean, sd = 0.1, 0.2  # a quarter of the mass below 0 is cut away
    got = _draws("normal", (mean, sd), "user_switch")
    assert got.min() >= lo and got.max() <= hi
    truncated = stats.truncnorm((lo - mean) / sd, (hi - mean) / sd, loc=mean, scale=sd)
    assert stats.kstest(got, truncated.cdf).pvalue > 1e-3
    assert stats.kstest(got, stats.norm(mean, sd).cdf).pvalue < 1e-6  # truncation matters
    values = (0.0, 0.005, 0.01)
    got = _draws("values", values, "user_tremor")
    counts = [(got == np.float32(v)).sum() for v in values]
    assert sum(counts) == len(got)
    assert stats.chisquare(counts).pvalue > 1e-3


def test_a_population_sweep_records_each_rollouts_user(tmp_path):
    """A sweep over population settings: the set.* column of a populated setting is text
    for every point, the rollouts table holds each rollout's drawn values (the plain
    value where a point has none, a draw in the population's support where it has),
    the same draws in every mode, read alike by pyarrow and pandas."""
    from sweeps.config import parse_config
    from sweeps.distributed.runner import run_sweep

    cfg = parse_config({
        "name": "population", "modes": ["baseline", "shacc"], "chunk": 2,
        "source": {"kind": "random", "count": 2, "tasks": [3, 3], "sampling": "both",
                   "seed": 4},
        "settings": {"start_grid": [2, 2], "user_tremor": 0.004},
        "axes": {"user_noise": [0.1, {"uniform": [0.0, 0.4]}],
                 "user_switch": [{"values": [0.0, 0.3]}]}}, "cfg.toml", tmp_path)
    run_sweep(cfg, tmp_path / "out", None, workers=1, progress=False)
    scenes = pd.read_parquet(tmp_path / "out" / "scenes")
    assert sorted(set(scenes["set.user_noise"])) == ["0.1", "uniform(0, 0.4)"]
    assert set(scenes["set.user_switch"]) == {"values(0, 0.3)"}
    rollouts = ds.dataset(tmp_path / "out" / "rollouts").to_table().to_pandas()
    assert len(rollouts) == 2 * 2 * 2 * 4 * 3
    first, second = (rollouts[rollouts.point == p] for p in (0, 1))
    assert (first.user_noise == np.float32(0.1)).all()
    assert second.user_noise.between(0, 0.4).all() and second.user_noise.nunique() > 10
    assert set(rollouts.user_switch) == {0.0, np.float32(0.3)}
    assert (rollouts.user_tremor == np.float32(0.004)).all()
    per_mode = second.pivot_table(index=["scene_index", "start", "task"], columns="mode",
                                  values="user_noise", observed=True)
    assert (per_mode["baseline"] == per_mode["shacc"]).all()


def test_a_population_bake_has_its_codes_and_the_layout_steps():
    """The bake encodes a population per scene; the layout then steps and draws."""
    from geometry_precompute import load_scene, precompute, shipped_scene_paths

    scene = load_scene(shipped_scene_paths()[0])
    r = precompute(scene, scene.settings(DEFAULTS, {"start_grid": [2, 2],
                                                    "user_switch": {"values": [0.1, 0.2]}}))
    b = bake([r])
    i = POPULATED.index("user_switch")
    assert b.user_dist[0].tolist() == [3 if j == i else 0 for j in range(len(POPULATED))]
    assert b.user_dist_args[0, i, 0] == 2 and b.user_dist_values[0, i, :2].tolist() == [0.1, 0.2]
    layout = b.layout()
    assert layout.populations and layout.stepped_users and layout.switching
    # A batch whose users never change their mind traces no first-headed task.
    plain = bake([precompute(scene, scene.settings(DEFAULTS, {"start_grid": [2, 2],
                                                              "user_noise": 0.2}))])
    assert plain.layout().stepped_users and not plain.layout().switching
