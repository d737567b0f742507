"""How a run's episodes end: the last seconds before each one that leaves the road or collides.

    python -m crllk.analysis.endings RUN_DIR [--episodes 100] [--seconds 2] [--deterministic]

An evaluation counts how often a policy leaves the road; this command shows how. It plays
``episodes`` episodes of the run's policy (sampled, or its deployed policy with
``--deterministic``, :func:`crllk.training.runs.played_action`) from
the validation spawn seed, never the test seed (episode k in simulation k mod N, each
simulation's first episodes, as an evaluation assigns them), keeps the last ``seconds`` of
every episode that ends off the road or on a collision, and reports for each: where it ended
(tile and its kind), how far right of its lane centre the robot drove on average over that
window and at its end (m; negative: left), its heading error, how hard it turned (the wheel
duties' difference, right minus left: positive turns left) and how often that turn swung from
one side to the other (weaving), and how far the nearest mover was at the end (None without
movers). The result goes to ``<run>/endings.json`` (``endings-mode.json``).
"""

from __future__ import annotations

import json
import math
import statistics
import sys
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from itertools import pairwise
from pathlib import Path
from typing import Any

from crllk.cli import Parser, positive_int, run
from crllk.errors import ConfigError
from crllk.files import atomic_write_text

SOURCE = "endings"
SIMULATIONS = 8
"""Simulations stepped side by side while the episodes are played."""
SWING = 0.2
"""A turn (right minus left wheel duty) counts in a swing only beyond this magnitude."""


@dataclass(frozen=True)
class Step:
    """What the window keeps of one control step."""

    lateral: float
    """Offset from the lane centre (m), positive right."""
    heading_error: float
    """Yaw minus lane heading (rad)."""
    turn: float
    """Right minus left wheel duty of the step's action (positive: turning left)."""
    mover_distance: float
    """Distance (m) from the robot's axle to the nearest mover's centre (inf: none)."""


@dataclass(frozen=True)
class Ending:
    """The last steps of one episode that ended off the road or on a collision."""

    termination: str
    tile: tuple[int, int]
    tile_kind: str
    steps: int
    mean_lateral: float
    final_lateral: float
    heading_error_deg: tuple[float, float]
    mean_abs_turn: float
    swings: int
    """Sign changes of the turn among the window's steps that turn beyond :data:`SWING`."""
    mover_distance: float | None
    """None without movers."""


def swings(turns: Sequence[float], threshold: float = SWING) -> int:
    """How often ``turns`` change side, counting only turns beyond ``threshold``."""
    sides = [math.copysign(1.0, t) for t in turns if abs(t) > threshold]
    return sum(1 for a, b in pairwise(sides) if a != b)


def ending(termination: str, tile: tuple[int, int], tile_kind: str,
           window: Sequence[Step]) -> Ending:
    """The :class:`Ending` of an episode whose last steps are ``window``."""
    headings = [math.degrees(s.heading_error) for s in window]
    nearest = window[-1].mover_distance
    return Ending(termination, tile, tile_kind, len(window),
                  statistics.fmean(s.lateral for s in window), window[-1].lateral,
                  (min(headings), max(headings)), statistics.fmean(abs(s.turn) for s in window),
                  swings([s.turn for s in window]), nearest if math.isfinite(nearest) else None)


def summary(endings: Sequence[Ending], episodes: int) -> dict[str, Any]:
    """Counts by termination and tile kind, and the medians of the windows' figures."""
    def median(values: list[float]) -> float | None:
        return statistics.median(values) if values else None

    return {"episodes": episodes, "endings": len(endings),
            "by_termination": dict(Counter(e.termination for e in endings)),
            "by_tile_kind": dict(Counter(e.tile_kind for e in endings)),
            "by_tile": {f"{c},{r}": n for (c, r), n in
                        Counter(e.tile for e in endings).most_common()},
            "median_mean_lateral": median([e.mean_lateral for e in endings]),
            "median_mean_abs_turn": median([e.mean_abs_turn for e in endings]),
            "median_swings": median([float(e.swings) for e in endings])}


def play_endings(run_dir: Path, episodes: int, seconds: float,
                 deterministic: bool) -> dict[str, Any]:
    """Plays the episodes and returns the document :func:`main` writes."""
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from crllk.envs.batched import TERMINATIONS
    from crllk.evaluation.runs import evaluation_config
    from crllk.protocol import VALIDATION_SEED
    from crllk.rl.rollout import Rollout, episode_quotas
    from crllk.tasks.actions import action_duty
    from crllk.training.build import build_env
    from crllk.training.runs import load_actor, played_action

    config = evaluation_config(run_dir)
    env = build_env(config, num_envs=min(SIMULATIONS, episodes), seed=VALIDATION_SEED,
                    action=played_action(config, deterministic))
    quotas = episode_quotas(episodes, env.num_envs).tolist()
    try:
        actor, _ = load_actor(run_dir, env, deployed=deterministic)
        length = max(1, round(seconds / env.config.control_timestep))
        windows = [deque(maxlen=length) for _ in range(env.num_envs)]
        found: list[Ending] = []
        finished = 0

        def on_step(stepped) -> None:
            nonlocal finished
            for i, (task, physics) in enumerate(zip(env.tasks, env.physics, strict=True)):
                if quotas[i] == 0:  # this simulation has played its share
                    continue
                x, y, yaw = physics.pose()
                pose = task.map.lane_pose(x, y, yaw)
                left, right = action_duty(env.action_type, stepped["action"][i].tolist())
                movers = task.mover_boxes
                nearest = min((math.hypot(b.x - x, b.y - y) for b in movers), default=math.inf)
                windows[i].append(Step(pose.lateral, pose.heading_error, right - left, nearest))
                if not bool(stepped["next", "done"][i]):
                    continue
                finished += 1
                quotas[i] -= 1
                termination = TERMINATIONS[int(stepped["next", "termination"][i])]
                if termination in ("off_road", "collision"):
                    tile = (pose.lane.column, pose.lane.row)
                    kind = task.map.tile(*tile).kind
                    found.append(ending(termination, tile, kind, list(windows[i])))
                windows[i].clear()

        rollout = Rollout(env, actor)
        exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
        with torch.random.fork_rng(), torch.no_grad(), set_exploration_type(exploration):
            torch.manual_seed(VALIDATION_SEED)
            while finished < episodes:
                rollout.step(on_step)
    finally:
        env.close()
    return {"run": str(run_dir), "task": config.task_name, "seed": VALIDATION_SEED,
            "deterministic": deterministic, "seconds": length * env.config.control_timestep,
            "summary": summary(found, episodes), "endings": [asdict(e) for e in found]}


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="python -m crllk.analysis.endings", description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--deterministic", action="store_true",
                        help="play the deployed policy (discrete: expected duties; "
                        "continuous: the expected action)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if not args.run_dir.is_dir():
        raise ConfigError(SOURCE, "run", f"no such run directory: {args.run_dir}")
    if not (math.isfinite(args.seconds) and args.seconds > 0):
        raise ConfigError(SOURCE, "--seconds", f"must be a positive number, got {args.seconds}")
    document = play_endings(args.run_dir, args.episodes, args.seconds, args.deterministic)
    out = args.run_dir / ("endings-mode.json" if args.deterministic else "endings.json")
    atomic_write_text(out, json.dumps(document, indent=1) + "\n")
    s = document["summary"]
    print(f"{out}: {s['endings']} of {s['episodes']} episodes ended off the road or on a "
          f"collision {s['by_termination']}; by tile kind {s['by_tile_kind']}")
    return 0


if __name__ == "__main__":
    run(main)
