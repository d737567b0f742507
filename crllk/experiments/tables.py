"""The experiments' tables: mean ± std across seeds per agent, the paper's numbers beside them,
verdicts and comparisons, as a JSON document and the Markdown written from it."""

from __future__ import annotations

import json
import os
import platform
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from crllk.evaluation.report import PAPER_CONSTRAINTS, aggregate
from crllk.evaluation.runs import evaluate_follower
from crllk.experiments.runs import (
    PAPER_J_R_PER_METRE,
    THRESHOLDS,
    Outcome,
    Settings,
    deployed_label,
    deployed_note,
    expected_forms_deployed,
    mode_aggregate,
)
from crllk.experiments.seeds import write_seeds
from crllk.files import atomic_write_text
from crllk.protocol import TEST_SEED


def agent_results(outcome: Outcome, task: str, agents: Sequence[str],
                  lane_threshold: float = THRESHOLDS["lane"]) -> dict[str, dict[str, Any]]:
    """Mean ± std across seeds per agent, with the training budget actually spent, and under
    ``"mode"`` those of the deployed policy when every seed's was evaluated."""
    results = {}
    for agent in agents:
        specs = [s for s in outcome.documents
                 if s.agent == agent and s.task == task and s.lane_threshold == lane_threshold]
        docs = [outcome.documents[s] for s in specs]
        if docs:
            summary = aggregate(docs)
            if all(s in outcome.modes for s in specs):
                summary["mode"] = mode_aggregate([outcome.modes[s] for s in specs])
            summary["train_seconds"] = [d["source"]["elapsed_s"] for d in docs]
            summary["frames"] = [d["source"]["frames"] for d in docs]
            summary["multipliers"] = [d["source"]["multipliers"] for d in docs]
            summary["action_histogram"] = [d["action_histogram"] for d in docs]
            results[agent] = summary
    return results


def _cell(entry: dict[str, float], digits: int) -> str:
    return f"{entry['mean']:.{digits}f} ± {entry['std']:.{digits}f}"


def _constraints(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """The constraints of the agents' evaluations (the paper's two for older documents)."""
    first = next(iter(results.values()), {})
    return list(first.get("constraints") or PAPER_CONSTRAINTS)


def _all_of(constraints: Sequence[Any]) -> str:
    return "both constraints" if len(constraints) == 2 else "every constraint"


def verdicts(results: dict[str, dict[str, Any]], constrained: Sequence[str],
             thresholds: dict[str, float], mode: bool = False) -> list[str]:
    """One sentence per constrained agent: satisfied, or by how much each constraint misses
    (with ``mode``: of its deployed policy, where evaluated)."""
    constraints = _constraints(results)
    everything = _all_of(constraints)
    lines = []
    for agent in constrained:
        entry = results.get(agent, {}).get("mode") if mode else results.get(agent)
        if entry is None:
            continue
        misses = []
        for c in constraints:
            value, bound = entry[c["metric"]]["mean"], thresholds[c["name"]]
            if value > bound:
                unit = f" {c['unit']}" if c["unit"] == "dm" else ""
                misses.append(f"{c['metric']} by {value - bound:.3f}{unit}")
        per_seed = ", ".join("yes" if s else "no" for s in entry["satisfied"])
        held = "both hold per seed" if len(constraints) == 2 else "all hold per seed"
        intervals = entry.get("intervals")
        if intervals:
            upper = [all(intervals[c["metric"]][k][1] <= thresholds[c["name"]]
                         for c in constraints) for k in range(len(entry["satisfied"]))]
            per_seed += "; at the 95 % upper bound: " + ", ".join(
                "yes" if u else "no" for u in upper)
        name = f"{agent}'s {deployed_label([entry])}" if mode else agent
        if misses:
            lines.append(f"- {name} misses on average: {'; '.join(misses)} "
                         f"({held}: {per_seed}).")
        else:
            lines.append(f"- {name} satisfies {everything} on average "
                         f"({held}: {per_seed}).")
    return lines


def comparisons(results: dict[str, dict[str, Any]], pairs: Sequence[tuple[str, str]],
                ) -> list[str]:
    """Constrained agent against its fixed-weight baseline, as measured."""
    constraints = _constraints(results)
    lines = []
    for ours, baseline in pairs:
        if ours not in results or baseline not in results:
            continue
        a, b = results[ours], results[baseline]
        metrics = ", ".join(
            f"{c['metric']} {a[c['metric']]['mean']:.3f} vs {b[c['metric']]['mean']:.3f}"
            + (f" {c['unit']}" if c["unit"] == "dm" else "") for c in constraints)
        lines.append(f"- {ours} vs {baseline}: J_R {a['J_R']['mean']:.2f} vs "
                     f"{b['J_R']['mean']:.2f} m, {metrics}.")
    return lines


def machine_text() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} CPU cores ({cpu}), no GPU, Python {platform.python_version()}"


