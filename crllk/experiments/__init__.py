"""The paper's experiments, trained and evaluated from one command each.

    python -m crllk.experiments table1    # CRLLK-D, PPO-D, CRLLK-C, PPO-C on small_loop
    python -m crllk.experiments maps      # the same four agents on zigzag and obstacle_loop
    python -m crllk.experiments figure1   # CRLLK-D on small_loop with alpha_1 = 0.5 and 0.75
    python -m crllk.experiments sweep     # fixed-weight PPO-D over a grid of weights, every map
    python -m crllk.experiments robustness  # CRLLK-D with and without randomisation, held out
    python -m crllk.experiments all       # table1, maps and figure1

Every experiment trains its runs as trainer multiruns (``python -m crllk.train -m
task=... seed=... resume=true``, one sweep per agent and setting, Hydra's joblib launcher running
``--jobs`` at a time, one per core; output in ``<runs-root>/sweeps.log``), so an interrupted
experiment picks up where its runs stopped and finished runs are not trained again. Each run is
then evaluated (:func:`crllk.evaluation.runs.evaluate_run`, as ``python -m crllk.evaluate``; an
``eval.json`` of the same policy and settings is reused, as the one the trainer writes from its
final evaluation, which the runs make with the experiment's episodes and seed; so is the policy
it deploys, its mode, into ``eval-mode.json``, where the policy is there) and the results are
written to ``results/<obs>/``: a Markdown table with the paper's numbers beside ours and the
JSON behind it, or the figures, and ``seeds.md``, every seed of the tables' runs side by side
(:mod:`crllk.experiments.seeds`). Runs live in ``results/runs/<obs>/<task>/`` and are kept in
the repository without their checkpoints but with their policy (configuration, logs,
``eval.json``, ``policy.pt``), so a finished run is reused by a later invocation, and can be
evaluated again and exported, where its checkpoints are gone.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from crllk.cli import Parser
from crllk.errors import ConfigError
from crllk.evaluation.report import PAPER_CONSTRAINTS, aggregate
from crllk.evaluation.robustness import conditions
from crllk.evaluation.runs import evaluate_follower
from crllk.experiments.robustness import robustness
from crllk.experiments.runs import (
    AGENTS,
    FIGURE_THRESHOLDS,
    MAP_TASKS,
    PAPER_J_R_PER_METRE,
    PAPER_TABLE1,
    PIXEL_FRAMES,
    SOURCE,
    STATE_FRAMES,
    SWEEP_COLLISION_WEIGHTS,
    SWEEP_LANE_WEIGHTS,
    SWEEP_TASKS,
    THRESHOLDS,
    Outcome,
    RunSpec,
    Settings,
    train_and_evaluate,
)
from crllk.experiments.seeds import write_seeds
from crllk.files import atomic_write_text, write_problem
from crllk.training.compose import compose_config
from crllk.training.config import validate


# ----- tables -------------------------------------------------------------------------------
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
                summary["mode"] = aggregate([outcome.modes[s] for s in specs])
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
        name = f"{agent}'s deployed policy (mode)" if mode else agent
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
    if with_mode:
        for metric, digits in (*((c["metric"], 3) for c in _constraints(results)), ("J_R", 2)):
            cells = [_cell(results[a]["mode"][metric], digits) if "mode" in results[a] else "—"
                     for a in agents]
            rows.append(f"| {metric}, deployed policy (mode) | " + " | ".join(cells) + " | |")
    minutes = [s / 60 for a in agents for s in results[a]["train_seconds"]]
    obs = settings["obs"]
    lines = [
        f"# {document['title']}", "",
        f"Map `{document['task']}`, α1 = {thresholds['lane']} dm, α2 = "
        f"{thresholds['collision']} collisions per episode. Mean ± std (population, ddof 0) "
        f"across training seeds {', '.join(map(str, settings['seeds']))}.", "",
        f"- Observation: `{obs}`" + (" (lane-relative features, not the camera)"
                                     if obs == "state" else " (the 30×40 camera image)") + ".",
        f"- Budget: {settings['frames']:,} environment frames per run (training wall time "
        f"{min(minutes):.1f}–{max(minutes):.1f} min per run, "
        + ("one run at a time)." if settings["jobs"] == 1
           else f"{settings['jobs']} runs at a time)."),
        f"- Evaluation: {settings['episodes']} episodes per run of the sampled policy (the one "
        f"the constraints are learned for), spawn and sampling seed {settings['eval_seed']} "
        "(never a training seed), the last checkpoint" + (
            "; the rows marked *deployed policy (mode)* play the same episodes with the most "
            "probable action, the policy `crllk.export` writes for the robot." if with_mode
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
                "settings": _settings_dict(settings), **invocation(outcome),
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


def _settings_dict(settings: Settings) -> dict[str, Any]:
    return {"frames": settings.frames, "seeds": list(settings.seeds),
            "train_overrides": list(settings.train_overrides),
            "episodes": settings.episodes, "obs": settings.obs, "eval_seed": settings.eval_seed,
            "jobs": settings.jobs, "command": settings.command, "machine": machine_text()}


# ----- experiments --------------------------------------------------------------------------
def table1(settings: Settings) -> Path:
    agents = list(settings.agents)
    specs = [RunSpec(agent, "small_loop", seed) for agent in agents for seed in settings.seeds]
    outcome = train_and_evaluate(specs, settings)
    return write_table("table1", "Table 1: small_loop", "small_loop", agents, outcome,
                       settings, PAPER_TABLE1, _pairs(agents))


def maps(settings: Settings) -> list[Path]:
    agents = list(settings.agents)
    specs = [RunSpec(agent, task, seed) for task in MAP_TASKS for agent in agents
             for seed in settings.seeds]
    outcome = train_and_evaluate(specs, settings)
    return [write_table(f"table_{task}", f"CRLLK vs PPO: {task}", task, agents, outcome,
                        settings, None, _pairs(agents))
            for task in MAP_TASKS]


def _pairs(agents: Sequence[str]) -> list[tuple[str, str]]:
    """The (CRLLK, PPO) pairs of the same action type among ``agents``."""
    return [pair for pair in (("CRLLK-D", "PPO-D"), ("CRLLK-C", "PPO-C"))
            if pair[0] in agents and pair[1] in agents]


def figure1(settings: Settings) -> list[Path]:
    from crllk.analysis.figures import figure1_pictures  # matplotlib only when drawing

    specs = [RunSpec("CRLLK-D", "small_loop", seed, threshold)
             for threshold in FIGURE_THRESHOLDS for seed in settings.seeds]
    train_and_evaluate(specs, settings)
    by_threshold = {t: [s.directory(settings.runs_root) for s in specs if s.lane_threshold == t]
                    for t in FIGURE_THRESHOLDS}
    return figure1_pictures(by_threshold, settings.results, _settings_dict(settings))


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
            "settings": _settings_dict(settings), **invocation(outcome), "maps": maps}


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


EXPERIMENTS = {"table1": table1, "maps": maps, "figure1": figure1, "sweep": sweep,
               "robustness": robustness}
ALL = ("table1", "maps", "figure1")
"""What ``all`` runs (the sweep is asked for by name)."""


def check_settings(settings: Settings) -> None:
    """Checks, before any run starts, that every agent's trainer configuration composes with
    the ``--set`` overrides and that the runs and results folders can be written.

    Raises:
        ConfigError: naming the override or the folder.
    """
    for agent in settings.agents:
        overrides = [f"agent={agent}", f"obs={settings.obs}", f"seed={min(settings.seeds)}",
                     f"total_frames={settings.frames}", *settings.train_overrides]
        validate(compose_config(overrides))
    for option, folder in (("--runs-root", settings.runs_root), ("--results", settings.results)):
        problem = write_problem(folder / "probe")
        if problem:
            raise ConfigError(SOURCE, option, problem)


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="python -m crllk.experiments", description=__doc__.splitlines()[0])
    parser.add_argument("experiment", choices=[*EXPERIMENTS, "all"])
    parser.add_argument("--frames", type=int, default=None,
                        help=f"environment frames per training run (pixels: {PIXEL_FRAMES:,}, "
                             f"state: {STATE_FRAMES:,}, the trainer's defaults)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(Settings.seeds))
    parser.add_argument("--agents", nargs="+", choices=list(AGENTS), default=list(AGENTS),
                        help="table1 and maps: the agents to train and tabulate")
    parser.add_argument("--episodes", type=int, default=Settings.episodes,
                        help="evaluation episodes per run")
    parser.add_argument("--obs", choices=("state", "pixels"), default=Settings.obs)
    parser.add_argument("--jobs", type=int, default=Settings.jobs, help="runs at a time")
    parser.add_argument("--runs-root", type=Path, default=Settings.runs_root,
                        help="runs go to <runs-root>/<obs>/<task>/<agent>-a<alpha_1>-seed<seed>")
    parser.add_argument("--results", type=Path, default=Settings.results,
                        help="tables and figures go to <results>/<obs>/")
    parser.add_argument("--sweep-tasks", nargs="+", default=list(SWEEP_TASKS),
                        help="sweep: the maps")
    parser.add_argument("--lane-weights", type=float, nargs="+",
                        default=list(SWEEP_LANE_WEIGHTS), help="sweep: fixed lambda_lane values")
    parser.add_argument("--collision-weights", type=float, nargs="+",
                        default=list(SWEEP_COLLISION_WEIGHTS),
                        help="sweep: fixed lambda_coll values")
    parser.add_argument("--robust-tasks", nargs="+", default=list(Settings.robust_tasks),
                        help="robustness: the maps")
    parser.add_argument("--conditions", nargs="+", default=[], choices=list(conditions()),
                        help="robustness: the conditions (default: all)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="extra trainer overrides for every run, e.g. ppo.epochs=5")
    args = parser.parse_args(argv)
    if args.frames is None:
        args.frames = PIXEL_FRAMES if args.obs == "pixels" else STATE_FRAMES
    for name in ("frames", "episodes", "jobs"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be at least 1, got {getattr(args, name)}")
    command = "python -m crllk.experiments " + shlex.join(sys.argv[1:] if argv is None else argv)
    settings = Settings(frames=args.frames, seeds=tuple(args.seeds), episodes=args.episodes,
                        obs=args.obs, jobs=args.jobs, runs_root=args.runs_root / args.obs,
                        results=args.results / args.obs, command=command,
                        train_overrides=tuple(args.set), agents=tuple(args.agents),
                        sweep_tasks=tuple(args.sweep_tasks),
                        lane_weights=tuple(args.lane_weights),
                        collision_weights=tuple(args.collision_weights),
                        robust_tasks=tuple(args.robust_tasks),
                        conditions=tuple(args.conditions))
    check_settings(settings)
    names = list(ALL) if args.experiment == "all" else [args.experiment]
    try:
        for name in names:
            EXPERIMENTS[name](settings)
    except RuntimeError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    return 0

