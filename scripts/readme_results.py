"""The README's results table, written from the committed test evaluations.

    python scripts/readme_results.py          # print the table
    python scripts/readme_results.py --write  # put it into README.md between its markers

Each cell is the mean over training seeds of J_clane (dm) / J_coll / J_R (m) of the sampled
policy on the test seed, from ``results/pixels/table1.json``, ``table_zigzag.json`` and
``table_obstacle_loop.json``, with how many seeds hold both constraints. A test checks that
the README holds exactly what this writes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TABLES = {"small_loop": "table1.json", "zigzag": "table_zigzag.json",
          "obstacle_loop": "table_obstacle_loop.json"}
START, END = "<!-- results-table -->", "<!-- /results-table -->"


def results_table(results: Path = REPO / "results" / "pixels") -> str:
    """The Markdown table: one row per agent, one column per map."""
    documents = {task: json.loads((results / name).read_text()) for task, name in TABLES.items()}
    agents = list(next(iter(documents.values()))["agents"])
    lines = ["| agent | " + " | ".join(f"`{task}`" for task in TABLES) + " |",
             "| --- |" + " --- |" * len(TABLES)]
    for agent in agents:
        cells = []
        for document in documents.values():
            entry = document["agents"][agent]
            held = sum(document["runs"][run]["satisfied"] for run in entry["runs"])
            cells.append(f"{entry['J_clane']['mean']:.3f} / {entry['J_coll']['mean']:.3f} / "
                         f"{entry['J_R']['mean']:.2f} ({held} of {len(entry['runs'])})")
        lines.append(f"| {agent} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write(readme: Path = REPO / "README.md") -> None:
    text = readme.read_text()
    head, rest = text.split(START, 1)
    tail = rest.split(END, 1)[1]
    readme.write_text(f"{head}{START}\n{results_table()}\n{END}{tail}")


if __name__ == "__main__":
    if sys.argv[1:] == ["--write"]:
        write()
    else:
        print(results_table())
