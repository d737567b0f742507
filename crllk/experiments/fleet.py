"""The fleet experiment: every Duckiebot of ``traffic_loop`` driven by the learned policy.

``python -m crllk.experiments fleet`` takes the traffic experiment's runs on ``traffic_loop``
(trained if missing) and evaluates each on the test seed twice: alone among the scripted
traffic (its test evaluation, ``test.json``) and as one of :data:`FLEET_ROBOTS` robots that
all drive with its policy (:mod:`crllk.evaluation.fleet`, ``test-fleet.json``), with as many
robot-episodes as the test evaluation has episodes. It writes ``fleet.json`` and ``fleet.md``
into ``<results>/<obs>/``: per agent and seed, both evaluations side by side, every constraint
judged per robot-episode, and what each robot's collisions hit.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from joblib import Parallel, delayed

from crllk.errors import ConfigError
from crllk.evaluation.community import FORMATS, METRICS
from crllk.evaluation.report import format_summary
from crllk.experiments.runs import (
    RunSpec,
    Settings,
    agent_seeds,
    train_and_evaluate,
    trained_frames,
)
from crllk.experiments.tables import (
    invocation,
    invocation_note,
    seeds_text,
    settings_dict,
    write_documents,
)
from crllk.experiments.traffic import agent_entry, run_cells

FLEET_TASK = "traffic_loop"
"""The map the fleet drives: the traffic task, so the policies have seen other robots."""
FLEET_AGENTS = ("CRLLK-D", "PPO-D")
"""Learned multipliers against fixed weights, from the traffic experiment."""
FLEET_ROBOTS = 4
"""Robots of the fleet: the traffic task's two vehicles and the robot, and one more."""
FLEET_EVALUATION = "test-fleet"
"""The fleet evaluation's file in each run directory (``test-fleet.json``)."""


def fleet_specs(settings: Settings) -> list[RunSpec]:
    """The runs of :data:`FLEET_AGENTS` that ``--agents`` keeps, with their seeds."""
    return [RunSpec(agent, FLEET_TASK, seed) for agent in FLEET_AGENTS
            if agent in settings.agents for seed in agent_seeds(settings, agent)]