def table_markdown(document: dict[str, Any]) -> str:
    """The Markdown table of an experiment from its JSON document (see :func:`write_table`)."""
    results, follower, paper = document["agents"], document["follower"], document["paper"]
    settings, thresholds = document["settings"], document["thresholds"]
    agents = list(results)
    header = "| metric | " + " | ".join(agents) + " | lane follower |"
    rule = "| --- " * (len(agents) + 2) + "|"
    rows = []
    for metric, label, digits in (
            *((c["metric"], f"{c['metric']} ({c['unit']}, ≤ {thresholds[c['name']]})", 3)
              for c in _constraints(results)),
            ("J_R", "J_R (m per episode)", 2),
            ("episode_length", "episode length (steps)", 0)):
        cells = [_cell(results[a][metric], digits) for a in agents]
        cells.append(f"{follower[metric]:.{digits}f}")
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
        if paper and metric in ("J_clane", "J_coll", "J_R"):
            paper_digits = 1 if metric == "J_R" else 2
            paper_cells = [f"{paper[a][metric][0]:.{paper_digits}f} ± "
                           f"{paper[a][metric][1]:.{paper_digits}f}" for a in agents]
            suffix = f" (paper, ≈ {PAPER_J_R_PER_METRE:g} per m)" if metric == "J_R" else " (paper)"
            rows.append(f"| {metric}{suffix} | " + " | ".join(paper_cells) + " | |")
    with_mode = any("mode" in results[a] for a in agents)
    expected = expected_forms_deployed(results[a]["mode"] for a in agents
                                        if "mode" in results[a])
    deployed_row = "deployed policy" if expected else "deployed policy (mode)"
    if with_mode:
        for metric, digits in (*((c["metric"], 3) for c in _constraints(results)), ("J_R", 2)):
            cells = [_cell(results[a]["mode"][metric], digits) if "mode" in results[a] else "—"
                     for a in agents]
            rows.append(f"| {metric}, {deployed_row} | " + " | ".join(cells) + " | |")
    minutes = [s / 60 for a in agents for s in results[a]["train_seconds"]]
    obs = settings["obs"]
    lines = [
        f"# {document['title']}", "",
        f"Map `{document['task']}`, α1 = {thresholds['lane']} dm, α2 = "
        f"{thresholds['collision']} collisions per episode. Mean ± std (population, ddof 0) "
        f"across training seeds {seeds_text(settings, agents)}.", "",
        f"- Observation: `{obs}`" + (" (lane-relative features, not the camera)"
                                     if obs == "state" else " (the 30×40 camera image)") + ".",
        f"- Budget: {settings['frames']:,} environment frames per run (training wall time "
        f"{min(minutes):.1f}–{max(minutes):.1f} min per run, "
        + ("one run at a time)." if settings["jobs"] == 1
           else f"{settings['jobs']} runs at a time)."),
        f"- Evaluation: {settings['episodes']} episodes per run of the sampled policy (the one "
        f"the constraints are learned for), spawn and sampling seed {settings['eval_seed']} "
        + ("(the test seed: evaluated once per finished run, never used to choose a setting)"
           if settings["eval_seed"] == TEST_SEED else
           "(a validation seed, not the test protocol's; never a training seed)")
        + ", the last checkpoint" + (
            "; the rows marked *deployed policy* play the same episodes with "
            + deployed_note(results[a].get("mode") for a in agents) + "."
            if with_mode and expected else
            "; the rows marked *deployed policy (mode)* play the same episodes with the most "
            "probable action, the policy `crllk.export` wrote for the robot when these were "
            "evaluated." if with_mode
            else "."),
        f"- Command: `{settings['command']}` ({invocation_note(document)}).",
        f"- Machine: {settings['machine']}.", "",
        header, rule, *rows, "",
    ]
    if paper:
        lines += ["The paper's J_R is the sum of its per-step reward (speed × cos(heading) at "
                  f"30 Hz), about {PAPER_J_R_PER_METRE:g} per metre; ours is metres along the "
                  "lane. Its episodes also end on leaving a road tile or hitting an object, "
                  "after at most 512 steps.", ""]
    constrained = [a for a in agents if a.startswith("CRLLK")]
    lines += ["Constraints (mean over seeds):", "",
              *verdicts(results, constrained, thresholds),
              *(verdicts(results, constrained, thresholds, mode=True) if with_mode else [])]
    if document["pairs"]:
        lines += ["", "Against the fixed-weight baselines (same budget):", "",
                  *comparisons(results, document["pairs"])]
    lines += ["", "The lane follower is the scripted controller (true pose, privileged), "
              "evaluated through the same episodes and metrics as a reference."]
    return "\n".join(lines) + "\n"


