"""``python -m crllk.experiments robustness``: how randomisation carries a policy through
conditions it never trained in.

CRLLK-D from pixels, trained without randomisation (the runs of Table 1 and the maps table,
reused) and with ``task.randomize=default``, on ``small_loop`` and ``zigzag``, each seed
evaluated (``crllk.evaluate``, the same episodes and seeds as every evaluation) under each
condition of :func:`crllk.evaluation.robustness.conditions`: nominal, each held-out axis, the
deployment camera path and everything together. The table and figure go to
``results/<obs>/robustness.{md,json,png}``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from crllk.evaluation.report import aggregate
from crllk.evaluation.robustness import conditions, result_name
from crllk.experiments.runs import (
    THRESHOLDS,
    RunSpec,
    Settings,
    evaluate_runs,
    evaluation_is_current,
    train_and_evaluate,
)
from crllk.files import atomic_write_text

AGENT = "CRLLK-D"
RANDOMIZED = "-rand"
"""Tag of the runs trained with ``task.randomize=default``."""
TRAININGS = {"nominal": "", "randomized": RANDOMIZED}


def robustness_specs(settings: Settings) -> list[RunSpec]:
    """Each task and seed, trained without and with randomisation."""
    return [RunSpec(AGENT, task, seed, extra=("task.randomize=default",) if tag else (),
                    tag=tag)
            for task in settings.robust_tasks for tag in TRAININGS.values()
            for seed in settings.seeds]


def evaluate_conditions(specs: Sequence[RunSpec], settings: Settings,
                        table: Mapping[str, Mapping[str, Any]]) -> dict[tuple[RunSpec, str], dict]:
    """Evaluates every run under every condition not evaluated yet; returns the documents."""
    root = settings.runs_root
    requests = [(s.directory(root), {"name": result_name(name), "overrides": dict(overrides)})
                for s in specs for name, overrides in table.items()
                if not evaluation_is_current(s.directory(root), settings, result_name(name))]
    print(f"evaluating {len(requests)} of {len(specs) * len(table)} run conditions", flush=True)
    evaluate_runs(requests, settings)
    return {(s, name): json.loads((s.directory(root) / f"{result_name(name)}.json").read_text())
            for s in specs for name in table}


def robustness_document(documents: Mapping[tuple[RunSpec, str], dict], settings: Settings,
                        table: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Mean ± std across seeds per task, training and condition, and each seed's verdict."""
    cells = []
    for task in settings.robust_tasks:
        for training, tag in TRAININGS.items():
            for name in table:
                docs = [d for (s, c), d in documents.items()
                        if s.task == task and s.tag == tag and c == name]
                summary = aggregate(docs)
                cells.append({"task": task, "training": training, "condition": name,
                              "J_R": summary["J_R"], "J_clane": summary["J_clane"],
                              "J_coll": summary["J_coll"],
                              "satisfied": [bool(d["summary"]["satisfied"]) for d in docs]})
    return {"title": "Robustness: CRLLK-D from pixels under held-out conditions",
            "thresholds": THRESHOLDS, "conditions": {k: dict(v) for k, v in table.items()},
            "settings": {"obs": settings.obs, "episodes": settings.episodes,
                         "seeds": list(settings.seeds),
                         "frames": settings.frames, "eval_seed": settings.eval_seed,
                         "command": settings.command},
            "cells": cells}


def robustness_markdown(document: Mapping[str, Any]) -> str:
    """One table per task: conditions down, trainings across."""
    lines = [f"# {document['title']}", ""]
    s = document["settings"]
    lines += [f"`{s['command']}`: {len(s['seeds'])} seeds, {s['episodes']} episodes per "
              f"condition from spawn seed {s['eval_seed']}, {s['frames']:,} frames per run. "
              f"Holds: J_clane ≤ {document['thresholds']['lane']} dm and J_coll ≤ "
              f"{document['thresholds']['collision']}, per seed.", ""]
    for task in dict.fromkeys(c["task"] for c in document["cells"]):
        lines += [f"## {task}", "", "| condition | training | J_R (m) | J_clane (dm) | J_coll | "
                  "holds per seed |", "| --- | --- | --- | --- | --- | --- |"]
        for c in (c for c in document["cells"] if c["task"] == task):
            holds = " ".join("yes" if ok else "no" for ok in c["satisfied"])
            lines.append(f"| {c['condition']} | {c['training']} | "
                         f"{c['J_R']['mean']:.2f} ± {c['J_R']['std']:.2f} | "
                         f"{c['J_clane']['mean']:.3f} ± {c['J_clane']['std']:.3f} | "
                         f"{c['J_coll']['mean']:.2f} ± {c['J_coll']['std']:.2f} | {holds} |")
        lines.append("")
    return "\n".join(lines)


def robustness(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates every condition, writes table, JSON and figure."""
    from crllk.analysis.figures import draw_robustness, save_figure

    specs = robustness_specs(settings)
    table = conditions() if not settings.conditions else \
        {name: overrides for name, overrides in conditions().items()
         if name in settings.conditions}
    unevaluated = [s for s in specs if not all(
        evaluation_is_current(s.directory(settings.runs_root), settings, result_name(name))
        for name in table)]
    train_and_evaluate(specs, settings, policies=unevaluated)
    document = robustness_document(evaluate_conditions(specs, settings, table), settings, table)
    out = settings.results
    written = [atomic_write_text(out / "robustness.json", json.dumps(document, indent=1) + "\n"),
               atomic_write_text(out / "robustness.md", robustness_markdown(document))]
    written.append(save_figure(draw_robustness(document), out / "robustness.png"))
    return written


__all__ = ["robustness", "robustness_document", "robustness_markdown",
           "robustness_specs"]
