"""``python -m crllk.experiments sweep``: is tuning still needed? Fixed-weight PPO-D over a grid
of weights next to CRLLK-D's single configuration, on every map."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from crllk.evaluation.report import aggregate
from crllk.experiments.runs import THRESHOLDS, Outcome, RunSpec, Settings, train_and_evaluate
from crllk.experiments.tables import invocation, invocation_note, settings_dict
from crllk.files import atomic_write_text


def sweep_specs(settings: Settings) -> list[RunSpec]:
    """CRLLK-D and PPO-D at every pair of fixed weights, on every sweep map and seed."""
    specs = []
    for task in settings.sweep_tasks:
        for seed in settings.seeds:
            specs.append(RunSpec("CRLLK-D", task, seed))
            for lane in settings.lane_weights:
                for collision in settings.collision_weights:
                    specs.append(RunSpec("PPO-D", task, seed, tag=f"-w{lane:g}-{collision:g}",
                                         extra=(f"algo.constraints.lane.initial={lane}",
                                                f"algo.constraints.collision.initial={collision}",
                                                "algo.constraints.collision.max_value="
                                                f"{max(collision, 100)}")))
    return specs


def sweep(settings: Settings) -> list[Path]:
    """Fixed-weight PPO-D over :data:`SWEEP_LANE_WEIGHTS` × :data:`SWEEP_COLLISION_WEIGHTS` next
    to CRLLK-D on every map: ``<results>/<obs>/sweep.json``, ``.md`` and ``.png``."""
    from crllk.analysis.figures import draw_sweep, save_figure  # matplotlib only when drawing

    specs = sweep_specs(settings)
    outcome = train_and_evaluate(specs, settings)
    document = sweep_document(outcome, settings)
    name = "sweep"
    settings.results.mkdir(parents=True, exist_ok=True)
    json_path = settings.results / f"{name}.json"
    atomic_write_text(json_path, json.dumps(document, indent=1) + "\n")
    markdown = sweep_markdown(document)
    atomic_write_text(settings.results / f"{name}.md", markdown)
    picture = save_figure(draw_sweep(document), settings.results / f"{name}.png")
    print(markdown, flush=True)
    return [json_path, settings.results / f"{name}.md", picture]


def sweep_document(outcome: Outcome, settings: Settings) -> dict[str, Any]:
    """Per map: every fixed-weight pair's mean metrics across seeds and whether both
    constraints hold on every seed, CRLLK-D's, and the comparison."""
    maps: dict[str, Any] = {}
    for task in settings.sweep_tasks:
        entries = []
        for specs in _group_by_weights(outcome, task):
            docs = [outcome.documents[s] for s in specs]
            summary = aggregate(docs)
            lane = collision = None
            for item in specs[0].extra:
                key, value = item.split("=")
                if key == "algo.constraints.lane.initial":
                    lane = float(value)
                elif key == "algo.constraints.collision.initial":
                    collision = float(value)
            entries.append({"agent": specs[0].agent, "lane_weight": lane,
                            "collision_weight": collision,
                            **{m: summary[m] for m in ("J_R", "J_clane", "J_coll")},
                            "satisfied": summary["satisfied"],
                            "satisfied_all_seeds": all(summary["satisfied"])})
        crllk = next(e for e in entries if e["agent"] == "CRLLK-D")
        fixed = [e for e in entries if e["agent"] == "PPO-D"]
        feasible = [e for e in fixed if e["satisfied_all_seeds"]]
        best = max(feasible, key=lambda e: e["J_R"]["mean"]) if feasible else None
        maps[task] = {"crllk": crllk, "fixed": fixed, "best_feasible_fixed": best,
                      "feasible_pairs": len(feasible)}
    return {"title": f"Fixed-weight PPO-D against CRLLK-D ({settings.obs})",
            "thresholds": THRESHOLDS, "lane_weights": list(settings.lane_weights),
            "collision_weights": list(settings.collision_weights),
            "settings": settings_dict(settings), **invocation(outcome), "maps": maps}


def _group_by_weights(outcome: Outcome, task: str) -> list[list[RunSpec]]:
    groups: dict[tuple[str, str], list[RunSpec]] = {}
    for spec in outcome.documents:
        if spec.task == task:
            groups.setdefault((spec.agent, spec.tag), []).append(spec)
    return list(groups.values())


def sweep_markdown(document: dict[str, Any]) -> str:
    """The sweep's Markdown: a table per map and what it shows, from its JSON document."""
    thresholds, settings = document["thresholds"], document["settings"]
    lines = [f"# {document['title']}", "",
             f"α1 = {thresholds['lane']} dm, α2 = {thresholds['collision']}. Fixed weights: "
             f"λ_lane ∈ {document['lane_weights']} × λ_coll ∈ {document['collision_weights']}; "
             f"CRLLK-D learns both with its single default configuration. Mean over training "
             f"seeds {', '.join(map(str, settings['seeds']))}; 'holds' means both constraints "
             f"hold on every seed.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} evaluation episodes per run of the sampled policy, spawn "
             f"and sampling seed {settings['eval_seed']}.",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.", ""]
    for task, entry in document["maps"].items():
        lines += [f"## {task}", "", "| agent | λ_lane | λ_coll | J_clane (dm) | J_coll | J_R (m) "
                  "| holds |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for e in [entry["crllk"], *entry["fixed"]]:
            weights = ("learned", "learned") if e["agent"] == "CRLLK-D" else (
                f"{e['lane_weight']:g}", f"{e['collision_weight']:g}")
            lines.append(f"| {e['agent']} | {weights[0]} | {weights[1]} | "
                         f"{e['J_clane']['mean']:.3f} | {e['J_coll']['mean']:.3f} | "
                         f"{e['J_R']['mean']:.2f} | "
                         f"{'yes' if e['satisfied_all_seeds'] else 'no'} |")
        lines += ["", sweep_verdict(task, entry), ""]
    return "\n".join(lines)


def sweep_verdict(task: str, entry: dict[str, Any]) -> str:
    """What the sweep shows on one map, in one sentence."""
    crllk, best = entry["crllk"], entry["best_feasible_fixed"]
    holds = "meets both constraints" if crllk["satisfied_all_seeds"] else \
        "does not meet both constraints on every seed"
    text = (f"On {task}, {entry['feasible_pairs']} of {len(entry['fixed'])} fixed-weight pairs "
            f"meet both constraints on every seed; CRLLK-D {holds} with J_R "
            f"{crllk['J_R']['mean']:.2f} m")
    if best is None:
        return text + "."
    difference = crllk["J_R"]["mean"] - best["J_R"]["mean"]
    relation = "farther than" if difference > 0 else "less far than"
    return (text + f", {abs(difference):.2f} m {relation} the best of them (λ_lane "
            f"{best['lane_weight']:g}, λ_coll {best['collision_weight']:g}: "
            f"{best['J_R']['mean']:.2f} m).")
