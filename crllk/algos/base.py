"""What the trainer needs of a learning algorithm: :class:`Learner`.

The trainer (:mod:`crllk.training.loop`) collects batches with the learner's ``actor`` and its
simulations' action streams, learns the multipliers from the finished episodes, and hands both
to the learner; it names no term of any loss. A learner is one module of :mod:`crllk.algos`
holding a class with ``name`` and ``build`` (chosen by ``algo.learner``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar, Protocol

import torch
from tensordict import TensorDictBase

from crllk.config import TrainConfig
from crllk.envs.distributed import RayLaneKeepingCollector
from crllk.envs.parallel import LaneKeepingEnv
from crllk.rl.sampling import ActionNoise

TrainingEnv = LaneKeepingEnv | RayLaneKeepingCollector
"""What a run collects from: simulations in this process or in workers, or remote collectors."""


class Learner(Protocol):
    """A policy and what trains it, built from a run's configuration and environment."""

    name: ClassVar[str]
    """The ``algo.learner`` value that selects it."""
    actor: torch.nn.Module
    """The stochastic policy that collects, is evaluated and is exported."""
    action_noise: ActionNoise
    """Each training simulation's stream of action samples (:mod:`crllk.rl.sampling`)."""

    @classmethod
    def build(cls, config: TrainConfig, env: TrainingEnv) -> Learner:
        """The learner for ``env``'s observations, actions and constraints."""

    @property
    def diagnostic_names(self) -> list[str]:
        """The names of what :meth:`update` returns (``metrics.csv`` columns)."""

    def prepare(self, frames: int, multipliers: Mapping[str, float]) -> None:
        """Sets what changes over a run (the multipliers, the schedules after ``frames``)
        before the next update."""

    def needs_teacher(self, frames: int) -> bool:
        """Whether batches collected after ``frames`` must carry the teacher's actions."""

    def update(self, batch: TensorDictBase, generator: torch.Generator) -> dict[str, float]:
        """Learns from one batch of transitions ``[num_envs, steps]`` (rewards and costs
        already shaped); ``generator`` orders the minibatches. Returns named losses and
        diagnostics (means over the update). With ``collect_ahead`` the batch was collected
        by the policy as it was before the previous update (and the next one is being
        collected meanwhile, by a copy of the actor as :meth:`prepare` left it): an update
        must weigh its samples by the probabilities stored with them (``action_log_prob``),
        and must not use ``action_noise``."""

    def state_dict(self) -> dict[str, Any]:
        """Everything to resume the learner exactly, in tensors and plain containers; the
        policy's weights under ``"actor"``."""

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restores :meth:`state_dict`."""
