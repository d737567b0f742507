"""Every seed of every agent on every map, in one place: ``results/<obs>/seeds.md``.

The experiments' tables give mean ± std across seeds; a constraint is claimed per seed, so this
file shows each seed's evaluation next to the others, for the sampled policy (the one the
constraints are learned for) and for the deployed one (its mode). It is written from the
tables' JSON documents (``table1.json`` for ``small_loop``, ``table_<map>.json`` for the
others) whenever an experiment writes a table, and the documentation site includes it as it
is.
"""

from __future__ import annotations

import json
import re
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from crllk.evaluation.report import DIRECTIONS
from crllk.experiments.runs import MAP_TASKS, deployed_note, expected_forms_deployed
from crllk.files import atomic_write_text
from crllk.paths import task_file, task_names
from crllk.protocol import TEST_SEED
from crllk.yaml_files import read_yaml

SEED_OF_RUN = re.compile(r"-seed(\d+)$")
"""The training seed at the end of a run directory's name (``CRLLK-D-a0.5-seed1``)."""

PER_SEED_METRICS = (("J_clane", 3), ("J_coll", 2), ("J_R", 2))
"""The three numbers of a cell, with their decimals: lane deviation (dm), collisions per
episode, travel (m)."""

INTERVAL_DIGITS = 2
"""Decimals of the confidence intervals in a cell."""


def table_documents(results: Path) -> dict[str, dict[str, Any]]:
    """The table documents of one observation's results folder, by name (``table1``,
    ``table_zigzag``, ...): Table 1 first, then the maps tables in the maps experiment's order
    (then any other ``table_*.json``, by name)."""
    named = [results / f"table_{task}.json" for task in MAP_TASKS]
    paths = [results / "table1.json", *named,
             *(p for p in sorted(results.glob("table_*.json")) if p not in named)]
    return {path.stem: json.loads(path.read_text()) for path in paths if path.exists()}


def seed_cells(entry: Mapping[str, Any], thresholds: Mapping[str, float] | None = None,
               ) -> dict[int, str]:
    """``{seed: "J_clane / J_coll / J_R ✓"}`` of one agent's evaluations (an agent's entry of
    a table document, or its ``"mode"``): ✓ where every constraint held for that seed, ✗
    where one did not; each constraint's 95 % confidence interval in brackets where the entry
    has them (:func:`crllk.evaluation.report.aggregate`), and then, given the ``thresholds``
    (by constraint name), a second mark: whether every interval's upper bound holds too."""
    intervals = entry.get("intervals", {})
    cells = {}
    for index, run in enumerate(entry["runs"]):
        match = SEED_OF_RUN.search(run)
        if match is None:
            raise ValueError(f"run directory {run!r} does not end in -seed<N>")
        numbers = []
        for metric, digits in PER_SEED_METRICS:
            number = f"{entry[metric]['values'][index]:.{digits}f}"
            if metric in intervals:
                low, high = intervals[metric][index]
                number += f" ({low:.{INTERVAL_DIGITS}f}–{high:.{INTERVAL_DIGITS}f})"
            numbers.append(number)
        mark = "✓" if entry["satisfied"][index] else "✗"
        if thresholds is not None and intervals:
            mark += " " + _mark(all(intervals[c["metric"]][index][1] <= thresholds[c["name"]]
                                    for c in entry["constraints"]))
        cells[int(match.group(1))] = f"{' / '.join(numbers)} {mark}"
    return cells


def _mark(holds: bool) -> str:
    return "✓" if holds else "✗"


def direction_cells(entry: Mapping[str, Any], thresholds: Mapping[str, float],
                    ) -> dict[tuple[int, str], str]:
    """``{(seed, direction): "J_clane (interval) / J_coll (interval) ✓ ✗"}`` of an entry whose
    runs kept their start directions: the constraints over the episodes that started in each
    direction, judged on the point estimate and on the 95 % upper bound."""
    cells = {}
    for run, directions in zip(entry["runs"], entry.get("by_direction", []), strict=False):
        match = SEED_OF_RUN.search(run)
        if match is None:
            raise ValueError(f"run directory {run!r} does not end in -seed<N>")
        for direction, result in directions.items():
            numbers, point, upper = [], True, True
            for c in entry["constraints"]:
                metric, bound = c["metric"], thresholds[c["name"]]
                low, high = result[f"{metric}_interval"]
                digits = dict(PER_SEED_METRICS).get(metric, 3)
                numbers.append(f"{result[metric]:.{digits}f} ({low:.{INTERVAL_DIGITS}f}–"
                               f"{high:.{INTERVAL_DIGITS}f})")
                point &= result[metric] <= bound
                upper &= high <= bound
            cells[int(match.group(1)), direction] = (
                f"{result['episodes']} episodes: {' / '.join(numbers)} "
                f"{_mark(point)} {_mark(upper)}")
    return cells


def seeds_table(documents: Mapping[str, Mapping[str, Any]], mode: bool = False) -> list[str]:
    """A Markdown table, a row per agent and seed, a column per map (``—`` where that agent
    or seed was not evaluated there); with ``mode``, of the deployed policies."""
    tasks = list(dict.fromkeys(document["task"] for document in documents.values()))
    rows: dict[tuple[str, int], dict[str, str]] = {}
    for document in documents.values():
        task = document["task"]
        for agent, entry in document["agents"].items():
            source = entry.get("mode") if mode else entry
            if source is None:
                continue
            for seed, cell in seed_cells(source, document["thresholds"]).items():
                rows.setdefault((agent, seed), {})[task] = cell
    lines = ["| agent, seed | " + " | ".join(tasks) + " |", "| --- " * (len(tasks) + 1) + "|"]
    agents = list(dict.fromkeys(agent for agent, _ in rows))
    for agent in agents:
        for seed in sorted(seed for a, seed in rows if a == agent):
            cells = [rows[agent, seed].get(task, "—") for task in tasks]
            lines.append(f"| {agent} seed {seed} | " + " | ".join(cells) + " |")
    return lines


