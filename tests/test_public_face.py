"""The tests use the packages through their public face: no test reaches for a private
name (one that starts with an underscore) of shacc_jax, geometry_precompute or sweeps,
whether imported or read as a module's attribute. What a test needs is public and
documented, or tested through what is."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGES = ("shacc_jax", "geometry_precompute", "sweeps")


# A named tuple's own public API begins with an underscore.
NAMEDTUPLE = {"_fields", "_replace", "_asdict", "_make", "_field_defaults"}


def _private(name: str) -> bool:
    return (name.startswith("_") and name not in NAMEDTUPLE
            and not (name.startswith("__") and name.endswith("__")))


def _ours(module: str | None) -> bool:
    return module is not None and module.split(".")[0] in PACKAGES


def private_uses(source: str) -> list[str]:
    """The private names of the packages that ``source`` imports or reads."""
    tree = ast.parse(source)
    modules: set[str] = set()  # local names bound to modules of the packages
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if _ours(a.name):
                    modules.add(a.asname or a.name.split(".")[0])
                    found += [a.name for part in a.name.split(".") if _private(part)]
        elif isinstance(node, ast.ImportFrom) and _ours(node.module):
            found += [f"{node.module}.{a.name}" for a in node.names if _private(a.name)]
            modules.update(a.asname or a.name for a in node.names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(base, ast.Name) and base.id in modules:
                found.append(ast.unparse(node))
    return found


def test_the_check_finds_private_names():
    assert private_uses("from sweeps.app.cli import _local_sweep") == \
        ["sweeps.app.cli._local_sweep"]
    assert private_uses("import shacc_jax.collision as col\ncol._x(1)") == ["col._x"]
    assert private_uses("from sweeps import tables\ntables._numbers") == ["tables._numbers"]
    assert private_uses("import numpy as np\nnp._x\nfrom sweeps import cli\ncli.main") == []


def test_no_test_uses_a_private_name_of_the_packages():
    here = Path(__file__).parent
    used = {p.name: private_uses(p.read_text()) for p in sorted(here.rglob("*.py"))}
    assert {k: v for k, v in used.items() if v} == {}
