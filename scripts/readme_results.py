"""The README's results table and its peer comparison, written from the committed test
evaluations.

    python scripts/readme_results.py          # print them
    python scripts/readme_results.py --write  # put them into README.md between their markers

Each cell of the table is the mean over training seeds of J_clane (dm) / J_coll / J_R (m) of
the sampled policy on the test seed, from ``results/pixels/table1.json``, ``table_zigzag.json``
and ``table_obstacle_loop.json``, with how many seeds hold both constraints. The peer paragraph
names, per map of ``results/state/peers.json``, the best constraint tracker and every learner
that tracks the constraints more tightly than CRLLK-D. A test checks that the README holds
exactly what this writes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TABLES = {"small_loop": "table1.json", "zigzag": "table_zigzag.json",
          "obstacle_loop": "table_obstacle_loop.json"}
START, END = "<!-- results-table -->", "<!-- /results-table -->"
PEERS_START, PEERS_END = "<!-- peers-summary -->", "<!-- /peers-summary -->"
PEERS = REPO / "results" / "state" / "peers.json"


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


def _worst(entry: dict, thresholds: dict) -> tuple[float, float, float]:
    """The largest metric/threshold over seeds and both constraints (at most 1: every seed
    holds both), and the largest J_clane and J_coll over seeds."""
    lane, coll = max(entry["J_clane"]["values"]), max(entry["J_coll"]["values"])
    return max(lane / thresholds["lane"], coll / thresholds["collision"]), lane, coll


def peers_summary(path: Path = PEERS) -> str:
    """One paragraph from the peer comparison: per map the best tracker, and the learners that
    track both constraints more tightly than CRLLK-D (a lower worst-seed metric/threshold)."""
    document = json.loads(path.read_text())
    thresholds = document["thresholds"]
    sentences = []
    for task, table in document["maps"].items():
        learners = table["learners"]
        best = table["best"]
        ratios = {name: _worst(entry, thresholds)[0] for name, entry in learners.items()}
        _, lane, coll = _worst(learners[best], thresholds)
        text = (f"on `{task}` the best constraint tracker is **{best}** (over its seeds at "
                f"most J_clane {lane:.3f} dm and J_coll {coll:.3f}; its largest "
                f"metric/threshold {ratios[best]:.2f})")
        reference = ratios["CRLLK-D"]
        tighter = [name for name in learners if name != "CRLLK-D" and ratios[name] < reference]
        peers = [name for name in tighter if name.startswith("OmniSafe")]
        if tighter:
            text += (f"; tighter than CRLLK-D ({reference:.2f}): "
                     + ", ".join(f"{name} ({ratios[name]:.2f})" for name in tighter))
        text += ("; OmniSafe's learners do better than CRLLK-D here" if peers else
                 "; neither OmniSafe learner does better than CRLLK-D here")
        sentences.append(text)
    return ("From state, crllk's learners beside OmniSafe's PPOLag and CPPOPID on the same tasks "
            f"({len(document['settings']['seeds'])} seeds each, "
            f"{document['settings']['episodes']} test episodes per run, "
            "[Peer libraries](docs/results/peers.md)): " + "; ".join(sentences) + ".")


def _replace(text: str, start: str, end: str, block: str) -> str:
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    return f"{head}{start}\n{block}\n{end}{tail}"


def write(readme: Path = REPO / "README.md") -> None:
    text = _replace(readme.read_text(), START, END, results_table())
    if PEERS.is_file():
        text = _replace(text, PEERS_START, PEERS_END, peers_summary())
    readme.write_text(text)


if __name__ == "__main__":
    if sys.argv[1:] == ["--write"]:
        write()
    else:
        print(results_table())
        if PEERS.is_file():
            print(peers_summary())
