"""The paper's experiments, trained and evaluated from one command each.

    python -m crllk.experiments table1    # CRLLK-D, PPO-D, CRLLK-C, PPO-C on small_loop
    python -m crllk.experiments maps      # the same four agents on zigzag and obstacle_loop
    python -m crllk.experiments figure1   # CRLLK-D on small_loop, alpha_1 = 0.08 ... 0.5 dm
    python -m crllk.experiments sweep     # fixed-weight PPO-D over a grid of weights, every map
    python -m crllk.experiments robustness  # CRLLK-D with and without randomisation, held out
    python -m crllk.experiments teacher   # CRLLK-D with the teacher's floor, annealed, none
    python -m crllk.experiments aids      # CRLLK-D without encounter spawns, pixel critics
    python -m crllk.experiments realmaps  # CRLLK-D on two real Duckietown maps nobody tuned on
    python -m crllk.experiments peers --obs state  # crllk's learners beside OmniSafe's
    python -m crllk.experiments traffic   # CRLLK-D, PPO-D, CRLLK-C with vehicles and pedestrians
    python -m crllk.experiments fleet     # every robot of traffic_loop driven by the policy
    python -m crllk.experiments all       # table1, maps and figure1

Every experiment trains its runs as trainer multiruns (``python -m crllk.train -m
task=... seed=... resume=true``, one sweep per agent and setting, Hydra's joblib launcher running
``--jobs`` at a time, one per core; output in ``<runs-root>/sweeps.log``), so an interrupted
experiment picks up where its runs stopped and finished runs are not trained again. The runs
train with the trainer's validation evaluations (``eval.csv``, ``eval.json``: spawn seed
1,000,000); each finished run is then evaluated once on the **test seed**
(:mod:`crllk.protocol`, 400 episodes by default: ``test.json`` for the sampled policy,
``test-mode.json`` for the deployed one (a discrete run's expected duties, a continuous run's
expected action), where the policy is there;
:func:`crllk.evaluation.runs.evaluate_run`, as ``python -m crllk.evaluate``), and those test
evaluations alone make the tables, which are
written to ``results/<obs>/``: a Markdown table with the paper's numbers beside ours and the
JSON behind it, or the figures, and ``seeds.md``, every seed of the tables' runs side by side
(:mod:`crllk.experiments.seeds`). Runs live in ``results/runs/<obs>/<task>/`` and are kept in
the repository without their checkpoints but with their policy (configuration, logs,
``eval.json``, ``policy.pt``), so a finished run is reused by a later invocation, and can be
evaluated again and exported, where its checkpoints are gone.
"""

from __future__ import annotations

import json
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from crllk.cli import Parser
from crllk.config import validate
from crllk.errors import ConfigError
from crllk.evaluation.robustness import conditions
from crllk.experiments.aids import aids
from crllk.experiments.figure1 import figure1_markdown
from crllk.experiments.fleet import fleet
from crllk.experiments.peers import peers
from crllk.experiments.realmaps import realmaps
from crllk.experiments.robustness import robustness
from crllk.experiments.runs import (
    AGENTS,
    FIGURE_THRESHOLDS,
    MAP_TASKS,
    PAPER_TABLE1,
    PIXEL_FRAMES,
    SOURCE,
    STATE_FRAMES,
    SWEEP_COLLISION_WEIGHTS,
    SWEEP_LANE_WEIGHTS,
    SWEEP_TASKS,
    RunSpec,
    Settings,
    agent_seeds,
    train_and_evaluate,
)
from crllk.experiments.sweep import sweep, sweep_markdown, sweep_specs
from crllk.experiments.tables import settings_dict, table_markdown, write_table
from crllk.experiments.teacher import teacher
from crllk.experiments.traffic import traffic
from crllk.files import atomic_write_text, write_problem
from crllk.training.compose import compose_config

__all__ = ["AGENTS", "ALL", "EXPERIMENTS", "PAPER_TABLE1", "check_settings", "figure1", "main",
           "maps", "sweep", "sweep_markdown", "sweep_specs", "table1", "table_markdown"]


