"""Execute the notebooks (jupytext percent scripts in ``notebooks/``) through nbclient.

    python -m sweeps.app.notebook_runner [NAME ...] [--out DIR] [-p NAME=VALUE ...]

Every notebook keeps what a reader may change in one cell tagged ``parameters`` (the
convention of papermill and jupytext). ``-p NAME=VALUE`` runs a notebook with other
values: a cell tagged ``injected-parameters`` is inserted after that cell, as papermill
does; VALUE is a Python literal (``-p GRID=64``, ``-p SWEEP='"out/my-sweep"'``), or a
string where it is none (``-p SWEEP=out/my-sweep``). ``--out DIR`` writes the executed
copies there as ``NAME.ipynb`` (never beside the sources; ``make notebooks`` uses
``build/notebooks``). The test suite runs each notebook this way with its defaults.
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jupytext
import nbformat
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"


def parameters_cell(nb) -> int:
    """The index of the cell tagged ``parameters``."""
    for i, cell in enumerate(nb.cells):
        if "parameters" in cell.get("metadata", {}).get("tags", []):
            return i
    raise ValueError("the notebook has no cell tagged 'parameters'")


def parameter_names(nb) -> list[str]:
    """The names the parameters cell assigns, in order."""
    tree = ast.parse(nb.cells[parameters_cell(nb)].source)
    return [t.id for node in tree.body if isinstance(node, ast.Assign | ast.AnnAssign)
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
            if isinstance(t, ast.Name)]


def inject(nb, parameters: Mapping[str, Any]) -> None:
    """Insert a cell that sets ``parameters`` after the parameters cell; a name that
    cell does not assign is an error (a typo would otherwise be silently ignored)."""
    known = parameter_names(nb)
    unknown = [k for k in parameters if k not in known]
    if unknown:
        has = f"this notebook's parameters: {', '.join(known)}" if known else \
            "this notebook has no parameters"
        raise ValueError(f"no parameter {', '.join(unknown)}; {has}")
    cell = nbformat.v4.new_code_cell("\n".join(f"{k} = {v!r}" for k, v in parameters.items()))
    cell.metadata["tags"] = ["injected-parameters"]
    nb.cells.insert(parameters_cell(nb) + 1, cell)


def execute(name: str, parameters: Mapping[str, Any] | None = None, timeout: int = 600):
    """Run ``notebooks/NAME.py`` top to bottom with its working directory in
    ``notebooks/``, ``parameters`` overriding its parameters cell; returns the executed
    notebook. A cell that raises raises here."""
    nb = jupytext.read(NOTEBOOKS / f"{name}.py")
    if parameters:
        inject(nb, parameters)
    NotebookClient(nb, timeout=timeout, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    return nb


def _value(text: str) -> tuple[str, Any]:
    name, sep, value = text.partition("=")
    if not sep or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return name, value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("names", nargs="*", help="notebook names (default: all)")
    p.add_argument("--out", type=Path, help="write the executed NAME.ipynb here")
    p.add_argument("-p", dest="parameters", action="append", type=_value, default=[],
                   metavar="NAME=VALUE", help="a parameter (repeatable); given to every "
                   "named notebook that has it")
    args = p.parse_args(argv)
    names = args.names or sorted(q.stem for q in NOTEBOOKS.glob("*.py"))
    missing = [n for n in names if not (NOTEBOOKS / f"{n}.py").is_file()]
    if missing:
        p.error(f"no notebook {', '.join(missing)} in notebooks/")
    known = {n: parameter_names(jupytext.read(NOTEBOOKS / f"{n}.py")) for n in names}
    unused = sorted({k for k, _ in args.parameters} - {k for ks in known.values() for k in ks})
    if unused:
        p.error(f"no notebook named has the parameter {', '.join(unused)}")
    for name in names:
        nb = execute(name, {k: v for k, v in args.parameters if k in known[name]})
        if args.out is not None:
            args.out.mkdir(parents=True, exist_ok=True)
            nbformat.write(nb, args.out / f"{name}.ipynb")
        print(f"ran {name}" + (f" -> {args.out / (name + '.ipynb')}" if args.out else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
