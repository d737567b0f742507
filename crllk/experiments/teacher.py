"""``python -m crllk.experiments teacher``: what the privileged teacher buys. CRLLK-D from the
default configuration (the imitation weight falls from 1 to its floor, 0.3, and stays there),
with the teacher annealed to zero before the end, and without a teacher, on each map, every
seed judged on the test seed (sampled policy and deployed mode, each start direction apart)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from crllk.evaluation.report import aggregate
from crllk.experiments.runs import THRESHOLDS, Outcome, RunSpec, Settings, train_and_evaluate
from crllk.experiments.seeds import direction_cells, seed_cells
from crllk.experiments.tables import invocation, invocation_note, settings_dict
from crllk.files import atomic_write_text

TEACHER_TASKS = ("obstacle_loop", "small_loop")
"""The maps of the ablation: the one with obstacles in a lane, and the paper's Table 1 map."""
TEACHER_VARIANTS: dict[str, tuple[str, tuple[str, ...]]] = {
    "floor 0.3 (default)": ("", ()),
    "annealed to 0 by 400k frames": ("-teacher0", ("teacher.final=0", "teacher.frames=400000")),
    "no teacher": ("-noteacher", ("teacher.coeff=0",)),
}
"""Each variant's run-directory tag and trainer overrides: the default's weight falls from 1
to 0.3 over 150,000 frames and stays; annealed, it falls to 0 over 400,000 of the 500,000
frames, so the last 100,000 are Lagrangian PPO alone; without, it is 0 throughout."""


def teacher_specs(settings: Settings, tasks: Sequence[str] = TEACHER_TASKS) -> list[RunSpec]:
    """CRLLK-D with each teacher variant, on every map and seed."""
    return [RunSpec("CRLLK-D", task, seed, tag=tag, extra=extra)
            for task in tasks for tag, extra in TEACHER_VARIANTS.values()
            for seed in settings.seeds]


def teacher(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``teacher.json`` and
    ``teacher.md`` into ``<results>/<obs>/``."""
    specs = teacher_specs(settings)
    outcome = train_and_evaluate(specs, settings)
    document = teacher_document(outcome, settings)
    settings.results.mkdir(parents=True, exist_ok=True)
    json_path = atomic_write_text(settings.results / "teacher.json",
                                  json.dumps(document, indent=1) + "\n")
    markdown = teacher_markdown(document)
    md_path = atomic_write_text(settings.results / "teacher.md", markdown)
    print(markdown, flush=True)
    return [json_path, md_path]


def teacher_document(outcome: Outcome, settings: Settings) -> dict[str, Any]:
    """Per map and variant: the aggregate across seeds of the sampled policy and of the
    mode (with each run's intervals and start directions)."""
    maps: dict[str, Any] = {}
    for task in dict.fromkeys(s.task for s in outcome.documents):
        variants = {}
        for name, (tag, _) in TEACHER_VARIANTS.items():
            specs = [s for s in outcome.documents if s.task == task and s.tag == tag]
            if not specs:
                continue
            entry = aggregate([outcome.documents[s] for s in specs])
            if all(s in outcome.modes for s in specs):
                entry["mode"] = aggregate([outcome.modes[s] for s in specs])
            variants[name] = entry
        maps[task] = variants
    return {"title": f"The teacher measured: CRLLK-D ({settings.obs})", "thresholds": THRESHOLDS,
            "settings": settings_dict(settings), **invocation(outcome), "maps": maps}


def teacher_markdown(document: dict[str, Any]) -> str:
    """The ablation's Markdown from its JSON document: per map a row per variant and seed."""
    thresholds, settings = document["thresholds"], document["settings"]
    lines = [f"# {document['title']}", "",
             f"α1 = {thresholds['lane']} dm, α2 = {thresholds['collision']}. Each cell: J_clane "
             "(dm) / J_coll / J_R (m) of one training run, with the 95 % intervals of the "
             "constraints' metrics; marks: both constraints hold on the point estimate, then "
             "at the 95 % upper bound.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} test episodes per run from spawn seed "
             f"{settings['eval_seed']} (the test seed).",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.", ""]
    for task, variants in document["maps"].items():
        lines += [f"## {task}", "", "| teacher | seed | sampled policy | deployed policy (mode) |",
                  "| --- | --- | --- | --- |"]
        for name, entry in variants.items():
            sampled = seed_cells(entry, thresholds)
            mode = seed_cells(entry["mode"], thresholds) if "mode" in entry else {}
            for seed in sorted(sampled):
                lines.append(f"| {name} | {seed} | {sampled[seed]} | {mode.get(seed, '—')} |")
        directions = [(name, direction_cells(entry, thresholds))
                      for name, entry in variants.items() if "by_direction" in entry]
        if directions:
            lines += ["", "By start direction (sampled policy):", "",
                      "| teacher | seed | intended | reverse |", "| --- | --- | --- | --- |"]
            for name, cells in directions:
                for seed in sorted({seed for seed, _ in cells}):
                    lines.append(f"| {name} | {seed} | {cells.get((seed, 'intended'), '—')} | "
                                 f"{cells.get((seed, 'reverse'), '—')} |")
        lines.append("")
    return "\n".join(lines)


__all__ = ["TEACHER_TASKS", "TEACHER_VARIANTS", "teacher", "teacher_document",
           "teacher_markdown", "teacher_specs"]
