"""Execute the notebooks (jupytext percent scripts in ``notebooks/``) through nbclient.

    python -m sweeps.notebook_runner [--write-ipynb] [NAME ...]

The test suite runs each one this way; ``make notebooks`` also writes executed .ipynb
copies beside them (git-ignored) and, with SHACC_FIGURES set, the README's pictures.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import jupytext
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"


def execute(name: str, timeout: int = 300):
    """Run ``notebooks/NAME.py`` top to bottom in notebooks/; returns the executed
    notebook. A cell that raises raises here."""
    nb = jupytext.read(NOTEBOOKS / f"{name}.py")
    NotebookClient(nb, timeout=timeout, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    return nb


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("names", nargs="*", help="notebook names (default: all)")
    p.add_argument("--write-ipynb", action="store_true")
    args = p.parse_args()
    names = args.names or sorted(q.stem for q in NOTEBOOKS.glob("*.py"))
    for name in names:
        nb = execute(name)
        if args.write_ipynb:
            jupytext.write(nb, NOTEBOOKS / f"{name}.ipynb")
        print(f"ran {name}")


if __name__ == "__main__":
    main()
