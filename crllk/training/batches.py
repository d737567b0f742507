"""Where each training iteration's batch comes from: :class:`BatchSource`.

By default an iteration collects its batch when it starts, with the policy the last update
left, and the workers are idle while the main process updates the networks. With
``collect_ahead=true`` (worker processes only) the workers collect the next batch *during* the
update, with a copy of the policy taken just before it: the update on batch ``k`` and the
collection of batch ``k + 1`` share the cores. Each batch is then one update older than the
policy that learns from it; PPO's ratios stay exact, since they divide by the probabilities the
collecting policy stored with each action (``action_log_prob``), and its clipping bounds how far
an update may move from it.

A checkpoint waits for the batch under way (:meth:`BatchSource.settle`) and keeps it
(:meth:`BatchSource.pending`), with the simulations, the tensordict to continue from and the
action streams as that collection left them, so a resumed run learns from the same batch.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch
from tensordict import TensorDictBase

from crllk.config import TrainConfig
from crllk.envs.distributed import RayLaneKeepingCollector
from crllk.envs.parallel import ParallelLaneKeepingEnv
from crllk.rl.collection import Collection, collect_in_workers, start_collection
from crllk.rl.rollout import collect
from crllk.rl.sampling import ActionNoise
from crllk.training.build import Learner, TrainingEnv


class BatchSource:
    """The batches of one run, collected on demand or one update ahead (see the module).

    Args:
        env: the training simulations.
        actor: the policy that collects (the learner's, updated in place).
        steps: control steps of every simulation per batch.
        noise: the simulations' action streams.
        carry: what collection continues from (None: the remote collectors reset their own).
        collect_ahead: collect the next batch during the update (needs a
            :class:`~crllk.envs.parallel.ParallelLaneKeepingEnv`).
        ready: a batch collected before (a checkpoint's :meth:`pending`), learned from next.
    """

    def __init__(self, env: TrainingEnv, actor: torch.nn.Module, steps: int,
                 noise: ActionNoise, carry: TensorDictBase | None, *,
                 collect_ahead: bool = False, ready: TensorDictBase | None = None) -> None:
        if collect_ahead and not isinstance(env, ParallelLaneKeepingEnv):
            raise ValueError("collecting ahead needs the simulations in worker processes")
        self.env, self.actor, self.steps, self.noise = env, actor, steps, noise
        self.carry = carry
        """What the next collection continues from."""
        self.collect_ahead = collect_ahead
        self._ready = ready
        self._under_way: Collection | None = None

    @classmethod
    def for_run(cls, config: TrainConfig, env: TrainingEnv, learner: Learner,
                carry: TensorDictBase | None, ready: TensorDictBase | None = None
                ) -> BatchSource:
        """A run's batches: ``collect_ahead`` as configured, by the learner's actor and
        action streams, continuing from ``carry`` (and first learning from ``ready``, a
        checkpoint's batch collected ahead)."""
        return cls(env, learner.actor, config.rollout_steps, learner.action_noise, carry,
                   collect_ahead=config.collect_ahead, ready=ready)

    def next(self) -> TensorDictBase:
        """The next batch: the one collected ahead (waiting for it if it is still under way),
        or one collected now with the policy as it is."""
        self.settle()
        if self._ready is not None:
            batch, self._ready = self._ready, None
            return batch
        batch, self.carry = collect_batch(self.env, self.actor, self.carry, self.steps,
                                          self.noise)
        return batch

    def prefetch(self) -> None:
        """With ``collect_ahead``: starts collecting the next batch with the policy as it is
        now, and returns at once. Call it after everything the next batch's collection depends
        on is set (the learner's ``prepare``, the teacher flag) and before the update. Without:
        nothing (:meth:`next` collects)."""
        if not self.collect_ahead or self._under_way is not None or self._ready is not None:
            return
        assert isinstance(self.env, ParallelLaneKeepingEnv) and self.carry is not None
        self._under_way = start_collection(self.env, self.actor, self.carry, self.steps,
                                           self.noise)

    def settle(self) -> None:
        """Waits for the batch under way, if any: afterwards the simulations, :attr:`carry` and
        the action streams are as its collection left them."""
        under_way, self._under_way = self._under_way, None
        if under_way is not None:  # a failed collection raises once, and is not waited for again
            self._ready, self.carry = under_way.finish()

    def pending(self) -> TensorDictBase | None:
        """The batch collected ahead and not yet learned from (after :meth:`settle`)."""
        if self._under_way is not None:
            raise RuntimeError("a collection is under way: settle() first")
        return self._ready


def first_carry(env: TrainingEnv) -> TensorDictBase | None:
    """What collection starts from: a reset of every simulation, or None for remote
    collectors (they reset their own simulations when they start)."""
    return None if isinstance(env, RayLaneKeepingCollector) else env.reset()


def collect_batch(env: TrainingEnv, actor: torch.nn.Module, carry: TensorDictBase | None,
                  steps: int, noise: ActionNoise) -> tuple[TensorDictBase, TensorDictBase | None]:
    """``steps`` steps of every simulation with the stochastic policy (the transitions
    ``[num_envs, steps]``) and what to continue from: :func:`crllk.rl.rollout.collect` from
    ``carry`` with the simulations' action streams ``noise``, in this process or in the
    worker processes (the same batch either way), or a batch of the remote collectors with the
    policy's current weights."""
    if isinstance(env, RayLaneKeepingCollector):
        return env.collect(actor, steps), None
    if isinstance(env, ParallelLaneKeepingEnv):
        return collect_in_workers(env, actor, carry, steps, noise)
    with torch_threads(1):  # as in a worker: the same kernels, so the same actions
        return collect(env, actor, carry, steps, noise)


@contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Torch runs ``count`` CPU threads meanwhile: with simulation workers stepping on every
    core, the policy's forward passes in more threads only spin against them."""
    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


__all__ = ["BatchSource", "collect_batch", "first_carry", "torch_threads"]