def fleet_episodes(settings: Settings) -> int:
    """Fleet episodes per run: as many robot-episodes as a test evaluation's episodes."""
    return max(1, settings.episodes // FLEET_ROBOTS)


def fleet_is_current(run_dir: Path, settings: Settings) -> bool:
    """Whether ``test-fleet.json`` evaluated the run's last policy with these settings."""
    path = run_dir / f"{FLEET_EVALUATION}.json"
    if not path.is_file():
        return False
    document = json.loads(path.read_text())
    evaluation = document.get("evaluation", {})
    return (document.get("source", {}).get("frames") == trained_frames(run_dir)
            and evaluation.get("fleet_episodes") == fleet_episodes(settings)
            and evaluation.get("robots") == FLEET_ROBOTS
            and evaluation.get("seed") == settings.eval_seed
            and evaluation.get("deterministic") is False)


def _evaluate_fleet(run_dir: Path, episodes: int, seed: int) -> None:
    import torch

    from crllk.evaluation.fleet import evaluate_fleet

    torch.set_num_threads(1)
    print(format_summary(evaluate_fleet(run_dir, robots=FLEET_ROBOTS, episodes=episodes,
                                       seed=seed, name=FLEET_EVALUATION)), flush=True)


def fleet(settings: Settings) -> list[Path]:
    """Trains what is missing, makes the test and fleet evaluations not yet made, writes
    ``fleet.json`` and ``fleet.md``."""
    started = time.perf_counter()
    specs = fleet_specs(settings)
    if not specs:
        raise ConfigError("experiments", "--agents",
                          f"fleet drives {' or '.join(FLEET_AGENTS)}, got {list(settings.agents)}")
    outcome = train_and_evaluate(specs, settings)
    root = settings.runs_root
    missing = [s for s in specs if not fleet_is_current(s.directory(root), settings)]
    print(f"fleet evaluation of {len(missing)} of {len(specs)} runs", flush=True)
    Parallel(n_jobs=settings.jobs)(
        delayed(_evaluate_fleet)(s.directory(root), fleet_episodes(settings), settings.eval_seed)
        for s in missing)
    fleets = {s: json.loads((s.directory(root) / f"{FLEET_EVALUATION}.json").read_text())
              for s in specs}
    agents = {}
    for agent in dict.fromkeys(s.agent for s in specs):
        chosen = [s for s in specs if s.agent == agent]
        agents[agent] = {"alone": agent_entry([outcome.documents[s] for s in chosen]),
                         "fleet": agent_entry([fleets[s] for s in chosen])}
    first = outcome.documents[specs[0]]
    document = {"title": f"Every robot driven by the policy ({settings.obs})",
                "settings": {**settings_dict(settings), "robots": FLEET_ROBOTS,
                             "fleet_episodes": fleet_episodes(settings)},
                **invocation(outcome), "wall_s": time.perf_counter() - started,
                "evaluations_made": outcome.evaluated + len(missing),
                "task": FLEET_TASK, "thresholds": dict(first["thresholds"]), "agents": agents}
    return write_documents(settings, "fleet", document, fleet_markdown(document))


def fleet_markdown(document: Mapping[str, Any]) -> str:
    """The experiment's Markdown from its JSON document: per agent and seed, the run alone
    among the scripted traffic and in the fleet."""
    settings, thresholds = document["settings"], document["thresholds"]
    agents = document["agents"]
    constraints = next(iter(agents.values()))["alone"]["constraints"]
    robots = settings["robots"]
    lines = [f"# {document['title']}", "",
             f"Each run of the traffic experiment on `{document['task']}` evaluated twice on the "
             "test seed with its sampled policy: **alone**, the robot among the scripted "
             f"traffic (its test evaluation), and in a **fleet** of {robots} robots that every "
             "one drive with the run's policy from their own observations, where each robot's "
             "episode is one row (every constraint judged per robot). Each row: every "
             "constraint's metric with its 95 % interval (✓ within its threshold, ✗ with the "
             "excess), J_R (m), the Duckietown community's medians, and what the collisions "
             "hit (in the fleet, `vehicle` is another robot: a collision between two robots "
             "ends both robots' episodes and counts in both).",
             "",
             f"- Observation: `{settings['obs']}`; alone: {settings['episodes']} test episodes "
             f"per run; fleet: {settings['fleet_episodes']} fleet episodes of {robots} robots "
             f"({settings['fleet_episodes'] * robots} robot-episodes) per run, from spawn seed "
             f"{settings['eval_seed']} (the test seed); training seeds "
             f"{seeds_text(settings, list(agents))}.",
             f"- Command: `{settings['command']}` ({invocation_note(document)}).",
             f"- Machine: {settings['machine']}.", ""]
    header = ["agent", "evaluation", "seed", *(c["metric"] for c in constraints), "J_R",
              *(f"{label} ({unit})" for label, unit, _ in FORMATS.values()), "collisions"]
    lines += ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for agent, block in agents.items():
        for label in ("alone", "fleet"):
            for cells in run_cells(block[label], thresholds):
                values = [cells["seed"], *(cells[c["metric"]] for c in constraints),
                          cells["J_R"], *(cells[m] for m in METRICS), cells["collisions"]]
                lines.append(f"| {agent} | {label} | " + " | ".join(values) + " |")
    lines.append("")
    return "\n".join(lines)


__all__ = ["FLEET_AGENTS", "FLEET_EVALUATION", "FLEET_ROBOTS", "FLEET_TASK", "fleet",
           "fleet_episodes", "fleet_markdown", "fleet_specs"]