def seeds_markdown(documents: Mapping[str, Mapping[str, Any]]) -> str:
    """``seeds.md``: the sampled policies' table and, where evaluated, the deployed ones'.

    Raises:
        ValueError: the documents differ in thresholds or evaluation (one table, one setting).
    """
    first = next(iter(documents.values()))
    thresholds, settings = first["thresholds"], first["settings"]
    for name, document in documents.items():
        theirs = document["settings"]
        if document["thresholds"] != thresholds or any(
                theirs[key] != settings[key] for key in ("episodes", "eval_seed", "obs")):
            raise ValueError(f"{name}.json was evaluated with other thresholds or episodes "
                             f"than {next(iter(documents))}.json: no common table")
    seed = settings["eval_seed"]
    split = ("the test seed, used for nothing else" if seed == TEST_SEED
             else "a validation seed, not the test protocol's")
    lines = [
        "# Every seed", "",
        f"Each cell is one training run: J_clane (dm, ≤ {thresholds['lane']}) / J_coll "
        f"(collisions per episode, ≤ {thresholds['collision']}) / J_R (m per episode), over "
        f"{settings['episodes']} evaluation episodes from spawn seed {seed} ({split}; never "
        "a training seed); ✓ where both constraints hold for that run, ✗ where one "
        "does not (judged on the numbers themselves). In brackets, where the tables keep them, "
        "the 95 % confidence interval of each constraint's metric over the run's episodes "
        "(Wilson's for J_coll, the fraction of episodes that end on a collision; the normal "
        "interval of the mean for J_clane): how far the episodes pin the number down; the "
        "second mark says whether both upper bounds hold too. "
        f"Observation: `{settings['obs']}`. Written from "
        + ", ".join(f"`{name}.json`" for name in documents)
        + ", which give each table's command, budget and machine.", "",
        "## The sampled policy (the one the constraints are learned for)", "",
        *seeds_table(documents), ""]
    with_mode = any("mode" in entry for document in documents.values()
                    for entry in document["agents"].values())
    expected = expected_forms_deployed(entry["mode"] for document in documents.values()
                                        for entry in document["agents"].values()
                                        if "mode" in entry)
    if with_mode and expected:
        note = deployed_note(entry.get("mode") for document in documents.values()
                             for entry in document["agents"].values())
        lines += [f"## The deployed policy ({note})", "",
                  *seeds_table(documents, mode=True), ""]
    elif with_mode:
        lines += ["## The deployed policy (the most probable action, what `crllk.export` "
                  "wrote when these were evaluated)", "", *seeds_table(documents, mode=True), ""]
    for document in documents.values():
        if any("by_direction" in entry for entry in document["agents"].values()):
            lines += [f"## By start direction: {document['task']}", "",
                      f"{_directions_note(document['task'])} The constraints over the episodes "
                      "that started in each direction of the loop (J_clane / J_coll with their "
                      "95 % intervals; marks: point estimate, upper bound).", "",
                      *direction_table(document),
                      *(["", *direction_table(document, mode=True)] if with_mode else []), ""]
    return "\n".join(lines)


def _directions_note(task: str) -> str:
    """Whether the shipped task's obstacles stand in the lane of one direction."""
    if task in task_names() and (read_yaml(task_file(task)).get("map") or {}).get("objects"):
        return "The obstacles of this map stand in the lane of one direction (the intended one)."
    return "This map has no obstacles."


def direction_table(document: Mapping[str, Any], mode: bool = False) -> list[str]:
    """A row per agent and seed, a column per start direction, of one table document's
    runs (with ``mode``: of the deployed policies)."""
    expected = expected_forms_deployed(entry["mode"] for entry in document["agents"].values()
                                        if "mode" in entry)
    label = ("sampled policy" if not mode else "deployed policy" if expected
             else "deployed policy (mode)")
    lines = [f"| {label}: agent, seed | " + " | ".join(DIRECTIONS) + " |",
             "| --- " * (len(DIRECTIONS) + 1) + "|"]
    for agent, entry in document["agents"].items():
        source = entry.get("mode") if mode else entry
        if source is None or "by_direction" not in source:
            continue
        cells = direction_cells(source, document["thresholds"])
        for seed in sorted({seed for seed, _ in cells}):
            lines.append(f"| {agent} seed {seed} | " + " | ".join(
                cells.get((seed, d), "—") for d in DIRECTIONS) + " |")
    return lines


def write_seeds(results: Path) -> Path | None:
    """Writes ``<results>/seeds.md`` from the table documents there (none: nothing). Tables
    evaluated with other settings than the others (``--episodes``, ``--seeds``...) have no
    common table: a one-line warning, and the table just written stands alone."""
    documents = table_documents(results)
    if not documents:
        return None
    try:
        markdown = seeds_markdown(documents)
    except ValueError as err:
        print(f"warning: {results / 'seeds.md'} not written: {err}", file=sys.stderr)
        return None
    return atomic_write_text(results / "seeds.md", markdown)
