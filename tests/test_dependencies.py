"""Every runtime dependency pyproject declares is there for a reason one can check: the
packages import it, or it serves a named feature of another dependency (bokeh: the
Dask dashboard; flatbuffers: jax.export's serialisation), which this imports."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("shacc_jax", "geometry_precompute", "sweeps")
# distribution name -> the module our code imports
MODULE = {"mujoco-mjx": "mujoco.mjx", "tomli-w": "tomli_w"}
# declared for another dependency's feature: (the module of that feature, what it imports)
FOR_ANOTHER = {"bokeh": ("distributed.dashboard.core", "bokeh"),
               "flatbuffers": ("jax._src.export.serialization", "flatbuffers")}


def _declared() -> list[str]:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    return [re.match(r"[A-Za-z0-9_.-]+", d)[0].lower() for d in deps]


def _imported() -> set[str]:
    """Every module imported anywhere in the packages, and each of its parents."""
    out: set[str] = set()
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
                for n in names:
                    parts = n.split(".")
                    out.update(".".join(parts[:k]) for k in range(1, len(parts) + 1))
    return out


@pytest.mark.parametrize("dist", _declared())
def test_each_runtime_dependency_is_used(dist):
    if dist in FOR_ANOTHER:
        feature, module = FOR_ANOTHER[dist]
        code = f"import sys, {feature}; sys.exit(0 if {module!r} in sys.modules else 1)"
        assert subprocess.run([sys.executable, "-c", code]).returncode == 0, \
            f"{feature} no longer imports {module}: is {dist} still needed?"
        return
    module = MODULE.get(dist, dist.replace("-", "_"))
    assert module in _imported(), f"{dist} is declared but no module of {PACKAGES} imports " \
                                  f"{module}"
