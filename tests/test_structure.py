"""The architecture a reader relies on (docs/ARCHITECTURE.md), held by the code's own
imports: no module of the three packages imports, however indirectly and wherever in
the module (inside a function too), a module that imports it back; ``sweeps``' three
rooms depend one way (the application on the runner and the analysis, the runner on
the analysis' tables only); the JAX half and the CPU half meet only at the bake."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("shacc_jax", "geometry_precompute", "sweeps")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            out[name.removesuffix(".__init__")] = path
    return out


def _lazy_names() -> dict[str, str]:
    """geometry_precompute's names loaded on first use (PEP 562): name -> module."""
    import geometry_precompute

    return {k: f"geometry_precompute.{v}" for k, v in geometry_precompute.LAZY_NAMES.items()}


def import_graph() -> dict[str, set[str]]:
    """module -> the modules of the three packages it imports anywhere in its file,
    except under ``if TYPE_CHECKING:`` (never run)."""
    mods, lazy = _modules(), _lazy_names()

    def known(name: str) -> str | None:
        while name not in mods and "." in name:
            name = name.rsplit(".", 1)[0]
        return name if name in mods else None

    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(), str(path))
        hidden = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                  and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(tree):
            if id(node) in hidden:
                continue
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                    base = ".".join(parts + ([node.module] if node.module else []))
                for a in node.names:
                    full = f"{base}.{a.name}"
                    targets.append(full if full in mods else
                                   lazy.get(a.name, base) if base == "geometry_precompute"
                                   else base)
            for t in targets:
                if t.split(".")[0] in PACKAGES and (k := known(t)) and k != mod:
                    graph[mod].add(k)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_circle():
    assert circles(import_graph()) == []


def test_the_check_finds_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert circles(graph) == [["a", "b", "c"]]


def test_the_rooms_of_sweeps_depend_one_way():
    allowed = {"sweeps.app": {"sweeps.app", "sweeps.distributed", "sweeps.analysis"},
               "sweeps.distributed": {"sweeps.distributed", "sweeps.analysis.tables"},
               "sweeps.analysis": {"sweeps.analysis"}}
    wrong = []
    for mod, deps in import_graph().items():
        room = next((r for r in allowed if mod == r or mod.startswith(r + ".")), None)
        if room is None:
            continue
        for d in deps:
            if d.startswith("sweeps.") and d.count(".") >= 2 and \
                    not any(d == a or d.startswith(a + ".") for a in allowed[room]):
                wrong.append(f"{mod} -> {d}")
    assert wrong == []


def test_the_halves_meet_only_at_the_bake():
    """shacc_jax reads the bake by its schema, the populations' codes, the
    per-scene metrics in NumPy (one definition for both halves), errors and files: never
    the scene model or a module of the mesh libraries. geometry_precompute never
    imports shacc_jax."""
    bridge = {"geometry_precompute.schema",
              "geometry_precompute.population", "geometry_precompute.outcomes",
              "geometry_precompute.errors", "geometry_precompute.fileio"}
    graph = import_graph()
    crossing = sorted(f"{m} -> {d}" for m, deps in graph.items() for d in deps
                      if (m.startswith("shacc_jax") and d.startswith("geometry_precompute")
                          and d not in bridge)
                      or (m.startswith("geometry_precompute") and d.startswith("shacc_jax")))
    assert crossing == []
