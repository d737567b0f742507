"""Every robot on the map driven by the learned policy: a fleet evaluation.

``python -m crllk.evaluate run=RUN fleet=4`` puts four robots on the run's map, each driven by
the run's policy from its own observations (one shared policy; a pixel run's robots each read
their own camera), and writes ``<run>/fleet.json``: an evaluation document
(:func:`crllk.evaluation.report.result_document`) with one row per robot and fleet episode, so
every constraint is judged per robot, and a ``fleet`` section with each robot's own metrics and
whom each collision hit.

The fleet is N simulations of the map stepped together (:mod:`crllk.tasks.fleet`): robot i
drives in simulation i with full physics; the other robots are that simulation's mover
Duckiebots, placed before every step where their own simulations had them before it (so a
contact is seen by the robot that moved into the other; a collision between two robots ends
both robots' episodes with it). A fleet episode starts every robot at once, from the spawns of
their simulations, drawn again for a robot until its footprint is at least
:data:`FLEET_CLEARANCE` from those of the robots before it; each robot's episode ends on its
own (collision, off the road, or the horizon) and the robot then leaves the road for the
others. The next fleet episode starts when the last has ended.

A fleet needs a map whose road is free of static obstacles (as scripted traffic does), no
pedestrians, and a policy that reads the camera or was trained with traffic (a state policy
trained without movers has no inputs for them).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.config import TrainConfig
from crllk.envs.batched import TERMINATIONS, BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats
from crllk.errors import ConfigError
from crllk.evaluation.runs import (
    evaluation_config,
    policy_settings,
    result_path,
    write_evaluation,
)
from crllk.files import output_lock
from crllk.maps.obstacles import footprint_gap
from crllk.rl.import_probes import settle_import_probes
from crllk.rl.rollout import EvaluationResult, Rollout
from crllk.settings import MAX_FLEET
from crllk.tasks.constraints import Constraint
from crllk.tasks.fleet import FleetBoard, FleetTraffic
from crllk.tasks.traffic import duckiebot_box
from crllk.tasks.traffic_config import MIN_VEHICLE_DISTANCE, START_SPACING, TrafficConfig
from crllk.training.build import build_env
from crllk.training.run_dir import FLEET_FILE
from crllk.training.runs import load_actor, played_action

MAX_ROBOTS = MAX_FLEET
"""The most robots a fleet evaluation puts on a map."""
FLEET_CLEARANCE = 0.25
"""Least gap (m) between two robots' footprints when a fleet episode starts."""
SPAWN_TRIES = 100
"""Spawns drawn for one robot before the fleet gives up placing it apart from the others."""


def fleet_overrides(config: TrainConfig, robots: int) -> dict[str, Any]:
    """Task settings that give each simulation one mover Duckiebot per other robot.

    Raises:
        ConfigError: for fewer than 2 or more than :data:`MAX_ROBOTS` robots, or a task with
            pedestrians.
    """
    if not 2 <= robots <= MAX_ROBOTS:
        raise ConfigError("evaluate", "fleet", f"expected 2 to {MAX_ROBOTS} robots, got {robots}")
    traffic = config.task_overrides().get("traffic") or {}
    own = load_task_traffic(config)
    if own is not None and own.pedestrians.count:
        raise ConfigError("evaluate", "fleet", f"the task {config.task_name} has pedestrians, "
                          "which the robots' simulations cannot share")
    return {"traffic": fleet_traffic(robots, traffic)}


