"""Every notebook runs top to bottom (jupytext percent scripts executed through
nbclient); a cell that raises fails the suite. They run in notebooks/ with their
default (small) sizes and write no files."""

from __future__ import annotations

import pytest

from sweeps.notebook_runner import NOTEBOOKS, execute

NAMES = ["scene_gallery", "success_fields", "clutteredness", "sweep_analysis"]


def test_every_notebook_is_listed():
    assert sorted(p.stem for p in NOTEBOOKS.glob("*.py")) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_notebook_runs(name, monkeypatch):
    monkeypatch.delenv("SHACC_FIGURES", raising=False)
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    before = sorted(p.name for p in NOTEBOOKS.iterdir())
    nb = execute(name)
    assert nb.cells[0].cell_type == "markdown"  # says what question it answers
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any(o.get("output_type") in ("display_data", "execute_result") for o in outputs), \
        "the notebook showed no figure or table"
    assert sorted(p.name for p in NOTEBOOKS.iterdir()) == before  # wrote nothing beside it
