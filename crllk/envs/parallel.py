"""The simulations of one training run stepped in several processes, behind one ``EnvBase``.

:class:`ParallelLaneKeepingEnv` runs TorchRL's :class:`~torchrl.envs.ParallelEnv` (spawned
worker processes, shared-memory buffers) over ``W`` :class:`~crllk.envs.batched.
BatchedLaneKeepingEnv` workers of ``n`` simulations each, and presents them as one env of batch
size ``[W * n]``: simulation ``w * n + j`` is simulation ``j`` of worker ``w``. Its tensordicts
have the keys and layout of a one-process env of ``W * n`` simulations, so the policy, the
episode statistics and the PPO update do not see the difference.

Workers are built by a picklable factory (a module-level function and its keyword arguments per
worker). :meth:`~ParallelLaneKeepingEnv.sim_state` gathers the workers' snapshots into the one
snapshot a one-process env would take (:func:`~crllk.envs.batched.merge_sim_states`), and
:meth:`~ParallelLaneKeepingEnv.load_sim_state` hands each worker its slice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs import EnvBase, ParallelEnv

from crllk.envs.batched import (
    BatchedLaneKeepingEnv,
    MirroredTeacherFlag,
    merge_sim_states,
    split_sim_state,
)


class ParallelLaneKeepingEnv(MirroredTeacherFlag, EnvBase):
    """``len(worker_kwargs)`` worker processes, each a :class:`BatchedLaneKeepingEnv` built by
    ``create_env_fn(**worker_kwargs[w])`` (every worker with as many simulations), stepped
    together as one env of batch size ``[workers * n]``.

    Args:
        create_env_fn: a module-level function (spawned workers import it) returning a
            :class:`BatchedLaneKeepingEnv`.
        worker_kwargs: its keyword arguments, one mapping per worker.
        num_threads: torch threads of this process (TorchRL would otherwise lower them by one
            per worker); each worker runs with one.

    The workers are daemonic: they end with this process even if :meth:`close` is never
    called (a run that fails half-way).
    """

    def __init__(self, create_env_fn: Callable[..., BatchedLaneKeepingEnv],
                 worker_kwargs: Sequence[dict[str, Any]], *, num_threads: int | None = None):
        workers = len(worker_kwargs)
        if workers < 1:
            raise ValueError("at least one worker is needed")
        # Building the metadata env and starting the workers must not move this process's
        # random generator: the policy's samples then match a one-process run.
        with torch.random.fork_rng():
            parallel = ParallelEnv(workers, create_env_fn, create_env_kwargs=list(worker_kwargs),
                                   mp_start_method="spawn", num_threads=num_threads,
                                   daemon=True)
            parallel.start()
        w, n = parallel.batch_size
        super().__init__(device="cpu", batch_size=torch.Size([w * n]))
        self.parallel = parallel
        self.workers, self.per_worker, self.num_envs = w, n, w * n
        self.config = parallel.config()[0]
        """The task's :class:`~crllk.tasks.config.TaskConfig` (the workers')."""
        self.constraints = self.config.constraints
        self.cost_keys = tuple(c.cost_key for c in self.constraints)
        self._teacher_active = bool(parallel.teacher_active()[0])
        flat = torch.Size([self.num_envs])
        self.observation_spec = _flatten(parallel.observation_spec, flat)
        self.action_spec = _flatten(parallel.action_spec, flat)
        self.reward_spec = _flatten(parallel.reward_spec, flat)
        self.done_spec = _flatten(parallel.done_spec, flat)

    # ----- the workers' settings ----------------------------------------------------------
    def _send_teacher_active(self, active: bool) -> None:
        self.parallel.set_teacher_active(active)

    @property
    def seeds(self) -> list[int]:
        """The spawn seed of each simulation, in order."""
        return [seed for worker in self.parallel.seeds() for seed in worker]

    # ----- reset and step -----------------------------------------------------------------
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get("_reset", None)
        inner = None
        if mask is not None:
            inner = TensorDict({"_reset": mask.reshape(self.workers, self.per_worker, 1)},
                               batch_size=self.parallel.batch_size)
        return self.parallel.reset(inner).reshape(self.num_envs)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.select(*self.action_keys).reshape(self.workers, self.per_worker)
        return self.parallel.step(actions).get("next").reshape(self.num_envs)

    def _set_seed(self, seed: int | None) -> None:
        raise NotImplementedError("the workers' spawn seeds are set when they are built")

    # ----- snapshots ----------------------------------------------------------------------
    def sim_state(self) -> dict[str, Any]:
        """The workers' snapshots as one: what a one-process env of all the simulations would
        return (:meth:`BatchedLaneKeepingEnv.sim_state`)."""
        return merge_sim_states(self.parallel.sim_state())

    def load_sim_state(self, state: dict[str, Any]) -> None:
        """Restores a :meth:`sim_state` (of this env or of a one-process env of as many
        simulations), each worker its slice."""
        parts = split_sim_state(state, [self.per_worker] * self.workers)
        for index, part in enumerate(parts):
            self.parallel[index].load_sim_state(part)

    # ----- teardown -----------------------------------------------------------------------
    def close(self, *, raise_if_closed: bool = True) -> None:
        """Stops the worker processes (each releases its renderers)."""
        if not self.parallel.is_closed:
            self.parallel.close(raise_if_closed=raise_if_closed)
        super().close(raise_if_closed=raise_if_closed)


def _flatten(spec: Any, shape: torch.Size) -> Any:
    """``spec`` of batch ``[W, n, ...]`` as batch ``[W * n, ...]``."""
    return spec.reshape(*shape, *spec.shape[2:])


__all__ = ["ParallelLaneKeepingEnv"]
