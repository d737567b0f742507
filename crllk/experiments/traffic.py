"""``python -m crllk.experiments traffic``: lane keeping with traffic. CRLLK-D (learned
multipliers), PPO-D (fixed weights) and CRLLK-C trained from pixels on ``traffic_loop`` (another
Duckiebot ahead in the robot's lane and one coming the other way; the headway constraint
J_chead) and ``pedestrian_loop`` (duckies crossing the road), judged on the test seed per task
and seed (sampled policy and deployed mode) with the paper's metrics, the community's
(:mod:`crllk.evaluation.community`) and what each episode collided with, beside the final
multipliers or weights.

CRLLK-C is there because none of the paper's three discrete actions stops (each drives
forward), so behind a slow vehicle or before a crossing duckie the discrete agents can only
weave or collide. The table shows it with the
scripted teacher (the lane follower that follows the traffic, :mod:`crllk.tasks.follower`)
answering in each action type through the same test episodes: what imitation can teach.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from crllk.evaluation.community import FORMATS, METRICS
from crllk.evaluation.report import aggregate
from crllk.evaluation.runs import evaluate_follower
from crllk.experiments.runs import (
    EXPECTED_FORMS,
    Outcome,
    RunSpec,
    Settings,
    agent_seeds,
    deployed_forms,
    train_and_evaluate,
)
from crllk.experiments.seeds import SEED_OF_RUN
from crllk.experiments.tables import (
    invocation,
    invocation_note,
    seeds_text,
    settings_dict,
    write_documents,
)

TRAFFIC_TASKS = {
    "traffic_loop": "other Duckiebots: one ahead in the robot's lane, slower than the robot may "
                    "drive, one coming the other way; J_chead is the fraction of steps closer "
                    "than traffic.headway behind the vehicle ahead",
    "pedestrian_loop": "duckies crossing the road at three straight tiles, at random times and "
                       "speeds",
}
"""The tasks and what each puts to the agent."""
TRAFFIC_AGENTS = ("CRLLK-D", "PPO-D", "CRLLK-C")
"""Learned multipliers against fixed weights with the paper's discrete actions, and learned
multipliers with continuous actions that can stand still (``action=stoppable``, run
directories ``CRLLK-C-stoppable-...``): a robot that cannot stop runs into a duckie crossing
close ahead."""
STOPPABLE = RunSpec("CRLLK-C", "", 0, extra=("action=stoppable",), tag="-stoppable")
"""What the CRLLK-C runs of the traffic tasks change: their action type and directory."""
TEACHER_ACTIONS = ("discrete", "continuous", "stoppable")
"""The action types the scripted teacher answers in for the table's reference rows."""


def traffic_specs(settings: Settings, tasks: Sequence[str] = tuple(TRAFFIC_TASKS)
                  ) -> list[RunSpec]:
    """Every agent of :data:`TRAFFIC_AGENTS` that ``--agents`` keeps on every task, with its
    training seeds (three for the CRLLK agents, two for the fixed-weight baseline); CRLLK-C
    with :data:`STOPPABLE` actions."""
    return [RunSpec(agent, task, seed, extra=STOPPABLE.extra, tag=STOPPABLE.tag)
            if agent == STOPPABLE.agent else RunSpec(agent, task, seed)
            for task in tasks for agent in TRAFFIC_AGENTS
            if agent in settings.agents for seed in agent_seeds(settings, agent)]


def agent_label(spec: RunSpec) -> str:
    """An agent's name in the traffic table: with its runs' tag (``CRLLK-C-stoppable``)."""
    return f"{spec.agent}{spec.tag}"


