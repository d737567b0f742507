"""The figures ``docs/findings.md`` quotes from kept evaluations are those evaluations'."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FINDINGS = (REPO / "docs/findings.md").read_text()


@pytest.mark.parametrize("margin", ["0.07", "0.04", "0.02"])
def test_the_teacher_margin_table_is_the_kept_evaluations(margin):
    path = REPO / f"results/scripted/teacher-obstacle_loop-margin{margin}.json"
    document = json.loads(path.read_text())["teacher"]
    assert document["evaluation"]["margin"] == float(margin)
    intended = document["breakdown"]["by_direction"]["intended"]
    row = (f"| {intended['J_clane']:.3f} | {intended['J_coll']:.3f} | "
           f"{document['summary']['J_clane']:.3f} |")
    assert any(line.startswith(f"| {margin}") and line.endswith(row)
               for line in FINDINGS.splitlines()), row


def test_the_default_command_s_directions_are_its_evaluation():
    run = REPO / "results/runs/pixels/obstacle_loop/default-command-alone"
    intended = json.loads((run / "eval.json").read_text())["breakdown"]["by_direction"][
        "intended"]
    text = " ".join(FINDINGS.split())
    assert (f"**{intended['J_clane']:.3f} dm** and {intended['J_coll']:.3f} over the "
            f"{intended['episodes']} intended episodes") in text
