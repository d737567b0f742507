"""The committed results agree with the code: every table's, the sweep's and the robustness
report's Markdown is what the current code writes from its JSON, the figures are PNGs, and the
paper notebook runs against ``results/`` as committed."""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
import pytest
from docs_pages import page
from nbclient import NotebookClient

from crllk.experiments import sweep_markdown, table_markdown
from crllk.experiments.robustness import robustness_markdown
from crllk.experiments.seeds import seeds_markdown, table_documents

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "results"
TABLES = sorted(RESULTS.glob("*/table*.json"))
SWEEPS = sorted(RESULTS.glob("*/sweep.json"))
ROBUSTNESS = sorted(RESULTS.glob("*/robustness.json"))


def test_every_run_a_results_document_names_is_kept():
    """A run directory named in a committed results document exists (a renamed run is renamed
    in the documents too)."""
    import re

    named = {(document.relative_to(REPO), run)
             for document in RESULTS.glob("*/*.json")
             for run in re.findall(r'"(results/runs/[^"]+?-seed\d+)"', document.read_text())}
    assert len(named) >= 100
    missing = sorted(str(pair) for pair in named if not (REPO / pair[1]).is_dir())
    assert not missing, missing


def test_there_are_committed_results():
    """The globs below found something (a glob that found nothing would test nothing)."""
    assert TABLES or SWEEPS, f"no committed tables under {RESULTS}"


DOCUMENTS = [(path, table_markdown) for path in TABLES] + \
    [(path, sweep_markdown) for path in SWEEPS] + \
    [(path, robustness_markdown) for path in ROBUSTNESS]
"""Every committed JSON document with the function that writes its Markdown."""


@pytest.mark.parametrize(("path", "writer"), DOCUMENTS,
                         ids=[f"{p.parent.name}/{p.stem}" for p, _ in DOCUMENTS])
def test_committed_markdown_is_what_the_code_writes(path, writer):
    document = json.loads(path.read_text())
    assert path.with_suffix(".md").read_text() == writer(document)
    assert document["settings"]["obs"] == path.parent.name
    if writer is not table_markdown:
        assert path.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("obs", sorted({path.parent.name for path in TABLES}))
def test_committed_seeds_are_what_the_code_writes(obs):
    assert (RESULTS / obs / "seeds.md").read_text() == seeds_markdown(
        table_documents(RESULTS / obs))


@pytest.mark.parametrize("obs", ["pixels", "state"])
def test_the_site_shows_every_seed_as_committed(obs):
    """The site's per-seed tables are seeds.md's, character for character (its results pages
    include the file), so no number in them was copied by hand."""
    readme = page({"pixels": "results/camera.md", "state": "results/state.md"}[obs])
    tables = [block for block in (RESULTS / obs / "seeds.md").read_text().split("\n\n")
              if block.startswith("| agent, seed |")]
    assert len(tables) == 2
    for table in tables:
        assert table.strip() in readme


def test_committed_pictures_are_pngs():
    for picture in RESULTS.glob("*/*.png"):
        assert picture.read_bytes()[:4] == b"\x89PNG", picture


def _execute(name: str) -> str:
    """Runs a notebook from the repository root with its defaults; returns its printed text."""
    path = REPO / "notebooks" / f"{name}.ipynb"
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(REPO)}}).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    return "".join(o.get("text", "") for o in outputs if o.output_type == "stream")


def test_paper_notebook_runs_against_the_committed_results(monkeypatch):
    monkeypatch.delenv("CRLLK_RESULTS", raising=False)
    text = _execute("paper_results")
    for table in TABLES:
        assert f"{table.relative_to(REPO)} not found" not in text


def test_run_notebook_runs_against_its_committed_default_run(monkeypatch):
    """run_analysis.ipynb's default run, the paper's agent on obstacle_loop, is kept in
    results/runs (without its checkpoint) and the notebook reads it."""
    monkeypatch.delenv("CRLLK_RUN", raising=False)
    run = RESULTS / "runs" / "pixels" / "obstacle_loop" / "CRLLK-D-a0.5-seed0"
    assert (run / "metrics.csv").exists() and (run / "eval.json").exists()
    text = _execute("run_analysis")
    assert "obstacle_loop" in text and "eval.json" in text
