"""Playing a policy on a batched environment: :class:`Rollout`, the one loop that training
(:func:`collect`), evaluation (:func:`run_episodes`) and recordings step through.

Episode ``k`` of an evaluation runs in sub-environment ``k mod N``: each sub-environment plays
its share of the episodes one after another from its own spawn seed, so the result depends only
on the environment's seed and ``N``, never on timing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type, step_mdp

from crllk.envs.batched import TERMINATIONS, BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats, Summary, summarise
from crllk.envs.parallel import LaneKeepingEnv
from crllk.rl.sampling import ActionNoise, sample_actions
from crllk.tasks.constraints import Constraint


@dataclass
class EvaluationResult:
    """Finished episodes in episode order, their summary and the actions taken per episode;
    ``directions`` the loop direction each started in (``"intended"``, ``"reverse"`` or None)
    ``hit_objects`` the map object each ended on (an index, or None) and ``hit_movers`` the
    moving agent (an index, vehicles then pedestrians, or None); where the env reports the lane
    pose, ``lateral_deviations`` each episode's mean |offset| from the lane centre (m) and
    ``outside_lane_steps`` its steps ended outside its lane or off the road."""

    episodes: list[EpisodeStats]
    summary: Summary
    constraints: tuple[Constraint, ...] = ()
    terminations: list[str | None] = field(default_factory=list)
    actions: list[np.ndarray] = field(default_factory=list)
    directions: list[str | None] = field(default_factory=list)
    hit_objects: list[int | None] = field(default_factory=list)
    hit_movers: list[int | None] = field(default_factory=list)
    lateral_deviations: list[float | None] = field(default_factory=list)
    outside_lane_steps: list[int | None] = field(default_factory=list)

    @classmethod
    def of_rows(cls, rows: Sequence[tuple[Any, ...]],
                constraints: Sequence[Constraint]) -> EvaluationResult:
        """The result of episodes given as rows (stats, termination, actions, direction,
        hit object, hit mover, lateral deviation, outside-lane steps), in episode order."""
        stats = [row[0] for row in rows]
        return cls(episodes=stats, summary=summarise(stats, constraints),
                   constraints=tuple(constraints),
                   terminations=[row[1] for row in rows], actions=[row[2] for row in rows],
                   directions=[row[3] for row in rows], hit_objects=[row[4] for row in rows],
                   hit_movers=[row[5] for row in rows],
                   lateral_deviations=[row[6] for row in rows],
                   outside_lane_steps=[row[7] for row in rows])


class Rollout:
    """Steps ``env`` with ``policy`` from ``td`` (a fresh reset without it). Finished
    sub-environments reset after each step, once ``on_step`` has seen the transition."""

    def __init__(self, env: LaneKeepingEnv,
                 policy: Callable[[TensorDictBase], TensorDictBase],
                 td: TensorDictBase | None = None) -> None:
        self.env, self.policy = env, policy
        self.td = env.reset() if td is None else td
        """What the policy acts on next."""

    def step(self, on_step: Callable[[TensorDictBase], None] | None = None) -> TensorDictBase:
        """One control step of every sub-environment; returns the transition (``"next"``
        holds the step's outputs). ``on_step`` sees it while the simulations still hold the
        state the step ended in (before finished ones reset)."""
        self.policy(self.td)
        stepped = self.env.step(self.td)
        if on_step is not None:
            on_step(stepped)
        env = self.env
        self.td = env.maybe_reset(step_mdp(stepped, reward_keys=env.reward_keys,
                                           done_keys=env.done_keys, action_keys=env.action_keys))
        return stepped


def episode_quotas(episodes: int, num_envs: int) -> np.ndarray:
    """How many episodes each sub-environment plays: episode k goes to ``k mod num_envs``."""
    quotas = np.full(num_envs, episodes // num_envs, dtype=np.int64)
    quotas[: episodes % num_envs] += 1
    return quotas


@torch.no_grad()
def run_episodes(env: LaneKeepingEnv, policy: Callable[[TensorDictBase], TensorDictBase],
                 episodes: int, *, deterministic: bool = True,
                 sample_seed: int | None = None) -> EvaluationResult:
    """Plays ``episodes`` full episodes with ``policy`` from a fresh reset of ``env``.

    Args:
        env: the simulations, in this process or in worker processes (batch size ``[N]``).
        policy: writes ``"action"`` into the tensordict it is given.
        episodes: how many episodes to finish in total.
        deterministic: take the policy's mode instead of sampling (a discrete run's
            deployed policy in a duty env never samples: its expected duties).
        sample_seed: when sampling, seeds torch's generator for the episodes and restores it
            afterwards, so the result depends only on the env's seed, ``N`` and this seed.
    """
    if deterministic or sample_seed is None:
        return _run_episodes(env, policy, episodes, deterministic)
    with torch.random.fork_rng():
        torch.manual_seed(sample_seed)
        return _run_episodes(env, policy, episodes, deterministic)


def _run_episodes(env: LaneKeepingEnv, policy: Callable[[TensorDictBase], TensorDictBase],
                  episodes: int, deterministic: bool) -> EvaluationResult:
    num_envs = int(env.batch_size[0])
    quotas = episode_quotas(episodes, num_envs)
    played = np.zeros(num_envs, dtype=np.int64)
    by_env: list[list[tuple[Any, ...]]] = [[] for _ in range(num_envs)]
    tasks = getattr(env, "tasks", [None] * num_envs)
    constraints = env.constraints
    accumulator = EpisodeAccumulator(num_envs, constraints)
    current_actions: list[list[np.ndarray]] = [[] for _ in range(num_envs)]
    lateral_sums, outside_counts = np.zeros(num_envs), np.zeros(num_envs, dtype=np.int64)
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM

    def finish_episodes(stepped: TensorDictBase) -> None:
        """Episode bookkeeping, while the tasks still hold the ended episodes' details."""
        nxt = stepped["next"]
        actions = stepped["action"].numpy()
        for i in range(num_envs):
            current_actions[i].append(actions[i].copy())
        lane_pose = "lane_lateral" in nxt
        if lane_pose:
            lateral_sums[:] += nxt["lane_lateral"].reshape(num_envs).abs().double().numpy()
            outside_counts[:] += ~nxt["in_lane"].reshape(num_envs).numpy()
        terminations = nxt["termination"].reshape(num_envs).tolist()
        for stats in accumulator.add_transition(nxt):
            i = stats.env_index
            if played[i] < quotas[i]:
                by_env[i].append((stats, TERMINATIONS[terminations[i]],
                                  np.stack(current_actions[i]),
                                  getattr(tasks[i], "start_direction", None),
                                  getattr(tasks[i], "hit_object", None),
                                  getattr(tasks[i], "hit_mover", None),
                                  float(lateral_sums[i] / stats.length) if lane_pose else None,
                                  int(outside_counts[i]) if lane_pose else None))
                played[i] += 1
            current_actions[i] = []
            lateral_sums[i], outside_counts[i] = 0.0, 0

    rollout = Rollout(env, policy)
    with set_exploration_type(exploration):
        while (played < quotas).any():
            rollout.step(finish_episodes)
    ordered = [by_env[k % num_envs][k // num_envs] for k in range(episodes)]
    return EvaluationResult.of_rows(ordered, constraints)


__all__ = ["EvaluationResult", "Rollout", "collect", "episode_quotas", "run_episodes"]


@torch.no_grad()
def collect(env: BatchedLaneKeepingEnv, actor: torch.nn.Module, carry: TensorDictBase,
            steps: int, noise: ActionNoise | None = None
            ) -> tuple[TensorDictBase, TensorDictBase]:
    """``steps`` control steps of every sub-environment with the stochastic policy; returns
    the transitions ``[N, steps]`` and the tensordict to continue from. With ``noise``,
    simulation ``i`` samples its actions from stream ``i`` (:func:`sample_actions`), else from
    torch's global generator."""
    policy = actor if noise is None else partial(sample_actions, actor, noise=noise)
    rollout = Rollout(env, policy, carry)
    with set_exploration_type(ExplorationType.RANDOM):
        transitions = [rollout.step() for _ in range(steps)]
    return torch.stack(transitions, dim=1), rollout.td
