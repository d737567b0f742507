"""Per-episode statistics from batched transitions: distance, mean lane cost, collisions.

The paper's metrics over finished episodes (DESIGN.md §6): J_R is the forward distance of an
episode (m), J_clane the mean per-step lane cost of an episode (dm) and J_coll its number of
collisions (road departures count). :class:`EpisodeAccumulator` adds up each sub-environment's
running episode step by step and hands back an :class:`EpisodeStats` when it ends.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from tensordict import TensorDictBase


@dataclass(frozen=True)
class EpisodeStats:
    """One finished episode of one sub-environment."""

    env_index: int
    distance: float  # m, sum of the forward progress rewards
    lane_cost: float  # dm, mean per-step lane cost
    collisions: float  # collisions and road departures in the episode
    length: int  # control steps
    truncated: bool  # ended by the time limit, not by the task
    encounter: bool = False  # started in front of an obstacle (training spawns only)

    def as_row(self) -> dict[str, Any]:
        return asdict(self)


class EpisodeAccumulator:
    """Running sums of ``num_envs`` sub-environments' current episodes."""

    def __init__(self, num_envs: int):
        self.num_envs = num_envs
        self.distance = np.zeros(num_envs)
        self.lane_cost = np.zeros(num_envs)
        self.collisions = np.zeros(num_envs)
        self.length = np.zeros(num_envs, dtype=np.int64)

    def add_batch(self, batch: TensorDictBase) -> list[EpisodeStats]:
        """Adds transitions of shape ``[N, T]`` (time last) and returns the episodes that
        ended in them, in the order they ended."""
        nxt = batch["next"]
        keys = ["reward", "cost_lane", "cost_collision", "done", "truncated"]
        if "encounter" in nxt:
            keys.append("encounter")
        columns = [nxt[key].reshape(self.num_envs, -1).numpy() for key in keys]
        finished: list[EpisodeStats] = []
        for t in range(columns[0].shape[1]):
            finished += self.add_step(*(column[:, t] for column in columns))
        return finished

    def add_step(self, reward: np.ndarray, cost_lane: np.ndarray, cost_collision: np.ndarray,
                 done: np.ndarray, truncated: np.ndarray,
                 encounter: np.ndarray | None = None) -> list[EpisodeStats]:
        """Adds one step of every sub-environment (arrays of shape ``[N]``); ``encounter``
        flags episodes that started in front of an obstacle."""
        self.distance += reward
        self.lane_cost += cost_lane
        self.collisions += cost_collision
        self.length += 1
        finished = []
        for i in np.flatnonzero(done):
            finished.append(EpisodeStats(
                env_index=int(i), distance=float(self.distance[i]),
                lane_cost=float(self.lane_cost[i] / self.length[i]),
                collisions=float(self.collisions[i]), length=int(self.length[i]),
                truncated=bool(truncated[i]),
                encounter=False if encounter is None else bool(encounter[i])))
            self.distance[i] = self.lane_cost[i] = self.collisions[i] = 0.0
            self.length[i] = 0
        return finished

    def state_dict(self) -> dict[str, np.ndarray]:
        return {"distance": self.distance.copy(), "lane_cost": self.lane_cost.copy(),
                "collisions": self.collisions.copy(), "length": self.length.copy()}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        for key in ("distance", "lane_cost", "collisions", "length"):
            value = np.asarray(state[key])
            if value.shape != (self.num_envs,):
                raise ValueError(f"episode accumulator state {key!r} has shape {value.shape}, "
                                 f"expected ({self.num_envs},)")
            getattr(self, key)[:] = value


@dataclass(frozen=True)
class Summary:
    """Mean metrics over episodes (NaN when there are none)."""

    episodes: int
    J_R: float  # m
    J_clane: float  # dm
    J_coll: float  # collisions per episode
    length: float  # control steps

    def as_row(self) -> dict[str, Any]:
        return asdict(self)


def summarise(episodes: Sequence[EpisodeStats]) -> Summary:
    """The paper's J_R, J_clane and J_coll over ``episodes``."""
    if not episodes:
        return Summary(0, math.nan, math.nan, math.nan, math.nan)

    def mean(values: list[float]) -> float:
        return math.fsum(values) / len(values)

    return Summary(
        episodes=len(episodes),
        J_R=mean([e.distance for e in episodes]),
        J_clane=mean([e.lane_cost for e in episodes]),
        J_coll=mean([e.collisions for e in episodes]),
        length=mean([float(e.length) for e in episodes]),
    )


__all__ = ["EpisodeAccumulator", "EpisodeStats", "Summary", "summarise"]
