"""Training batches collected inside the worker processes of a parallel env.

:func:`collect_in_workers` sends every worker of a
:class:`~crllk.envs.parallel.ParallelLaneKeepingEnv` the policy (once per batch), its slice of
the tensordict to continue from and its simulations' action streams; each worker then runs
:func:`crllk.rl.rollout.collect` on its own simulations, policy included, with no round trip
per step, and sends back its transitions. The parent waits in the kernel meanwhile, so the
workers have the cores to themselves; or (:func:`start_collection`) it updates the networks
meanwhile, on the batch before.

The batch equals what :func:`~crllk.rl.rollout.collect` gives in one process from the same
carry and streams: each simulation samples from its own stream
(:mod:`crllk.rl.sampling`), and the policy's outputs for a simulation do not depend on the
others in its batch (tested for the run's layouts: CPU kernels may round differently for
batches of other sizes).
"""

from __future__ import annotations

import pickle
from collections.abc import Iterable

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase

from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.parallel import ParallelLaneKeepingEnv
from crllk.rl.rollout import collect
from crllk.rl.sampling import ActionNoise

Arrays = dict[str | tuple[str, ...], np.ndarray]
"""A tensordict's leaves as numpy arrays by (nested) key: what crosses a worker's pipe."""


def to_arrays(tensordict: TensorDictBase) -> Arrays:
    """Every leaf of ``tensordict`` as a numpy array, by its (nested) key."""
    return {key: value.numpy() for key, value in
            tensordict.items(include_nested=True, leaves_only=True)}


def joined(parts: Iterable[Arrays], batch_size: torch.Size) -> TensorDict:
    """One tensordict of ``batch_size`` from slices of it along the first dimension, in
    order (the inverse of :func:`to_arrays` on consecutive slices)."""
    parts = list(parts)
    tensordict = TensorDict({}, batch_size=batch_size)
    for key in parts[0]:
        tensordict.set(key, torch.from_numpy(np.concatenate([part[key] for part in parts])))
    return tensordict


def collect_in_workers(env: ParallelLaneKeepingEnv, actor: torch.nn.Module,
                       carry: TensorDictBase, steps: int, noise: ActionNoise
                       ) -> tuple[TensorDictBase, TensorDictBase]:
    """``steps`` control steps of every simulation, each worker stepping its own with its copy
    of ``actor``; the transitions ``[N, steps]`` and the tensordict to continue from, as
    :func:`~crllk.rl.rollout.collect` returns them. ``noise`` continues from where the
    workers left their streams."""
    return start_collection(env, actor, carry, steps, noise).finish()


class Collection:
    """A :func:`collect_in_workers` under way in the workers (:func:`start_collection`)."""

    def __init__(self, env: ParallelLaneKeepingEnv, steps: int, noise: ActionNoise) -> None:
        self._env, self._steps, self._noise = env, steps, noise

    def finish(self) -> tuple[TensorDictBase, TensorDictBase]:
        """Waits for the workers: the transitions and the tensordict to continue from;
        ``noise`` continues from where the workers left their streams."""
        env = self._env
        answers = env.finish()
        batch = joined((answer[0] for answer in answers), torch.Size([env.num_envs, self._steps]))
        following = joined((answer[1] for answer in answers), env.batch_size)
        self._noise.load_states([torch.from_numpy(state)
                                 for answer in answers for state in answer[2]])
        return batch, following


def start_collection(env: ParallelLaneKeepingEnv, actor: torch.nn.Module,
                     carry: TensorDictBase, steps: int, noise: ActionNoise) -> Collection:
    """Starts :func:`collect_in_workers` and returns at once, with ``actor`` as it is now (the
    workers get a copy): this process may change the actor meanwhile (update it), and
    :meth:`Collection.finish` waits for the batch. ``noise`` must not be used meanwhile."""
    policy = pickle.dumps(actor)  # this process's own object, read only by its own workers
    n = env.per_worker
    states = [state.numpy() for state in noise.states()]
    shares = [(policy, to_arrays(carry[w * n:(w + 1) * n]), states[w * n:(w + 1) * n], steps)
              for w in range(env.workers)]
    env.start(collect_share, shares)
    return Collection(env, steps, noise)


def collect_share(env: BatchedLaneKeepingEnv, policy: bytes, carry: Arrays,
                  states: list[np.ndarray], steps: int
                  ) -> tuple[Arrays, Arrays, list[np.ndarray]]:
    """A worker's part of :func:`collect_in_workers` (runs in the worker): its transitions,
    the tensordict to continue from and its streams' states, as arrays."""
    actor = pickle.loads(policy)
    noise = ActionNoise.from_states([torch.from_numpy(state) for state in states])
    batch, following = collect(env, actor, joined([carry], env.batch_size), steps, noise)
    return to_arrays(batch), to_arrays(following), [s.numpy() for s in noise.states()]


__all__ = ["Collection", "collect_in_workers", "collect_share", "joined", "start_collection",
           "to_arrays"]