def fleet_traffic(robots: int, traffic: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``traffic`` task setting (``traffic``, without its vehicles) with one vehicle per
    other robot of a fleet of ``robots``: the scene's movers that :func:`join_fleet` hands to
    the other robots (their start distances are never used, but must be valid)."""
    distance = [MIN_VEHICLE_DISTANCE, MIN_VEHICLE_DISTANCE + robots * START_SPACING]
    return {**(traffic or {}), "vehicles": {"ahead": robots - 1, "opposite": 0,
                                            "distance": distance}}


def fleet_config(run_dir: str | Path, robots: int,
                 overrides: Mapping[str, Any] | None = None) -> TrainConfig:
    """The run's configuration for its evaluation in a fleet of ``robots`` robots.

    Raises:
        ConfigError: for a fleet the run's task cannot hold (see :func:`fleet_overrides`) or
            a state policy trained without traffic.
    """
    plain = evaluation_config(run_dir, overrides)
    fleet = {**(overrides or {}), **fleet_overrides(plain, robots)}
    config = evaluation_config(run_dir, fleet, workers=1)
    if config.obs.name == "state" and load_task_traffic(plain) is None:
        raise ConfigError(run_dir, "fleet", "a state policy trained without traffic has no "
                          "inputs for the other robots; evaluate a pixel run or one trained "
                          "with traffic")
    return config


def evaluate_fleet(run_dir: str | Path, *, robots: int, episodes: int,
                   deterministic: bool = False, seed: int | None = None,
                   overrides: Mapping[str, Any] | None = None,
                   name: str = FLEET_FILE) -> dict[str, Any]:
    """Plays ``episodes`` fleet episodes of ``robots`` robots driven by the run's policy and
    writes ``<run_dir>/<name>.json`` (one row per robot and episode); returns its content.

    Raises:
        ConfigError: for a fleet the run's task cannot hold (see :func:`fleet_overrides`) or
            a state policy trained without traffic.
    """
    settle_import_probes()
    config = fleet_config(run_dir, robots, overrides)
    seed = config.eval.seed if seed is None else seed
    with output_lock(result_path(run_dir, name)):
        env = build_env(config, num_envs=robots, seed=seed,
                        action=played_action(config, deterministic))
        try:
            board = join_fleet(env)
            actor, info = load_actor(run_dir, env, deployed=deterministic)
            with torch.random.fork_rng():
                torch.manual_seed(seed)
                result, hit_robots = play_fleet(env, actor, board, episodes,
                                                deterministic=deterministic)
        except ConfigError as err:  # too crowded a map: name the run
            raise ConfigError(run_dir, err.field, err.problem) from None
        finally:
            env.close()
        fleet_section = {"robots": robots,
                         "by_robot": by_robot(result.episodes, robots, result.constraints),
                         "hit_robots": hit_robots}
        return write_evaluation(
            run_dir, config, env, result, info,
            settings=policy_settings(config, deterministic, {
                "episodes": episodes * robots, "fleet_episodes": episodes, "robots": robots,
                "seed": seed}),
            overrides=overrides, name=name, extra={"fleet": fleet_section})


def load_task_traffic(config: TrainConfig) -> TrafficConfig | None:
    """The run's task's own ``traffic`` setting (None without traffic)."""
    from crllk.tasks.config import load_task_config

    return load_task_config(config.task_source(), config.task_overrides()).traffic


def join_fleet(env: BatchedLaneKeepingEnv) -> FleetBoard:
    """Makes every simulation of ``env`` one robot of a fleet: its movers become the other
    robots (:class:`FleetTraffic` on a shared board). Call before the first reset."""
    board = FleetBoard([physics.pose() for physics in env.physics], [False] * env.num_envs)
    for robot, task in enumerate(env.tasks):
        if task.traffic is None:
            raise ValueError("a fleet needs simulations with one mover per other robot")
        task.traffic = FleetTraffic(task.traffic.config, task.map, task.traffic.dt, board,
                                    robot)
    return board


def start_apart(env: BatchedLaneKeepingEnv, board: FleetBoard,
                arrange: Callable[[BatchedLaneKeepingEnv], None] | None = None
                ) -> TensorDictBase:
    """Resets every simulation, then each robot again until its footprint is at least
    :data:`FLEET_CLEARANCE` from those of the robots before it (then ``arrange``, if given,
    may move them); places every robot in the others' simulations and returns what the policy
    acts on first (every robot on the road, in every camera).

    Raises:
        ConfigError: when a robot cannot be placed apart in :data:`SPAWN_TRIES` spawns (too
            many robots for the map).
    """
    board.active = [False] * env.num_envs  # the last episode's robots are off the road
    td = env.reset()
    for robot in range(env.num_envs):
        for _ in range(SPAWN_TRIES):
            own = duckiebot_box(*env.physics[robot].pose())
            if all(footprint_gap(own, duckiebot_box(*env.physics[k].pose())) >= FLEET_CLEARANCE
                   for k in range(robot)):
                break
            mask = torch.zeros((env.num_envs, 1), dtype=torch.bool)
            mask[robot] = True
            td = env.reset(td.set("_reset", mask))
        else:
            raise ConfigError("evaluate", "fleet", f"no spawn of robot {robot} keeps "
                              f"{FLEET_CLEARANCE} m from the others in {SPAWN_TRIES} tries: "
                              "fewer robots, or a larger map")
    if arrange is not None:
        arrange(env)
    board.poses = [physics.pose() for physics in env.physics]
    board.active = [True] * env.num_envs
    for physics, task in zip(env.physics, env.tasks, strict=True):
        task.episode.traffic = task.traffic.reset(task.random, task.lane_pose.lane, 0.0)
        physics.set_mover_poses(task.traffic.poses(task.episode.traffic))
        physics.forward()
    return env.observe_again()


def play_fleet(env: BatchedLaneKeepingEnv,
               policy: Callable[[TensorDictBase], TensorDictBase], board: FleetBoard,
               episodes: int, *, deterministic: bool = False,
               arrange: Callable[[BatchedLaneKeepingEnv], None] | None = None
               ) -> tuple[EvaluationResult, list[int | None]]:
    """``episodes`` fleet episodes on ``env`` (joined by :func:`join_fleet`): the
    robot-episodes, episode by episode and robot by robot (``env_index`` is the robot;
    ``hit_movers`` the mover of its simulation a collision hit), and the robot each hit
    (None: none). ``arrange`` may move the robots at the start of each fleet episode
    (:func:`start_apart`)."""
    robots = env.num_envs
    constraints = env.constraints
    rows: list[tuple[Any, ...]] = []
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    with set_exploration_type(exploration), torch.no_grad():
        for _ in range(episodes):
            td = start_apart(env, board, arrange)
            rows += _fleet_episode(env, Rollout(env, policy, td), board, constraints, robots)
    result = EvaluationResult.of_rows(rows, constraints)
    hit_robots = [None if row[5] is None else board.robot_of_mover(row[0].env_index, row[5])
                  for row in rows]
    return result, hit_robots


def _fleet_episode(env: BatchedLaneKeepingEnv, rollout: Rollout, board: FleetBoard,
                   constraints: Sequence[Constraint], robots: int) -> list[tuple[Any, ...]]:
    """One fleet episode, until every robot's has ended: one row per robot, in robot order."""
    accumulator = EpisodeAccumulator(robots, constraints)
    actions: list[list[np.ndarray]] = [[] for _ in range(robots)]
    lateral, outside = np.zeros(robots), np.zeros(robots, dtype=np.int64)
    ended: dict[int, tuple[Any, ...]] = {}

    def bookkeeping(stepped: TensorDictBase) -> None:
        nxt = stepped["next"]
        for robot in range(robots):
            if board.active[robot]:
                actions[robot].append(stepped["action"][robot].numpy().copy())
        lateral[:] += nxt["lane_lateral"].reshape(robots).abs().double().numpy()
        outside[:] += ~nxt["in_lane"].reshape(robots).numpy()
        terminations = [TERMINATIONS[t] for t in nxt["termination"].reshape(robots).tolist()]
        finished = [s for s in accumulator.add_transition(nxt) if board.active[s.env_index]]
        for stats in finished:
            robot = stats.env_index
            task = env.tasks[robot]
            mover = task.hit_mover if terminations[robot] == "collision" else None
            ended[robot] = (stats, terminations[robot], np.stack(actions[robot]),
                            task.start_direction, task.hit_object, mover,
                            float(lateral[robot] / stats.length), int(outside[robot]))
        for stats in finished:  # a collision between two robots ends both robots' episodes
            robot = stats.env_index
            mover = ended[robot][5]
            other = None if mover is None else board.robot_of_mover(robot, mover)
            if other is None or other in ended:
                continue
            hit = accumulator.end(other, {"collision": 1.0})
            ended[other] = (hit, "collision", np.stack(actions[other]),
                            env.tasks[other].start_direction, None,
                            board.mover_of_robot(other, robot),
                            float(lateral[other] / hit.length), int(outside[other]))
        for robot in ended:
            board.active[robot] = False

    while any(board.active):
        board.poses = [physics.pose() for physics in env.physics]
        rollout.step(bookkeeping)
    return [ended[robot] for robot in range(robots)]


def by_robot(episodes: list[EpisodeStats], robots: int,
             constraints: Sequence[Constraint]) -> list[dict[str, float]]:
    """Each robot's episodes, J_R (m) and constraint metrics (J_clane, J_coll, ...) over its
    own episodes."""
    out = []
    for robot in range(robots):
        own = [e for e in episodes if e.env_index == robot]
        entry = {"episodes": len(own), "J_R": float(np.mean([e.distance for e in own]))}
        for constraint in constraints:
            entry[constraint.metric] = float(np.mean([e.costs[constraint.name] for e in own]))
        out.append(entry)
    return out


__all__ = ["FLEET_CLEARANCE", "MAX_ROBOTS", "by_robot", "evaluate_fleet", "fleet_config",
           "fleet_overrides", "fleet_traffic", "join_fleet", "load_task_traffic", "play_fleet",
           "start_apart"]

