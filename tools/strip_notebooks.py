"""Strips outputs and execution counts from notebooks before commit: `python tools/strip_notebooks.py`.

Without arguments every notebook in `notebooks/`, else the files named.
"""

import sys
from pathlib import Path

import nbformat

NOTEBOOKS_DIR = Path(__file__).resolve().parents[1] / "notebooks"


def strip(path: Path) -> bool:
    """Clears a notebook's outputs in place; whether it changed."""
    notebook = nbformat.read(path, as_version=4)
    changed = False
    for cell in notebook.cells:
        if cell.cell_type == "code" and (cell.outputs or cell.execution_count is not None):
            cell.outputs, cell.execution_count, changed = [], None, True
        if cell.get("metadata", {}).pop("execution", None) is not None:
            changed = True
    if changed:
        nbformat.write(notebook, path)
    return changed


if __name__ == "__main__":
    paths = [Path(p) for p in sys.argv[1:]] or sorted(NOTEBOOKS_DIR.glob("*.ipynb"))
    for path in paths:
        if strip(path):
            print(f"stripped {path}")