def table1(settings: Settings) -> Path:
    agents = list(settings.agents)
    specs = [RunSpec(agent, "small_loop", seed) for agent in agents
             for seed in agent_seeds(settings, agent)]
    outcome = train_and_evaluate(specs, settings)
    return write_table("table1", "Table 1: small_loop", "small_loop", agents, outcome,
                       settings, PAPER_TABLE1, _pairs(agents))


def maps(settings: Settings) -> list[Path]:
    agents = list(settings.agents)
    specs = [RunSpec(agent, task, seed) for task in MAP_TASKS for agent in agents
             for seed in agent_seeds(settings, agent)]
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
             for threshold in settings.figure_thresholds for seed in settings.seeds]
    train_and_evaluate(specs, settings)
    by_threshold = {t: [s.directory(settings.runs_root) for s in specs if s.lane_threshold == t]
                    for t in settings.figure_thresholds}
    sweep_path = settings.results / "sweep.json"
    sweep_document = json.loads(sweep_path.read_text()) if sweep_path.is_file() else None
    paths = figure1_pictures(by_threshold, settings.results, settings_dict(settings),
                             sweep_document)
    data = json.loads((settings.results / "figure1.json").read_text())
    words = atomic_write_text(settings.results / "figure1.md",
                              figure1_markdown(data, sweep_document))
    return [*paths, words]


EXPERIMENTS = {"table1": table1, "maps": maps, "figure1": figure1, "sweep": sweep,
               "robustness": robustness, "teacher": teacher, "aids": aids,
               "realmaps": realmaps, "peers": peers, "traffic": traffic, "fleet": fleet}
ALL = ("table1", "maps", "figure1")
"""What ``all`` runs (the sweep is asked for by name)."""


def check_settings(settings: Settings) -> None:
    """Checks, before any run starts, that every agent's trainer configuration composes with
    the ``--set`` overrides and that the runs and results folders can be written.

    Raises:
        ConfigError: naming the override or the folder.
    """
    for agent in settings.agents:
        seed = min(agent_seeds(settings, agent))
        overrides = [f"agent={agent}", f"obs={settings.obs}", f"seed={seed}",
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
    parser.add_argument("--seeds", type=int, nargs="+", default=None,
                        help=f"training seeds of every run (default: "
                             f"{' '.join(map(str, Settings.seeds))}, and "
                             f"{' '.join(map(str, Settings.crllk_seeds))} for the CRLLK agents "
                             f"of table1, maps and traffic)")
    parser.add_argument("--crllk-seeds", type=int, nargs="+", default=None,
                        help="table1, maps and traffic: the CRLLK agents' training seeds (default: "
                             "--seeds where given)")
    parser.add_argument("--agents", nargs="+", choices=list(AGENTS), default=list(AGENTS),
                        help="table1, maps, traffic and fleet: the agents to train and tabulate")
    parser.add_argument("--episodes", type=int, default=Settings.episodes,
                        help="test episodes per run (on the test seed)")
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
    parser.add_argument("--thresholds", type=float, nargs="+",
                        default=list(FIGURE_THRESHOLDS),
                        help="figure1: the alpha_1 values (dm) of the CRLLK-D runs")
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
    if not all(0 < t < float("inf") for t in args.thresholds):
        parser.error(f"--thresholds must be finite numbers above 0, got {args.thresholds}")
    command = "python -m crllk.experiments " + shlex.join(sys.argv[1:] if argv is None else argv)
    seeds = tuple(args.seeds or Settings.seeds)
    crllk_seeds = tuple(args.crllk_seeds or args.seeds or Settings.crllk_seeds)
    settings = Settings(frames=args.frames, seeds=seeds, crllk_seeds=crllk_seeds,
                        episodes=args.episodes,
                        obs=args.obs, jobs=args.jobs, runs_root=args.runs_root / args.obs,
                        results=args.results / args.obs, command=command,
                        train_overrides=tuple(args.set), agents=tuple(args.agents),
                        sweep_tasks=tuple(args.sweep_tasks),
                        lane_weights=tuple(args.lane_weights),
                        collision_weights=tuple(args.collision_weights),
                        robust_tasks=tuple(args.robust_tasks),
                        figure_thresholds=tuple(args.thresholds),
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

