"""``python -m crllk.peers.env_server task=<task> log=<episodes.csv>``: one lane-keeping task
(state features, continuous actions) served over standard input and output, for a learner that
runs in another Python (a peer library whose pins cannot share crllk's environment).

The protocol is JSON, one object per line each way, numbers and names only: neither side ever
unpickles what the other sends. On start the server writes the task's description::

    {"observation_size": 24, "action_size": 2, "horizon": 512, "cost_limit": 1.0,
     "thresholds": {"lane": 0.5, "collision": 0.02}}

then answers each request with one line::

    {"reset": 7}             -> {"observation": [...]}        (7: a spawn seed, or null)
    {"step": [0.4, -0.1]}    -> {"observation": [...], "reward": r, "cost": c,
                                 "costs": {"lane": .., "collision": ..},
                                 "terminated": false, "truncated": false}
    {"close": true}          -> the server exits (so does the end of its input)

A request it cannot serve (a seed out of range or the test seed, a step before the first reset
or after an episode's end, an action that is not two finite numbers) gets ``{"error": "..."}``
(one line) and the server exits with status 2. The reply's ``cost`` is the peer's single cost
(:func:`scalar_cost`, with :func:`episode_end_correction` on an episode's last step); ``costs``
the task's own, by constraint. Every finished episode is appended to ``log`` in
``metrics.csv``'s columns (one row per episode: ``frames`` served so far, wall ``time_s``,
``J_R`` and each constraint's episode value), so a peer's training curve is read like the
trainer's.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import crllk  # noqa: F401  (chooses the headless GL backend before mujoco loads)
from crllk.cli import run
from crllk.config import algo_thresholds
from crllk.errors import ConfigError
from crllk.gym import LaneKeepingEnv
from crllk.settings import MISSING, parse_dotlist, setting, spawn_seed
from crllk.tasks.constraints import Constraint
from crllk.training.logs import CsvLog

SOURCE = "crllk.peers.env_server"
COST_LIMIT = 1.0
"""The peer's limit on its episode cost (:func:`scalar_cost`): at most 1 implies every
constraint holds."""


def scalar_cost(costs: Mapping[str, float], constraints: Sequence[Constraint],
                thresholds: Mapping[str, float], horizon: int) -> float:
    """One step's single cost for a learner that takes one constraint (OmniSafe's): each
    constraint's step cost over its threshold, a mean-aggregated one also over the horizon::

        c_t = Σ_k c_k,t / (α_k · H)   (mean over the episode, e.g. lane deviation)
            + Σ_k c_k,t / α_k         (sum over the episode, e.g. collisions)

    With :func:`episode_end_correction` added on its last step, an episode's total is
    Σ_k (episode value_k / α_k) whatever its length, so an expectation at most
    :data:`COST_LIMIT` = 1 implies E[value_k] <= α_k for every k: a sufficient, tighter
    condition than the task's constraints (the budget is shared between them)."""
    total = 0.0
    for constraint in constraints:
        scale = thresholds[constraint.name] * (horizon if constraint.aggregate == "mean" else 1)
        total += costs[constraint.name] / scale
    return total


def episode_end_correction(totals: Mapping[str, float], length: int,
                           constraints: Sequence[Constraint], thresholds: Mapping[str, float],
                           horizon: int) -> float:
    """What an episode of ``length`` steps that ended before the horizon adds on its last step
    so that its mean-aggregated costs count over its own length: Σ_k total_k · (1/L − 1/H) / α_k
    (0 for a full-length episode)."""
    return sum(totals[c.name] * (1.0 / length - 1.0 / horizon) / thresholds[c.name]
               for c in constraints if c.aggregate == "mean")


@dataclass
class ServerConfig:
    """Command-line settings (``key=value``)."""

    task: str = setting(MISSING)
    """A task name or task/map file."""
    log: str = setting(MISSING)
    """The CSV file every finished episode is appended to."""
    lane_threshold: float = algo_thresholds()["lane"]
    """α1 (dm)."""
    collision_threshold: float = algo_thresholds()["collision"]
    """α2 (collisions per episode)."""

    def problems(self) -> Iterator[tuple[str, str]]:
        for name in ("lane_threshold", "collision_threshold"):
            if getattr(self, name) <= 0:
                yield name, "must be above 0"


