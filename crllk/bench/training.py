"""Training throughput next to environment-only throughput, measured in one process.

Training frames/s counts a whole iteration of :mod:`crllk.train` (collection with the policy,
GAE for reward and costs, PPO epochs); the bound is the same batched environment stepped with
random actions and no networks. The target is a ratio of at least 0.5 (state).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import crllk  # noqa: F401  (headless GL before torchrl)
from crllk.envs.episodes import EpisodeAccumulator
from crllk.training.build import build_run
from crllk.training.compose import compose_config
from crllk.training.config import TrainConfig, validate
from crllk.training.loop import learn


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
    carry = env.reset()

    episodes = EpisodeAccumulator(config.num_envs, env.constraints)

    def iterate(td):
        return learn(config, env, learner, multipliers, generator, episodes, td, 0)[1]

    carry = iterate(carry)  # warm-up
    start = time.perf_counter()
    for _ in range(iterations):
        carry = iterate(carry)
    training = iterations * config.frames_per_batch / (time.perf_counter() - start)

    steps = iterations * config.rollout_steps
    td = env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        td["action"] = env.action_spec.rand()
        _, td = env.step_and_maybe_reset(td)
    environment = steps * config.num_envs / (time.perf_counter() - start)
    env.close()
    return TrainingRates(training=training, environment=environment)


__all__ = ["TrainingRates", "bench_config", "training_rates"]
