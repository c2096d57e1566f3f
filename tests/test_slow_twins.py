"""The ``slow`` marker is only for a heavier case of what a faster test also checks.

``make test`` (what CI runs) leaves the slow tests out and ``make test-all`` runs them.
So each one must name, in its docstring after "Faster twin:", the tests that check the
same property in less time. Those tests must exist and must not be slow themselves."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).parents[1]
TWIN = re.compile(r"(tests/\w+\.py)::(\w+)")


def _is_slow(node: ast.AST) -> bool:
    return any(ast.unparse(d) == "pytest.mark.slow" for d in getattr(node, "decorator_list", []))


def _tests(path: Path) -> dict[str, ast.FunctionDef]:
    tree = ast.parse(path.read_text(), str(path))
    return {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}


def slow_tests() -> list[tuple[Path, ast.FunctionDef]]:
    """Every test function marked slow, by file."""
    return [(path, fn) for path in sorted((ROOT / "tests").glob("test_*.py"))
            for fn in _tests(path).values() if _is_slow(fn)]


def test_every_slow_test_names_existing_faster_twins():
    found = slow_tests()
    assert found, "no test is marked slow: drop this check with the marker"
    for path, fn in found:
        where = f"{path.name}::{fn.name}"
        doc = ast.get_docstring(fn) or ""
        assert "Faster twin:" in doc, f"{where}: its docstring names no 'Faster twin:'"
        twins = TWIN.findall(doc.split("Faster twin:", 1)[1])
        assert twins, f"{where}: 'Faster twin:' names no tests/<file>.py::<test>"
        for file, name in twins:
            twin = _tests(ROOT / file).get(name)
            assert twin is not None, f"{where}: its twin {file}::{name} does not exist"
            assert not _is_slow(twin), f"{where}: its twin {file}::{name} is slow too"


def test_the_marker_is_used_only_as_a_decorator():
    """A slow mark anywhere else (a parametrized case, a module's pytestmark) would leave
    tests out of ``make test`` without a twin this file checks."""
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        if path.name == Path(__file__).name:
            continue
        uses = path.read_text().count("mark.slow")
        decorated = sum(1 for fn in _tests(path).values() if _is_slow(fn))
        assert uses == decorated, f"{path.name}: mark.slow used other than on a test function"


def test_make_test_leaves_the_slow_tests_out_and_test_all_runs_them():
    text = (ROOT / "Makefile").read_text()
    targets = {m.group(1): m.group(2) for m in
               re.finditer(r"^([\w-]+):[^\n]*\n((?:\t[^\n]*\n)+)", text, re.M)}
    assert '-m "not slow"' in targets["test"]
    assert "$(PYTEST)" in targets["test-all"] and "not slow" not in targets["test-all"]