class EpisodeLog:
    """The served episodes so far, one ``metrics.csv``-like row each."""

    def __init__(self, path: Path, constraints: Sequence[Constraint]):
        self.constraints = tuple(constraints)
        self.csv = CsvLog(path, ["frames", "time_s", "episodes", "J_R",
                                 *(c.metric for c in self.constraints), "episode_length"])
        self.started = time.perf_counter()
        self.frames = 0
        self.start_episode()

    def start_episode(self) -> None:
        self.length, self.distance = 0, 0.0
        self.totals = {c.name: 0.0 for c in self.constraints}

    def add(self, reward: float, costs: Mapping[str, float], done: bool) -> None:
        self.frames += 1
        self.length += 1
        self.distance += reward
        for name, value in costs.items():
            self.totals[name] += value
        if done:
            self.csv.append({
                "frames": self.frames, "time_s": time.perf_counter() - self.started,
                "episodes": 1, "J_R": self.distance, "episode_length": self.length,
                **{c.metric: c.episode_value(self.totals[c.name], self.length)
                   for c in self.constraints}})
            self.start_episode()


class Server:
    """The task behind the protocol."""

    def __init__(self, config: ServerConfig):
        self.env = LaneKeepingEnv(config.task, observation="state", action="continuous")
        task = self.env.task_config
        self.constraints = tuple(task.constraints)
        self.horizon = int(task.horizon)
        wanted = {"lane": config.lane_threshold, "collision": config.collision_threshold}
        defaults = algo_thresholds()
        self.thresholds = {c.name: wanted.get(c.name, defaults[c.name])
                           for c in self.constraints}
        self.log = EpisodeLog(Path(config.log), self.constraints)
        self.in_episode = False

    def description(self) -> dict[str, Any]:
        return {"observation_size": int(self.env.observation_space.shape[0]),
                "action_size": int(self.env.action_space.shape[0]), "horizon": self.horizon,
                "cost_limit": COST_LIMIT, "thresholds": self.thresholds}

    def answer(self, request: Any) -> dict[str, Any] | None:
        """The reply to one request (None: close).

        Raises:
            ConfigError: for a request that is not one of the protocol's.
        """
        if not isinstance(request, dict) or len(request) != 1:
            raise _bad("request", f"expected one of reset, step, close, got {request!r}"[:200])
        (kind, value), = request.items()
        if kind == "close":
            return None
        if kind == "reset":
            if value is not None and (not isinstance(value, int) or isinstance(value, bool)):
                raise _bad("reset", f"expected a whole-number seed or null, got {value!r}")
            problem = None if value is None else spawn_seed(value)
            if problem:
                raise _bad("reset", f"seed {problem}")
            observation, _ = self.env.reset(seed=value)
            self.log.start_episode()
            self.in_episode = True
            return {"observation": observation.tolist()}
        if kind == "step":
            if not self.in_episode:
                raise _bad("step", "no episode under way: reset first")
            try:
                observation, reward, terminated, truncated, info = self.env.step(value)
            except ValueError as err:  # an action the task refuses
                raise _bad("step", str(err)) from None
            costs = {c.name: info[c.cost_key] for c in self.constraints}
            cost = scalar_cost(costs, self.constraints, self.thresholds, self.horizon)
            self.in_episode = not (terminated or truncated)
            if not self.in_episode:
                totals = {name: self.log.totals[name] + costs[name] for name in costs}
                cost += episode_end_correction(totals, self.log.length + 1, self.constraints,
                                               self.thresholds, self.horizon)
            self.log.add(reward, costs, not self.in_episode)
            return {"observation": observation.tolist(), "reward": reward, "cost": cost,
                    "costs": costs, "terminated": terminated, "truncated": truncated}
        raise _bad("request", f"expected one of reset, step, close, got {kind!r}"[:200])


def serve(server: Server, requests: IO[str], replies: IO[str]) -> None:
    """Answers ``requests`` line by line until ``close`` or their end."""
    _write(replies, server.description())
    for line in requests:
        try:
            request = json.loads(line)
        except json.JSONDecodeError as err:
            raise _bad("request", f"not JSON ({err.msg})") from None
        reply = server.answer(request)
        if reply is None:
            return
        _write(replies, reply)


def _bad(field: str, problem: str) -> ConfigError:
    return ConfigError(SOURCE, field, problem)


def _write(stream: IO[str], message: Mapping[str, Any]) -> None:
    stream.write(json.dumps(message) + "\n")
    stream.flush()


def main(argv: Sequence[str] | None = None) -> int:
    config = parse_dotlist(ServerConfig, sys.argv[1:] if argv is None else argv, SOURCE)
    server = Server(config)
    try:
        serve(server, sys.stdin, sys.stdout)
    except ConfigError as err:
        _write(sys.stdout, {"error": str(err)})
        raise
    finally:
        server.env.close()
    return 0


if __name__ == "__main__":
    run(main)
