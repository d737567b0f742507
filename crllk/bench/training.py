"""Training throughput next to environment-only throughput.

Training frames/s counts a whole iteration of :mod:`crllk.train` (collection with the policy,
GAE for reward and costs, PPO epochs); the bound is the same simulations stepped with random
actions and no networks, where training steps them (in this process, or each worker stepping
its own). The target is a ratio of at least 0.5.

:func:`collection_rates` times collection with the policy (and whole iterations) for a number
of worker processes (the trainer's ``workers``), to compare one process with several.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

import crllk  # noqa: F401  (headless GL before torchrl)
from crllk.config import TrainConfig, validate
from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator
from crllk.envs.parallel import ParallelLaneKeepingEnv
from crllk.training.batches import BatchSource, collect_batch, first_carry
from crllk.training.build import build_run
from crllk.training.compose import compose_config
from crllk.training.loop import learn
from crllk.training.updates import shape_signals


@dataclass(frozen=True)
class TrainingRates:
    """Frames per second of training and of the environment alone, with their ratio."""

    training: float
    environment: float

    @property
    def ratio(self) -> float:
        return self.training / self.environment


def bench_config(overrides: Sequence[str] = ()) -> TrainConfig:
    """The trainer's default configuration with Hydra-style ``overrides``."""
    return validate(compose_config(overrides))


def training_rates(config: TrainConfig, iterations: int = 5) -> TrainingRates:
    """Times ``iterations`` training iterations and as many environment-only steps."""
    env, learner, multipliers, generator = build_run(config)
    batches = BatchSource.for_run(config, env, learner, env.reset())
    episodes = EpisodeAccumulator(config.num_envs, env.constraints)

    def iterate() -> None:
        learn(config, env, learner, multipliers, generator, episodes, batches, 0)

    iterate()  # warm-up (with collect_ahead: also starts the first batch ahead)
    start = time.perf_counter()
    for _ in range(iterations):
        iterate()
    batches.settle()  # the last batch collected ahead counts as a cost, not a frame
    training = iterations * config.frames_per_batch / (time.perf_counter() - start)

    steps = iterations * config.rollout_steps
    start = time.perf_counter()
    if isinstance(env, ParallelLaneKeepingEnv):  # where training steps them: in the workers
        env.run(random_steps, [(steps,)] * env.workers)
    else:
        random_steps(env, steps)
    environment = steps * config.num_envs / (time.perf_counter() - start)
    env.close()
    return TrainingRates(training=training, environment=environment)


def random_steps(env: BatchedLaneKeepingEnv, steps: int) -> None:
    """``steps`` steps of every simulation of ``env`` with random actions, resetting those
    that finish (the environment alone; in a worker process for a parallel env)."""
    td = env.reset()
    for _ in range(steps):
        td["action"] = env.action_spec.rand()
        _, td = env.step_and_maybe_reset(td)


@dataclass(frozen=True)
class CollectionRates:
    """Frames per second of collection alone (:func:`crllk.training.batches.collect_batch`: the
    policy in this process and the simulations in ``workers`` processes, or both in
    ``workers`` remote collectors with ``collector=ray``) and of whole training iterations,
    with the main process's own shares of an iteration."""

    workers: int
    collector: str
    collection: float
    training: float
    policy_ms: float
    """One stochastic policy forward pass on a batch of ``num_envs`` observations in this
    process (ms)."""
    update_s: float
    """The learner's update on one collected batch (PPO-Lagrangian: GAE and the epochs) (s)."""


def collection_rates(config: TrainConfig, iterations: int = 3) -> CollectionRates:
    """Times ``iterations`` collections and ``iterations`` training iterations (after one
    warm-up collection), and the policy's forward pass on the collection's batch size."""
    env, learner, multipliers, generator = build_run(config)
    try:
        carry = first_carry(env)
        _, carry = collect_batch(env, learner.actor, carry, config.rollout_steps,
                                 learner.action_noise)  # warm-up
        start = time.perf_counter()
        for _ in range(iterations):
            batch, carry = collect_batch(env, learner.actor, carry, config.rollout_steps,
                                         learner.action_noise)
        collecting = (time.perf_counter() - start) / iterations
        shape_signals(batch, config, env.config)
        start = time.perf_counter()
        learner.update(batch, generator)
        update_s = time.perf_counter() - start

        episodes = EpisodeAccumulator(config.num_envs, env.constraints)
        batches = BatchSource.for_run(config, env, learner, carry)
        start = time.perf_counter()
        for _ in range(iterations):
            learn(config, env, learner, multipliers, generator, episodes, batches, 0)
        batches.settle()
        iterating = (time.perf_counter() - start) / iterations

        observations = batch[:, -1].select(*learner.actor.in_keys)
        repeats = 20
        with torch.no_grad(), set_exploration_type(ExplorationType.RANDOM):
            learner.actor(observations.clone())
            start = time.perf_counter()
            for _ in range(repeats):
                learner.actor(observations.clone())
        policy_ms = 1000 * (time.perf_counter() - start) / repeats
    finally:
        env.close()
    return CollectionRates(workers=config.workers, collector=config.collector,
                           collection=config.frames_per_batch / collecting,
                           training=config.frames_per_batch / iterating, policy_ms=policy_ms,
                           update_s=update_s)


__all__ = ["CollectionRates", "TrainingRates", "bench_config", "collection_rates",
           "training_rates"]
