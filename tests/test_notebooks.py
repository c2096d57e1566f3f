"""Every notebook runs top to bottom (jupytext percent scripts executed through
nbclient); a cell that raises fails the suite. They run in notebooks/ with their
default (small) parameters, but for the optimized mode's search (a small one, as the
optimize tests run), and write no files; their parameters cell is the one place to
change them."""

from __future__ import annotations

import jupytext
import pytest

from sweeps.app.notebook_runner import NOTEBOOKS, execute, main, parameter_names

NAMES = ["scene_gallery", "success_fields", "clutteredness", "sweep_analysis", "imperfect_users"]
# The default search (1.2 M activation rollouts) took 26 s of the notebook's 43 s on two
# cores; the search itself is checked in test_optimize.
SMALL = {"success_fields": {"SEARCH": {"optimize_population": 8, "optimize_generations": 3,
                                       "optimize_starts": 16}}}


def test_every_notebook_is_listed():
    assert sorted(p.stem for p in NOTEBOOKS.glob("*.py")) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs(name, monkeypatch):
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    before = sorted(p.name for p in NOTEBOOKS.iterdir())
    nb = execute(name, SMALL.get(name))
    assert nb.cells[0].cell_type == "markdown"  # says what question it answers
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any(o.get("output_type") in ("display_data", "execute_result") for o in outputs), \
        "the notebook showed no figure or table"
    assert sorted(p.name for p in NOTEBOOKS.iterdir()) == before  # wrote nothing beside it


@pytest.mark.parametrize("name", NAMES)
def test_parameters_live_in_one_tagged_cell(name):
    """No environment variables: what a reader may change is in the parameters cell,
    and the code below it reads only those names."""
    nb = jupytext.read(NOTEBOOKS / f"{name}.py")
    assert "FIGURES" in parameter_names(nb)
    source = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert "os.environ" not in source and "getenv" not in source


def test_parameters_are_injected_and_checked(tmp_path, capsys):
    """-p overrides a parameter (papermill's injected cell), FIGURES saves the figure,
    --out writes the executed copy outside the sources; an unknown name is refused."""
    scene = sorted(p for p in (NOTEBOOKS.parent / "geometry_precompute" / "scenes").glob(
        "*.toml"))[0]
    before = sorted(p.name for p in NOTEBOOKS.iterdir())
    assert main(["scene_gallery", "--out", str(tmp_path / "nb"), "-p", f"SCENES=['{scene}']",
                 "-p", f"FIGURES={tmp_path}", "-p", "COLUMNS=1"]) == 0
    assert (tmp_path / "scene_gallery.png").stat().st_size > 1000
    executed = jupytext.read(tmp_path / "nb" / "scene_gallery.ipynb")
    injected = [c for c in executed.cells if "injected-parameters" in c.metadata.get("tags", [])]
    assert len(injected) == 1 and "COLUMNS = 1" in injected[0].source
    printed = [o.get("text", "") for c in executed.cells if c.cell_type == "code"
               for o in c.get("outputs", [])]
    assert sum(line.strip() != "" for t in printed for line in t.splitlines()
               if "C_init" in line) == 1  # one scene, not every shipped one
    assert sorted(p.name for p in NOTEBOOKS.iterdir()) == before
    with pytest.raises(SystemExit):
        main(["scene_gallery", "-p", "GIRD=3"])
    assert "GIRD" in capsys.readouterr().err


def test_an_unknown_parameter_names_what_the_notebook_has():
    """The error names the notebook's parameters, or says it has none (never an empty
    list)."""
    import nbformat
    import pytest

    from sweeps.app.notebook_runner import inject

    def notebook(source: str):
        cell = nbformat.v4.new_code_cell(source)
        cell.metadata["tags"] = ["parameters"]
        return nbformat.v4.new_notebook(cells=[cell])

    with pytest.raises(ValueError, match=r"no parameter SCENES; this notebook's parameters: "
                       r"FIGURES, COLUMNS$"):
        inject(notebook("FIGURES = None\nCOLUMNS = 2"), {"SCENES": 3})
    with pytest.raises(ValueError, match=r"no parameter SCENES; this notebook has no "
                       r"parameters$"):
        inject(notebook("# nothing to set"), {"SCENES": 3})