def traffic(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``traffic.json`` and
    ``traffic.md`` into ``<results>/<obs>/``."""
    outcome = train_and_evaluate(traffic_specs(settings), settings)
    teachers = {(task, action): evaluate_follower(task, episodes=settings.episodes,
                                                  seed=settings.eval_seed, action=action,
                                                  avoid_obstacles=True)
                for task in TRAFFIC_TASKS for action in TEACHER_ACTIONS}
    document = traffic_document(outcome, settings, teachers)
    return write_documents(settings, "traffic", document, traffic_markdown(document))


def agent_entry(documents: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """:func:`aggregate` of an agent's runs, with each run's community summary, terminations
    and final multipliers (or fixed weights)."""
    entry = aggregate(list(documents))
    entry["community"] = [d.get("community") for d in documents]
    entry["terminations"] = [dict(d.get("terminations", {})) for d in documents]
    entry["multipliers"] = [dict(d["source"].get("multipliers") or {}) for d in documents]
    return entry


def teacher_entry(document: Mapping[str, Any]) -> dict[str, Any]:
    """The scripted teacher's evaluation as an agent's entry of one run (no multipliers)."""
    entry = agent_entry([{**document, "source": {**document["source"],
                                                 "run_dir": "teacher-seed0"}}])
    entry["multipliers"] = [{}]
    return entry


def traffic_document(outcome: Outcome, settings: Settings,
                     teachers: Mapping[tuple[str, str], Mapping[str, Any]] | None = None
                     ) -> dict[str, Any]:
    """Per task and agent: the runs' test evaluations (sampled policy, and under ``"mode"``
    the deployed one where every seed's was evaluated); under ``"teacher"`` the scripted
    teacher's in each action type of ``teachers`` (by task and action)."""
    tasks: dict[str, Any] = {}
    for task in dict.fromkeys(s.task for s in outcome.documents):
        agents = {}
        for agent in dict.fromkeys(agent_label(s) for s in outcome.documents if s.task == task):
            specs = [s for s in outcome.documents if s.task == task and agent_label(s) == agent]
            entry = agent_entry([outcome.documents[s] for s in specs])
            if all(s in outcome.modes for s in specs):
                modes = [outcome.modes[s] for s in specs]
                entry["mode"] = {**agent_entry(modes), "deployed": deployed_forms(modes)}
            agents[agent] = entry
        first = next(s for s in outcome.documents if s.task == task)
        tasks[task] = {"about": TRAFFIC_TASKS.get(task, ""),
                       "thresholds": dict(outcome.documents[first]["thresholds"]),
                       "agents": agents,
                       "teacher": {action: teacher_entry(document) for (name, action), document
                                   in (teachers or {}).items() if name == task}}
    return {"title": f"Lane keeping with traffic ({settings.obs})",
            "settings": settings_dict(settings), **invocation(outcome), "tasks": tasks}


def run_cells(entry: Mapping[str, Any], thresholds: Mapping[str, float]) -> list[dict[str, str]]:
    """Per run of an agent's entry: its seed, each constraint's metric with its 95 % interval
    and by how much it misses, J_R, the community's medians, collisions by kind and the final
    multipliers, as table cells."""
    intervals = entry.get("intervals", {})
    rows = []
    for index, run in enumerate(entry["runs"]):
        match = SEED_OF_RUN.search(run)
        if match is None:
            raise ValueError(f"run directory {run!r} does not end in -seed<N>")
        cells = {"seed": match.group(1)}
        for c in entry["constraints"]:
            metric, bound = c["metric"], thresholds[c["name"]]
            value = entry[metric]["values"][index]
            text = f"{value:.3f}"
            if metric in intervals:
                low, high = intervals[metric][index]
                text += f" ({low:.3f}–{high:.3f})"
            text += " ✓" if value <= bound else f" ✗ +{value - bound:.3f}"
            cells[metric] = text
        cells["J_R"] = f"{entry['J_R']['values'][index]:.2f}"
        community = entry["community"][index] or {}
        for metric in METRICS:
            value = community.get(metric)
            digits = FORMATS[metric][2]
            cells[metric] = "—" if value is None else f"{value['median']:.{digits}f}"
        kinds = community.get("collisions_by_kind") or {}
        cells["collisions"] = ", ".join(f"{kind} {count}" for kind, count in kinds.items()) \
            or "none"
        cells["multipliers"] = ", ".join(f"{name} {value:.2f}" for name, value
                                         in entry["multipliers"][index].items())
        rows.append(cells)
    return rows


def agents_of(document: Mapping[str, Any]) -> dict[str, None]:
    """The learning agents of every task of a traffic document, in order."""
    return dict.fromkeys(agent for block in document["tasks"].values()
                         for agent in block["agents"])


def traffic_markdown(document: Mapping[str, Any]) -> str:
    """The experiment's Markdown from its JSON document: per task, a row per agent, seed and
    policy."""
    settings = document["settings"]
    lines = [f"# {document['title']}", "",
             "CRLLK-D (multipliers learned by dual ascent), PPO-D (the same costs at fixed "
             "weights), both with the paper's three discrete actions, none of which stops, and "
             "CRLLK-C-stoppable (continuous actions that can stand still) from the robot's "
             "camera on "
             "tasks with moving agents. Each row is one "
             "training run's test evaluation: every constraint's metric with its 95 % "
             "interval (✓ within its threshold, ✗ with the excess), J_R (m), then the "
             "Duckietown community's medians over the episodes (survival time, distance along "
             "the lane in tiles, lateral deviation from the lane centre, time outside the "
             "lane), what the episodes that ended on a collision hit, and the multipliers "
             "(CRLLK: learned, at the end of training; PPO-D: the fixed weights). The teacher "
             "rows are the scripted lane follower that follows the traffic (the imitation "
             "term's teacher), answering in each action type, through the same episodes.", "",
             f"- Observation: `{settings['obs']}`; budget {settings['frames']:,} frames per run; "
             f"{settings['episodes']} test episodes per run from spawn seed "
             f"{settings['eval_seed']} (the test seed); training seeds "
             f"{seeds_text(settings, list(agents_of(document)))}.",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.", ""]
    for task, block in document["tasks"].items():
        thresholds = block["thresholds"]
        agents = block["agents"]
        constraints = next(iter(agents.values()))["constraints"]
        bounds = ", ".join(f"{c['metric']} ≤ {thresholds[c['name']]:g} {c['unit']}"
                           for c in constraints)
        header = ["agent", "policy", "seed", *(c["metric"] for c in constraints), "J_R",
                  *(f"{label} ({unit})" for label, unit, _ in FORMATS.values()),
                  "collisions", "multipliers"]
        lines += [f"## {task}", "", f"{block['about']}. Constraints: {bounds}.", "",
                  "| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
        for agent, entry in agents.items():
            policies = [("sampled", entry)] + (
                [(_deployed_short(entry["mode"]), entry["mode"])] if "mode" in entry else [])
            for label, source in policies:
                for cells in run_cells(source, thresholds):
                    values = [cells["seed"], *(cells[c["metric"]] for c in constraints),
                              cells["J_R"], *(cells[m] for m in METRICS), cells["collisions"],
                              cells["multipliers"]]
                    lines.append(f"| {agent} | {label} | " + " | ".join(values) + " |")
        for action, entry in block.get("teacher", {}).items():
            cells = run_cells(entry, thresholds)[0]
            values = [*(cells[c["metric"]] for c in constraints), cells["J_R"],
                      *(cells[m] for m in METRICS), cells["collisions"]]
            lines.append(f"| teacher | {action} | — | " + " | ".join(values) + " | — |")
        lines.append("")
    return "\n".join(lines)


__all__ = ["STOPPABLE", "TEACHER_ACTIONS", "TRAFFIC_AGENTS", "TRAFFIC_TASKS", "agent_entry",
           "agent_label", "run_cells",
           "teacher_entry", "traffic", "traffic_document", "traffic_markdown", "traffic_specs"]


def _deployed_short(entry: Mapping[str, Any]) -> str:
    """The policy column's name for a deployed policy: ``mode``, or ``expected duties`` or
    ``expected action`` where its evaluations played those."""
    forms = entry.get("deployed", ())
    return next((EXPECTED_FORMS[f] for f in EXPECTED_FORMS if f in forms), "mode")