def write_table(name: str, title: str, task: str, agents: Sequence[str], outcome: Outcome,
                settings: Settings, paper: dict[str, Any] | None,
                pairs: Sequence[tuple[str, str]]) -> Path:
    """Writes ``results/<name>.json`` (everything behind the table) and ``<name>.md``, and
    rewrites ``seeds.md`` from every table there."""
    follower = evaluate_follower(task, episodes=settings.episodes, seed=settings.eval_seed,
                                 thresholds=dict(THRESHOLDS))
    document = {"title": title, "task": task, "thresholds": THRESHOLDS,
                "settings": settings_dict(settings), **invocation(outcome),
                "agents": agent_results(outcome, task, agents),
                "follower": follower["summary"], "paper": paper,
                "pairs": [list(p) for p in pairs],
                "runs": {str(s.directory(settings.runs_root)): d["summary"]
                         for s, d in outcome.documents.items() if s.task == task}}
    settings.results.mkdir(parents=True, exist_ok=True)
    path = settings.results / f"{name}.md"
    atomic_write_text(path.with_suffix(".json"), json.dumps(document, indent=1) + "\n")
    markdown = table_markdown(document)
    atomic_write_text(path, markdown)
    write_seeds(settings.results)
    print(markdown, flush=True)
    return path


def settings_dict(settings: Settings) -> dict[str, Any]:
    return {"frames": settings.frames, "seeds": list(settings.seeds),
            "crllk_seeds": list(settings.crllk_seeds),
            "train_overrides": list(settings.train_overrides),
            "episodes": settings.episodes, "obs": settings.obs, "eval_seed": settings.eval_seed,
            "jobs": settings.jobs, "command": settings.command, "machine": machine_text()}


def seeds_text(settings: dict[str, Any], agents: Sequence[str]) -> str:
    """The training seeds of a table's ``agents``: ``0, 1`` or ``0, 1, 2 (CRLLK agents) and 0, 1
    (fixed-weight baselines)`` (documents older than per-agent seeds: ``seeds`` for all)."""
    seeds = settings["seeds"]
    crllk = settings.get("crllk_seeds", seeds)
    has_crllk = any(a.startswith("CRLLK") for a in agents)
    has_fixed = any(not a.startswith("CRLLK") for a in agents)
    if crllk == seeds or not has_crllk:
        return ", ".join(map(str, seeds))
    if not has_fixed:
        return ", ".join(map(str, crllk))
    return (f"{', '.join(map(str, crllk))} (CRLLK agents) and {', '.join(map(str, seeds))} "
            "(fixed-weight baselines)")


def write_documents(settings: Settings, name: str, document: dict[str, Any],
                    markdown: str) -> list[Path]:
    """Writes an experiment's ``<results>/<name>.json`` and ``<name>.md`` (printing the
    Markdown); returns both paths."""
    settings.results.mkdir(parents=True, exist_ok=True)
    json_path = atomic_write_text(settings.results / f"{name}.json",
                                  json.dumps(document, indent=1) + "\n")
    md_path = atomic_write_text(settings.results / f"{name}.md", markdown)
    print(markdown, flush=True)
    return [json_path, md_path]


def invocation(outcome: Outcome) -> dict[str, Any]:
    """What the invocation did, for its document: wall time (s), runs, and how many of them
    it trained and evaluated."""
    return {"wall_s": outcome.wall_s, "runs_total": len(outcome.documents),
            "runs_trained": outcome.trained, "evaluations_made": outcome.evaluated}


def invocation_note(document: dict[str, Any]) -> str:
    """What the command that wrote a table did: how long it ran and, where the document
    records it, how many runs it trained and evaluated (finished runs are reused, so a table
    written from finished runs took no training time)."""
    note = f"{document['wall_s'] / 60:.1f} min wall for the invocation that wrote it"
    if "runs_trained" not in document:
        return note + "; finished runs are reused"
    return (f"{note}, which trained {document['runs_trained']} of "
            f"{document['runs_total']} runs and made {document['evaluations_made']} "
            "evaluations; finished runs are reused")
