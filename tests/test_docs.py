"""The project explains itself: the reference builds into a site with warnings as
errors and documents every API member it lists; its generated tables match the code;
no tracked file outside the tests points to a specification the repository lacks;
the licence and citation files exist and are declared."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from sweeps.app import reference

ROOT = Path(__file__).resolve().parents[1]


def tracked() -> list[Path]:
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip("not a git checkout")
    return [ROOT / p for p in out.stdout.splitlines()]


def test_no_file_names_a_spec_section():
    """Nothing in the repository, the tests included, points to a specification it does
    not hold (this test's own pattern aside)."""
    pattern = re.compile(r"\bSPEC(\.md)?\b(?!S)")
    found = []
    for p in tracked():
        if p.name == "test_docs.py" or p.suffix in (".png", ".parquet", ".npz"):
            continue
        try:
            text = p.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError):
            continue
        found += [f"{p.relative_to(ROOT)}:{i + 1}" for i, line in enumerate(text.splitlines())
                  if pattern.search(line)]
    assert not found, f"points to a SPEC the repository does not hold: {found[:10]}"


def test_generated_reference_tables_are_current():
    assert reference.main(["--check"]) == 0, "run: python -m sweeps.app.reference"


def test_every_setting_and_column_is_in_the_reference():
    settings = (ROOT / "docs/reference/settings.md").read_text()
    from geometry_precompute.settings import SPECS

    assert all(f"`{name}`" in settings for name in SPECS)
    outputs = (ROOT / "docs/reference/outputs.md").read_text()
    from sweeps.analysis.tables import COLUMNS

    assert all(f"`{c}`" in outputs for cols in COLUMNS.values() for c in cols)


def test_the_site_builds_with_warnings_as_errors(tmp_path):
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent))
    if mkdocs is None:
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    site = tmp_path / "site"
    run = subprocess.run([mkdocs, "build", "--strict", "--site-dir", str(site)], cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    api = (site / "reference" / "api" / "index.html").read_text()
    missing = [name for name in _api_members() if f'id="{name}"' not in api]
    assert not missing, f"listed in api.md but not rendered: {missing}"
    for page in ("model", "scenes", "settings", "outputs", "conventions"):
        assert (site / "reference" / page / "index.html").stat().st_size > 5000


def test_licence_and_citation():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT" and "MIT License" in (ROOT / "LICENSE").read_text()
    cff = (ROOT / "CITATION.cff").read_text()
    assert "cff-version: 1.2.0" in cff and "Towards Shared Control in Clutter" in cff
    assert "Towards Shared Control in Clutter" in (ROOT / "README.md").read_text()


def test_the_readme_python_workflow_runs(tmp_path):
    """The README's "From Python" blocks, run one after the other as a user would."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## From Python"):text.index("## Sweeps")]
    blocks = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(blocks) == 2
    script = tmp_path / "workflow.py"
    script.write_text("\n".join(blocks))
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600,
                         env={**__import__("os").environ, "JAX_PLATFORMS": "cpu"})
    assert run.returncode == 0, run.stderr[-3000:]
    assert "C_init" in run.stdout and "'ci'" in run.stdout


def _api_members() -> list[str]:
    text = (ROOT / "docs/reference/api.md").read_text()
    blocks = dict(re.findall(r"^::: ([\w.]+)\n    options:\n      members:\n((?:        - \w+\n)+)",
                             text, re.M))
    names = [n for n in re.findall(r"^::: ([\w.]+)", text, re.M) if n not in blocks]
    names += [f"{mod}.{m}" for mod, block in blocks.items() for m in re.findall(r"- (\w+)", block)]
    return names


# The public API: each package's ``__all__`` and that of every sweeps module the reference
# renders (the command-line modules are documented by their --help and the reference).
API_MODULES = ("shacc_jax", "geometry_precompute", "sweeps.pipeline", "sweeps.distributed.runner",
               "sweeps.analysis.stats", "sweeps.analysis.plots")


def _public_api() -> dict[str, object]:
    import importlib

    out = {}
    for name in API_MODULES:
        mod = importlib.import_module(name)
        for attr in mod.__all__:
            out[f"{name}.{attr}"] = getattr(mod, attr)
    for name in _api_members():
        mod, _, attr = name.rpartition(".")
        try:
            out[name] = getattr(importlib.import_module(mod), attr)
        except (ImportError, AttributeError):
            pass  # a module: documented by its own docstring (mkdocstrings renders it)
    return out


def test_every_public_function_and_class_says_what_it_takes_and_shows_an_example():
    """Every public function and class (the API modules' ``__all__`` and api.md's
    members) has a real docstring, every function an example; every API module the
    reference renders whole has an ``__all__`` naming its public functions."""
    import importlib
    import inspect

    api = _public_api()
    thin = []
    for name, obj in api.items():
        if not (inspect.isfunction(obj) or inspect.isclass(obj)):
            continue  # constants (MODES, DEFAULTS) are described where they are defined
        doc = inspect.getdoc(obj) or ""
        if len(doc) < 100 or (inspect.isfunction(obj) and "Example" not in doc):
            thin.append(name)
    assert not thin, f"docstrings too thin or without an example: {thin}"
    assert len(api) > 60, sorted(api)
    for name in API_MODULES[2:]:
        mod = importlib.import_module(name)
        defined = {k for k, v in vars(mod).items() if not k.startswith("_")
                   and (inspect.isfunction(v) or inspect.isclass(v))
                   and v.__module__ == name}
        if f"::: {name}\n\n" in (ROOT / "docs/reference/api.md").read_text() + "\n\n":
            assert defined <= set(mod.__all__), (name, defined - set(mod.__all__))


def test_the_docstring_examples_run():
    """Every ``>>>`` example in the three packages runs and shows what it says (the
    statistics and plot helpers, the scene functions, the error types)."""
    import doctest
    import importlib
    import pkgutil

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ran, failed = 0, []
    finder, runner = doctest.DocTestFinder(), doctest.DocTestRunner(
        optionflags=doctest.NORMALIZE_WHITESPACE)
    for pkg in ("shacc_jax", "geometry_precompute", "sweeps"):
        names = [pkg] + [m.name for m in pkgutil.iter_modules(
            importlib.import_module(pkg).__path__, f"{pkg}.")]
        for name in names:
            if name.endswith("__main__"):
                continue
            for test in finder.find(importlib.import_module(name), name):
                if not test.examples:
                    continue
                result = runner.run(test, out=lambda text: failed.append(text))
                ran += result.attempted
            plt.close("all")
    assert not failed, "\n".join(failed)
    assert ran >= 60, ran
