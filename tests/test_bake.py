"""The bake: fixed shapes, padding, masks, clusters, settings per scene."""

from __future__ import annotations

import numpy as np
import pytest

from geometry_precompute import InputError, bake, precompute, random_scene, schema
from geometry_precompute.settings import DEFAULTS


def test_bake_shapes_and_padding(shipped_results):
    b = bake(shipped_results[:3], max_tasks=5)
    S, T, N = 3, 5, 36
    assert b.task_mask.shape == (S, T) and b.starts.shape == (S, N, 7)
    assert b.center_init.shape == (S, T, 3) and b.quat_opt.shape == (S, T, 4)
    assert b.task_mask[:, :3].all() and not b.task_mask[:, 3:].any()
    assert (b.cluster[:, 3:] == -1).all()
    for k in b.arrays():
        assert np.all(np.isfinite(getattr(b, k).astype(float))), k
    np.testing.assert_allclose(np.linalg.norm(b.quat_init, axis=-1), 1.0)


def test_bake_arrays_follow_the_schema(shipped_results):
    """Every schema field is baked once, with the schema's dtype and rank; a named axis
    has one size across all fields (S, T, N, O, P, No) and a numbered one that size."""
    b = bake(shipped_results[:3], max_tasks=5)
    fields = schema.GEOMETRY + schema.PARAMS + schema.SEARCH
    assert list(b.arrays()) == [f.name for f in fields]
    sizes = {}
    kinds = {"bool": "b", "int": "iu", "float": "f"}
    for f in fields:
        a = getattr(b, f.name)
        assert a.dtype.kind in kinds[f.dtype], (f.name, a.dtype)
        assert a.ndim == len(f.shape), (f.name, a.shape, f.shape)
        for axis, n in zip(f.shape, a.shape, strict=True):
            assert sizes.setdefault(axis, n) == n if isinstance(axis, str) else axis == n, \
                (f.name, axis, n)
    assert sizes["S"] == 3 and sizes["T"] == 5 and sizes["P"] == schema.MAX_PARAMS
    assert set(b.obj_kind[b.obj_mask]) <= {schema.CYLINDER, schema.BOX}


def test_the_typed_classes_mirror_the_schema():
    """BakedScenes, Geometry, Params and SearchProblem are written out field by field
    (so editors and type checkers see them); their fields are the schema's, in its
    order, and each annotation names the schema's dtype and axes (Params with a leading
    ``*P`` of sweep points)."""
    import dataclasses
    import re

    from geometry_precompute.baking import BakedScenes
    from shacc_jax.types import Geometry, Params, SearchProblem

    fields = schema.GEOMETRY + schema.PARAMS + schema.SEARCH
    assert [f.name for f in dataclasses.fields(BakedScenes)] == \
        [f.name for f in fields] + ["labels"]
    wrapper = {"bool": "Bool", "int": "Int", "float": "Float"}
    for cls, group, lead in ((Geometry, schema.GEOMETRY, ""), (Params, schema.PARAMS, "*P"),
                             (SearchProblem, schema.SEARCH, "")):
        assert cls._fields == schema.names(group), cls.__name__
        for f in group:
            hint = cls.__annotations__[f.name]  # a string, or a ForwardRef holding one
            hint = getattr(hint, "__forward_arg__", hint)
            m = re.fullmatch(r"(\w+)\[Array, ['\"]([^'\"]*)['\"]\]", hint)
            assert m, (cls.__name__, f.name, hint)
            axes = " ".join(str(a) for a in f.shape)
            assert (m[1], m[2].strip()) == (wrapper[f.dtype], f"{lead} {axes}".strip()), \
                (cls.__name__, f.name)


def test_layout_is_read_off_the_bake_once(shipped_results):
    """Layout: padded sizes, the modes, and the meta formula from the baked flags; it
    is hashable (a static argument) and refuses what it cannot mean."""
    b = bake(shipped_results[:3])
    lay = b.layout(("shacc",))
    assert (lay.n_tasks, lay.n_starts, lay.n_objects) == (b.n_tasks, b.n_starts,
                                                          b.obj_mask.shape[1])
    assert lay.modes == ("shacc",) and hash(lay) == hash(b.layout(["shacc"]))
    assert lay.meta_formula == "yaw" and b.yaw_meta.all()
    assert not lay.collision_checks and not lay.box_objects
    with pytest.raises(ValueError, match=r"Layout\.modes"):
        b.layout(("shacc", "bogus"))
    with pytest.raises(ValueError, match="lanes_per_block"):
        b.layout(lanes_per_block=0)


def test_bake_values_follow_results(shipped_results):
    b = bake(shipped_results)
    for s, r in enumerate(shipped_results):
        for t, (si, so) in enumerate(zip(r.shapes_init, r.shapes_opt, strict=True)):
            np.testing.assert_allclose(b.dims_init[s, t], si.dims)
            np.testing.assert_allclose(b.dims_opt[s, t], so.dims)
            np.testing.assert_allclose(b.center_opt[s, t], so.center)
        labels = b.cluster[s, : len(r.spaces)]
        for k, members in enumerate(r.meta_clusters()):
            assert (labels[members] == k).all()
        singles = [c[0] for c in r.clusters if len(c) == 1]
        assert (labels[singles] == -1).all()
    assert np.all(b.dt == DEFAULTS["dt"]) and np.all(b.max_steps == DEFAULTS["max_steps"])


def test_settings_become_per_scene_arrays():
    scene = random_scene(1, "uniform", 5, 5)
    r1 = precompute(scene, DEFAULTS)
    r2 = precompute(scene, DEFAULTS.with_overrides({"v_max": 0.3, "ambiguity": "nearest"}))
    b = bake([r1, r2])
    assert b.v_max.tolist() == [0.15, 0.3]
    assert b.ambiguity_nearest.tolist() == [False, True]


def test_bake_rejects_bad_input(shipped_results):
    with pytest.raises(InputError, match="max_tasks"):
        bake(shipped_results[:1], max_tasks=2)
    starts = np.zeros((4, 7))
    starts[:, 3] = 1.0
    starts[2, 3:] = 0.0
    with pytest.raises(InputError, match="zero quaternion"):
        bake(shipped_results[:1], starts=starts)
    small = precompute(shipped_results[0].scene,
                       shipped_results[0].settings.with_overrides({"start_grid": [2, 2]}))
    with pytest.raises(InputError, match="same number of start poses"):
        bake([shipped_results[0], small])


def test_explicit_starts_are_normalised(shipped_results):
    starts = np.array([[-0.5, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0]])
    b = bake(shipped_results[:2], starts=starts)
    assert b.starts.shape == (2, 1, 7)
    np.testing.assert_allclose(b.starts[:, 0, 3:], [[1, 0, 0, 0]] * 2)
