"""``shacc import-mjcf FILE.xml --out SCENE.toml``: a MuJoCo scene's named geoms and bodies
as a scene file (``geometry_precompute.mjcf_import``), with the tasks a mapping file or
``--task`` gives. The scene and its mesh files appear together or not at all: they are
written into a hidden folder beside ``--out``, the scene is read back (every rule of a
scene file, and that its objects do not interpenetrate), and only then moved into place."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

import tomli_w

from geometry_precompute import InputError, load_scene, precompute
from geometry_precompute.errors import HostError, SceneWarning
from geometry_precompute.fileio import read_toml, write_atomic
from geometry_precompute.mjcf_import import import_mjcf
from sweeps.output import check_output_file, nearest_existing


def _mapping(args) -> tuple[dict, str]:

    mapping: dict = read_toml(args.map, "a task mapping (TOML)") if args.map else {}
    src = str(args.map) if args.map else "<arguments>"
    tasks = list(mapping.get("tasks", []))
    for text in args.task:
        tid, sep, rest = text.partition("=")
        obj, sep2, template = rest.rpartition(":")
        if not (sep and sep2 and tid and obj and template):
            raise InputError("<arguments>", "--task", f"must be ID=OBJECT:TEMPLATE, got {text!r}")
        tasks.append({"id": tid, "object": obj, "template": template})
    mapping["tasks"] = tasks
    mapping["obstacles"] = list(mapping.get("obstacles", [])) + list(args.obstacle)
    return mapping, src


def _stand(rule: str) -> str:
    """The hint for an object placed below or above the table: what ``--stand`` does."""
    if "below the table" in rule or "above the table" in rule:
        return "; --stand stands every object on the table"
    return ""


def cmd_import_mjcf(args) -> int:

    out = Path(args.out)
    if out.suffix != ".toml":
        raise InputError("<arguments>", "--out", f"a scene file ends in .toml, got {str(out)!r}")
    check_output_file(out, "--out")  # its folders exist, or can be made, and are writable
    mapping, src = _mapping(args)
    folder = out.parent if str(out.parent) else Path(".")
    # The draft is written beside the nearest folder that exists (the same file system,
    # so the moves below are renames); the missing folders are made only at the end.
    base = nearest_existing(folder)
    try:
        work = Path(tempfile.mkdtemp(prefix=".import-", dir=base))
    except OSError as e:
        raise HostError(base, "make a working folder", e.strerror or str(e)) from None
    try:

        if not 0.0 <= args.max_tilt <= 45.0:
            raise InputError("<arguments>", "--max-tilt", f"must be in [0, 45] degrees, got "
                             f"{args.max_tilt:g}")
        table = import_mjcf(args.xml, mapping, work, src, args.max_tilt, args.stand)
        scene_file = work / out.name
        write_atomic(scene_file, tomli_w.dumps(table).encode())
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", SceneWarning)
                scene = load_scene(scene_file)
                precompute(scene, scene.settings())  # every rule, interpenetration included
        except InputError as e:  # named by the scene it would have been, not the draft
            raise InputError(f"{out} (from {args.xml})", e.field, e.rule + _stand(e.rule)
                             ) from None
        for w in caught:  # the same: the draft's warnings named by the scene
            said = str(w.message).replace(str(scene_file), str(out))
            warnings.warn(SceneWarning(said + _stand(said)), stacklevel=2)
        meshes = [o["mesh"] for o in table["objects"] if o["kind"] == "mesh"]
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise HostError.of(e, folder, "make the folder") from None
        for name in meshes:
            os.replace(work / name, folder / name)
        os.replace(scene_file, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"wrote {out} ({len(table['objects'])} objects, {len(table['tasks'])} tasks"
          + (f", {len(meshes)} mesh files beside it" if meshes else "") + ")", file=sys.stderr)
    return 0
