"""Per-episode statistics from batched transitions: distance and one value per constraint.

The paper's metrics over finished episodes: J_R is the forward distance of an episode (m); each
constraint's metric (J_clane, J_coll, ...) is the mean over episodes of the constraint's episode
value, the ``mean`` or ``sum`` of its per-step cost as the constraint declares
(:mod:`crllk.tasks.constraints`). :class:`EpisodeAccumulator` adds up each sub-environment's
running episode step by step and hands back an :class:`EpisodeStats` when it ends.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase

from crllk.tasks.constraints import Constraint, cost_key


@dataclass(frozen=True)
class EpisodeStats:
    """One finished episode of one sub-environment."""

    env_index: int
    distance: float
    """Sum of the forward progress rewards (m)."""
    costs: dict[str, float]
    """Each constraint's episode value, by constraint name."""
    length: int
    """Control steps."""
    truncated: bool
    """Ended by the time limit, not by the task."""
    encounter: bool = False
    """Started in front of an obstacle (training spawns only)."""

    def as_row(self) -> dict[str, Any]:
        """One flat row: ``cost_<name>`` per constraint."""
        return {"env_index": self.env_index, "distance": self.distance,
                **{cost_key(name): value for name, value in self.costs.items()},
                "length": self.length, "truncated": self.truncated, "encounter": self.encounter}


class EpisodeAccumulator:
    """Running sums of ``num_envs`` sub-environments' current episodes."""

    def __init__(self, num_envs: int, constraints: Sequence[Constraint]):
        self.num_envs = num_envs
        self.constraints = tuple(constraints)
        self.distance = np.zeros(num_envs)
        self.cost_sums = {c.name: np.zeros(num_envs) for c in self.constraints}
        self.length = np.zeros(num_envs, dtype=np.int64)

    def add_batch(self, batch: TensorDictBase) -> list[EpisodeStats]:
        """Adds transitions of shape ``[N, T]`` (time last) and returns the episodes that
        ended in them, in the order they ended."""
        nxt = batch["next"]

        def column(key: str) -> np.ndarray:
            return nxt[key].reshape(self.num_envs, -1).numpy()

        reward, done, truncated = column("reward"), column("done"), column("truncated")
        costs = {c.name: column(c.cost_key) for c in self.constraints}
        encounter = column("encounter") if "encounter" in nxt else None
        finished: list[EpisodeStats] = []
        for t in range(reward.shape[1]):
            finished += self.add_step(
                reward[:, t], {name: values[:, t] for name, values in costs.items()},
                done[:, t], truncated[:, t], None if encounter is None else encounter[:, t])
        return finished

    def add_transition(self, nxt: TensorDictBase) -> list[EpisodeStats]:
        """Adds one step, the ``"next"`` entries of a ``[N]`` transition."""
        def column(key: str) -> np.ndarray:
            return nxt[key].reshape(self.num_envs).numpy()

        return self.add_step(column("reward"),
                             {c.name: column(c.cost_key) for c in self.constraints},
                             column("done"), column("truncated"),
                             column("encounter") if "encounter" in nxt else None)

    def add_step(self, reward: np.ndarray, costs: Mapping[str, np.ndarray], done: np.ndarray,
                 truncated: np.ndarray, encounter: np.ndarray | None = None
                 ) -> list[EpisodeStats]:
        """Adds one step of every sub-environment (arrays of shape ``[N]``, ``costs`` by
        constraint name); ``encounter`` flags episodes that started in front of an obstacle."""
        self.distance += reward
        for name, sums in self.cost_sums.items():
            sums += costs[name]
        self.length += 1
        return [self._finish(int(i), bool(truncated[i]),
                             False if encounter is None else bool(encounter[i]))
                for i in np.flatnonzero(done)]

    def end(self, i: int, extra_costs: Mapping[str, float]) -> EpisodeStats:
        """Ends sub-environment ``i``'s running episode at its last step, ``extra_costs`` (by
        constraint name) added to that step's costs: an event its own simulation did not see
        (a fleet's robot hit by another, :mod:`crllk.evaluation.fleet`)."""
        for name, cost in extra_costs.items():
            if name in self.cost_sums:
                self.cost_sums[name][i] += cost
        return self._finish(i, truncated=False, encounter=False)

    def _finish(self, i: int, truncated: bool, encounter: bool) -> EpisodeStats:
        """Sub-environment ``i``'s episode as it stands; its sums start again."""
        length = int(self.length[i])
        stats = EpisodeStats(
            env_index=i, distance=float(self.distance[i]),
            costs={c.name: float(c.episode_value(self.cost_sums[c.name][i], length))
                   for c in self.constraints},
            length=length, truncated=truncated, encounter=encounter)
        self.distance[i] = 0.0
        for sums in self.cost_sums.values():
            sums[i] = 0.0
        self.length[i] = 0
        return stats

    def state_dict(self) -> dict[str, Any]:
        """The running sums as tensors (``distance``, ``length``, ``costs`` by constraint
        name), which checkpoints load without running code."""
        return {"distance": torch.from_numpy(self.distance.copy()),
                "length": torch.from_numpy(self.length.copy()),
                "costs": {name: torch.from_numpy(sums.copy())
                          for name, sums in self.cost_sums.items()}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Continues from a :meth:`state_dict` (tensors, or arrays of older snapshots)."""
        arrays = {"distance": self.distance, "length": self.length,
                  **{f"costs.{name}": sums for name, sums in self.cost_sums.items()}}
        saved = {"distance": state["distance"], "length": state["length"],
                 **{f"costs.{name}": value for name, value in state["costs"].items()}}
        if set(saved) != set(arrays):
            raise ValueError(f"episode accumulator state has {sorted(saved)}, expected "
                             f"{sorted(arrays)}")
        for key, target in arrays.items():
            value = np.asarray(saved[key])
            if value.shape != (self.num_envs,):
                raise ValueError(f"episode accumulator state {key!r} has shape {value.shape}, "
                                 f"expected ({self.num_envs},)")
            target[:] = value


@dataclass(frozen=True)
class Summary:
    """Mean metrics over episodes (NaN when there are none)."""

    episodes: int
    J_R: float
    """Mean distance (m)."""
    length: float
    """Mean episode length (control steps)."""
    J: dict[str, float] = field(default_factory=dict)
    """Each constraint's metric (mean episode value), by metric name (``J_clane``)."""

    def as_row(self) -> dict[str, Any]:
        """``episodes``, ``J_R``, one column per constraint metric, ``length``."""
        return {"episodes": self.episodes, "J_R": self.J_R, **self.J, "length": self.length}


def summarise(episodes: Sequence[EpisodeStats], constraints: Sequence[Constraint]) -> Summary:
    """J_R and each constraint's metric over ``episodes``."""
    if not episodes:
        return Summary(0, math.nan, math.nan, {c.metric: math.nan for c in constraints})

    def mean(values: list[float]) -> float:
        return math.fsum(values) / len(values)

    return Summary(
        episodes=len(episodes),
        J_R=mean([e.distance for e in episodes]),
        length=mean([float(e.length) for e in episodes]),
        J={c.metric: mean([e.costs[c.name] for e in episodes]) for c in constraints},
    )


__all__ = ["EpisodeAccumulator", "EpisodeStats", "Summary", "summarise"]
