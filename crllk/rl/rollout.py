"""Seeded evaluation episodes of a policy on a batched environment.

Episode ``k`` of an evaluation runs in sub-environment ``k mod N``: each sub-environment plays
its share of the episodes one after another from its own spawn seed, so the result depends only
on the environment's seed and ``N``, never on timing.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats, Summary, summarise
from crllk.tasks.constraints import Constraint


@dataclass
class EvaluationResult:
    """Finished episodes in episode order, their summary and the actions taken per episode;
    ``directions`` the loop direction each started in (``"intended"``, ``"reverse"`` or None)
    and ``hit_objects`` the map object each ended on (an index, or None)."""

    episodes: list[EpisodeStats]
    summary: Summary
    constraints: tuple[Constraint, ...] = ()
    terminations: list[str | None] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    directions: list[str | None] = field(default_factory=list)
    hit_objects: list[int | None] = field(default_factory=list)


def episode_quotas(episodes: int, num_envs: int) -> np.ndarray:
    """How many episodes each sub-environment plays: episode k goes to ``k mod num_envs``."""
    quotas = np.full(num_envs, episodes // num_envs, dtype=np.int64)
    quotas[: episodes % num_envs] += 1
    return quotas


@torch.no_grad()
def run_episodes(env: BatchedLaneKeepingEnv, policy: Callable[[TensorDictBase], TensorDictBase],
                 episodes: int, *, deterministic: bool = True,
                 sample_seed: int | None = None) -> EvaluationResult:
    """Plays ``episodes`` full episodes with ``policy`` from a fresh reset of ``env``.

    Args:
        env: a :class:`crllk.envs.batched.BatchedLaneKeepingEnv` (batch size ``[N]``).
        policy: writes ``"action"`` into the tensordict it is given.
        episodes: how many episodes to finish in total.
        deterministic: take the policy's mode instead of sampling.
        sample_seed: when sampling, seeds torch's generator for the episodes and restores it
            afterwards, so the result depends only on the env's seed, ``N`` and this seed.
    """
    if deterministic or sample_seed is None:
        return _run_episodes(env, policy, episodes, deterministic)
    with torch.random.fork_rng():
        torch.manual_seed(sample_seed)
        return _run_episodes(env, policy, episodes, deterministic)


def _run_episodes(env: BatchedLaneKeepingEnv, policy: Callable[[TensorDictBase], TensorDictBase],
                  episodes: int, deterministic: bool) -> EvaluationResult:
    num_envs = int(env.batch_size[0])
    quotas = episode_quotas(episodes, num_envs)
    played = np.zeros(num_envs, dtype=np.int64)
    by_env: list[list[tuple[Any, ...]]] = [[] for _ in range(num_envs)]
    tasks = getattr(env, "tasks", [None] * num_envs)
    constraints = env.constraints
    accumulator = EpisodeAccumulator(num_envs, constraints)
    current_actions: list[list[np.ndarray]] = [[] for _ in range(num_envs)]
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    td = env.reset()
    with set_exploration_type(exploration):
        while (played < quotas).any():
            policy(td)
            actions = td["action"].numpy().copy()
            stepped = env.step(td)
            nxt = stepped["next"]
            for i in range(num_envs):
                current_actions[i].append(actions[i])
            terminations = [getattr(getattr(task, "outcome", None), "termination", None)
                            for task in tasks]
            finished = accumulator.add_transition(nxt)
            for stats in finished:
                i = stats.env_index
                if played[i] < quotas[i]:
                    by_env[i].append((stats, terminations[i], np.stack(current_actions[i]),
                                      getattr(tasks[i], "start_direction", None),
                                      getattr(tasks[i], "hit_object", None)))
                    played[i] += 1
                current_actions[i] = []
            td = env.maybe_reset(step_mdp(stepped))  # after reading the termination reasons
    ordered = [by_env[k % num_envs][k // num_envs] for k in range(episodes)]
    stats = [entry[0] for entry in ordered]
    return EvaluationResult(episodes=stats, summary=summarise(stats, constraints),
                            constraints=tuple(constraints),
                            terminations=[entry[1] for entry in ordered],
                            actions=[entry[2] for entry in ordered],
                            directions=[entry[3] for entry in ordered],
                            hit_objects=[entry[4] for entry in ordered])


__all__ = ["EvaluationResult", "episode_quotas", "run_episodes"]


@torch.no_grad()
def collect(env: BatchedLaneKeepingEnv, actor: torch.nn.Module, carry: TensorDictBase,
            steps: int) -> tuple[TensorDictBase, TensorDictBase]:
    """``steps`` control steps of every sub-environment with the stochastic policy; returns
    the transitions ``[N, steps]`` and the tensordict to continue from."""
    transitions = []
    with set_exploration_type(ExplorationType.RANDOM):
        for _ in range(steps):
            actor(carry)
            stepped, carry = env.step_and_maybe_reset(carry)
            transitions.append(stepped)
    return torch.stack(transitions, dim=1), carry
