"""``shacc templates``: every skill template a scene can use, with its parameters and
their bounds (docs/reference/templates.md).

Without arguments it lists the built-in templates; ``--file`` adds template files, and a
scene adds its own files and shows, for each of its tasks, the bounds and fixed
dimensions evaluated for the task's object and the scene's settings."""

from __future__ import annotations

import json
from typing import Any

from geometry_precompute.errors import InputError
from geometry_precompute.loading import load_scene
from geometry_precompute.template_files import BUILTIN_SET, Template, template_set
from geometry_precompute.templates import resolve_tasks


def describe(t: Template) -> dict[str, Any]:
    """One template as a JSON object: what the listing prints."""
    return {
        "name": t.name, "file": "built-in" if t.builtin else t.source,
        "description": t.description, "fits": list(t.fits), "shape": t.shape,
        "params": {p.name: {"min": p.min.text, "init": p.init.text, "unit": p.unit}
                   for p in t.params},
        "fixed": {n: e.text for n, e in t.fixed},
        "center": [e.text for e in t.center], "dims": [e.text for e in t.dims],
        "rotation": t.rotation if isinstance(t.rotation, str) else list(t.rotation),
        "orientation": t.orientation if isinstance(t.orientation, str)
        else list(t.orientation),
    }


def cmd_templates(args) -> int:
    tasks: list[dict[str, Any]] = []
    if args.scene is not None:
        scene = load_scene(args.scene)
        tset = scene.templates
        for sp in resolve_tasks(scene, scene.settings()):
            tasks.append({"task": sp.task.id, "object": sp.obj.id, "template": sp.template,
                          "bounds": {n: [float(lo), float(hi)] for n, lo, hi in
                                     zip(sp.param_names, sp.q_min, sp.q_init, strict=True)},
                          "fixed": {k: float(v) for k, v in sp.fixed.items()}})
    else:
        tset = BUILTIN_SET
    if args.file:
        extra = template_set([str(f) for f in args.file], "<arguments>", "--file")
        names = set(tset.names())
        for t in extra.extra:
            if t.name in names:
                raise InputError(t.source, f"templates.{t.name}", "already defined by the "
                                 "scene's files; give it another name")
        tset = type(tset)(tset.files + extra.files, tset.extra + extra.extra)
    rows = [describe(tset[n]) for n in tset.names()]
    if args.json:
        print(json.dumps({"templates": rows, "tasks": tasks}, indent=1))
        return 0
    for r in rows:
        print(f"{r['name']}  ({r['file']}; {r['shape']}; fits {', '.join(r['fits'])})")
        if r["description"]:
            print(f"  {r['description']}")
        for n, p in r["params"].items():
            print(f"  shrinks {n} [{p['unit']}]: min {p['min']}, init {p['init']}")
        for n, text in r["fixed"].items():
            print(f"  fixed {n} = {text}")
        print(f"  centre {r['center']}, dims {r['dims']}, rotation {r['rotation']}, "
              f"orientation {r['orientation']}")
    if tasks:
        print(f"\nThe tasks of {args.scene} (bounds [min, init] for their objects):")
        for row in tasks:
            bounds = ", ".join(f"{n} [{lo:.4g}, {hi:.4g}]"
                               for n, (lo, hi) in row["bounds"].items())
            fixed = ", ".join(f"{n} {v:.4g}" for n, v in row["fixed"].items())
            print(f"  {row['task']} ({row['template']} on {row['object']}): {bounds}"
                  + (f"; fixed {fixed}" if fixed else ""))
    return 0
