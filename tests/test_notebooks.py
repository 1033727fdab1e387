"""The notebooks: committed without outputs, and each runs top to bottom in test mode."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from drake_grasp.apps.notebook import TEST_MODE_VARIABLE
from drake_grasp.robot.paths import REPO_ROOT

NOTEBOOKS = sorted((REPO_ROOT / "notebooks").glob("*.ipynb"))


def test_the_four_notebooks_are_there():
    assert {p.stem for p in NOTEBOOKS} >= {"grasp_pipeline", "reachability", "stability_cnn", "evaluation"}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_committed_notebook_holds_no_outputs(path: Path):
    notebook = nbformat.read(path, as_version=4)
    for cell in notebook.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, \
                f"{path.name} holds outputs: strip them (python tools/strip_notebooks.py)"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_in_test_mode(path: Path, monkeypatch):
    monkeypatch.setenv(TEST_MODE_VARIABLE, "1")
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    # Every notebook draws: at least one matplotlib figure came out.
    assert any("image/png" in o.get("data", {}) for o in outputs if o.output_type == "display_data")
