"""The notebooks in notebooks/ execute from top to bottom without error, against a tiny run and
tiny results made inside the test."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, tiny_experiments, monkeypatch):
    """Every cell runs; the notebook defines no library code, it only imports crllk."""
    runs, results, _ = tiny_experiments
    monkeypatch.setenv("CRLLK_RUN", str(runs / "small_loop" / "CRLLK-D-a0.5-seed0"))
    monkeypatch.setenv("CRLLK_RESULTS", str(results))
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parents[1])}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert all("def " not in cell.source for cell in notebook.cells if cell.cell_type == "code")


def test_there_are_the_notebooks():
    """The glob found the notebooks (a glob that found nothing would skip the test above)."""
    assert {p.stem for p in NOTEBOOKS} >= {"run_analysis", "paper_results", "maps_and_lanes"}
