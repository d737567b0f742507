"""The simulations of one training run stepped by remote collectors on a Ray cluster.

:class:`RayLaneKeepingCollector` runs TorchRL's :class:`~torchrl.collectors.distributed.
RayCollector` over ``W`` remote collectors (Ray actors, each a TorchRL
:class:`~torchrl.collectors.Collector` of a :class:`~crllk.envs.batched.BatchedLaneKeepingEnv`
of ``n`` simulations, built by a picklable factory on the machine Ray places it) and gathers one
batch of ``T`` steps from every collector at a time (``sync=True``; the collectors are
:class:`crllk.envs.remote.LaneKeepingCollector`). The trainer gets it in the layout of a local
collection, ``[W * n, T]`` with the same keys (simulation ``w * n + j`` is simulation ``j`` of
collector ``w``), so the episode statistics, the multipliers and the PPO update do not see the
difference. Before every batch the policy's current weights go to every
collector through Ray's object store, and the collection waits for them: batch ``k`` is
collected with the weights after update ``k - 1``.

The simulators' state stays with the collectors: it is not in checkpoints, so a resumed run
starts fresh episodes (:attr:`RayLaneKeepingCollector.keeps_snapshots`).

Networking: without an address the run starts a private Ray instance whose processes listen on
127.0.0.1 only (``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, no dashboard, token authentication
with a fresh token, nothing written to ``~/.ray``). Weights travel through Ray, not through
torch.distributed, whose store would listen on every interface.
"""

from __future__ import annotations

import atexit
import functools
import os
import secrets
import socket
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.envs.utils import ExplorationType

from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.workers import MirroredTeacherFlag
from crllk.network import RAY_LOCAL_ONLY, is_loopback

CPUS_PER_COLLECTOR = 1
"""Ray CPUs each remote collector reserves: it steps its simulations and the policy on one."""
CONNECT_TIMEOUT_S = 10.0
"""How long the head's port may take to answer before ``address`` is given up (s)."""
SAMPLE_STREAM = 1
"""Second entropy word of the collectors' sample seeds (:func:`sample_seeds`)."""
UNSYNCED_WARNING = "RayCollector iteration started before weight synchronization"
"""TorchRL's warning when no weight-sync scheme is set up: here the weights are pushed by
:meth:`RayLaneKeepingCollector.collect` instead."""


class RayClusterError(RuntimeError):
    """A Ray cluster that cannot host the collectors; ``setting`` names what to change."""

    def __init__(self, setting: str, problem: str) -> None:
        self.setting, self.problem = setting, problem
        super().__init__(f"{setting}: {problem}")


class RayLaneKeepingCollector(MirroredTeacherFlag):
    """``len(worker_kwargs)`` remote collectors on a Ray cluster, each stepping a
    :class:`BatchedLaneKeepingEnv` built by ``create_env_fn(**worker_kwargs[w])`` (every one
    with ``num_envs / W`` simulations), collected together as ``num_envs`` simulations.

    Args:
        create_env_fn: a module-level function (the collectors import it) returning a
            :class:`BatchedLaneKeepingEnv`.
        worker_kwargs: its keyword arguments, one mapping per collector.
        spec_env: a local env of the same task and settings (any number of simulations),
            whose specs, task configuration and constraints this object presents with batch
            size ``[num_envs]``; it is not stepped.
        num_envs: the simulations of all collectors together.
        address: ``host:port`` of the Ray cluster's head to join; None starts a private Ray
            instance on 127.0.0.1 for this process.
        seed: the collectors' policy samples are seeded from it (one seed per collector).

    Nothing of Ray starts before :meth:`start`.
    """

    keeps_snapshots = False
    """The simulators' state stays on the collectors: checkpoints hold none of it."""

    def __init__(self, create_env_fn: Callable[..., BatchedLaneKeepingEnv],
                 worker_kwargs: Sequence[dict[str, Any]], spec_env: BatchedLaneKeepingEnv, *,
                 num_envs: int, address: str | None = None, seed: int = 0) -> None:
        workers = len(worker_kwargs)
        if workers < 1 or num_envs % workers:
            raise ValueError(f"{workers} collectors cannot share {num_envs} simulations equally")
        self.create_env_fn, self.worker_kwargs = create_env_fn, list(worker_kwargs)
        self.workers, self.per_worker, self.num_envs = workers, num_envs // workers, num_envs
        self.address, self.seed = address, seed
        self.batch_size = torch.Size([num_envs])
        self.config = spec_env.config
        """The task's :class:`~crllk.tasks.config.TaskConfig`."""
        self.constraints = spec_env.constraints
        self.cost_keys = spec_env.cost_keys
        self.observation_spec = _batched(spec_env.observation_spec, num_envs)
        self.action_spec = _batched(spec_env.action_spec, num_envs)
        self.reward_spec = _batched(spec_env.reward_spec, num_envs)
        self.done_spec = _batched(spec_env.done_spec, num_envs)
        self._teacher_active = bool(spec_env.teacher_active)
        self._collector: Any = None
        self._batches: Any = None
        self._steps = 0
        self._owns_ray = False

    # ----- the collectors' settings -------------------------------------------------------
    def _send_teacher_active(self, active: bool) -> None:
        """Tells every started collector's env (they start with :attr:`teacher_active`)."""
        if self._collector is not None:
            self._collector.map_fn("env.set_teacher_active", [(active,)] * self.workers)

    # ----- start, collect, close ----------------------------------------------------------
    def start(self, policy: torch.nn.Module, steps: int) -> None:
        """Joins (or starts) Ray and starts the collectors, each with a copy of ``policy``,
        to collect ``steps`` steps of each simulation per batch.

        Raises:
            RayClusterError: if the head does not answer or the cluster has too few CPUs.
        """
        from torchrl.collectors.distributed import RayCollector

        from crllk.envs.remote import LaneKeepingCollector

        self._owns_ray = join_ray(self.address, self.workers * CPUS_PER_COLLECTOR)
        atexit.register(self.close)  # before Ray's own exit handler: stop the actors first
        self._collector = RayCollector(
            [functools.partial(self.create_env_fn, **kwargs) for kwargs in self.worker_kwargs],
            policy, frames_per_batch=self.num_envs * steps, total_frames=sys.maxsize, sync=True,
            collector_class=LaneKeepingCollector,
            collector_kwargs=[{"sample_seed": seed, "auto_register_policy_transforms": False}
                              for seed in sample_seeds(self.seed, self.workers)],
            exploration_type=ExplorationType.RANDOM,
            remote_configs={"num_cpus": CPUS_PER_COLLECTOR},
            weight_sync_schemes={})  # weights go through Ray's object store (collect)
        self._batches = iter(self._collector)
        self._steps = steps
        self._send_teacher_active(self._teacher_active)
        where = (f"the Ray cluster at {self.address}" if self.address
                 else "a private Ray instance on 127.0.0.1")
        print(f"ray: {self.workers} remote collectors on {where}, {self.per_worker} of the "
              f"{self.num_envs} simulations each", flush=True)

    def collect(self, policy: torch.nn.Module, steps: int) -> TensorDictBase:
        """Sends ``policy``'s weights to every collector, then collects ``steps`` steps of
        every simulation with them; returns the transitions ``[num_envs, steps]`` (time
        last, as :func:`crllk.rl.rollout.collect`)."""
        if self._collector is None:
            raise RuntimeError("start the collectors first")
        if steps != self._steps:
            raise ValueError(f"the collectors collect {self._steps} steps per batch, "
                             f"not {steps}")
        import ray

        weights = ray.put(TensorDict.from_module(policy).data)
        self._collector.map_fn("update_policy_weights_", [(weights,)] * self.workers)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=UNSYNCED_WARNING)
            return merge_batches(next(self._batches))

    def frames_stepped(self) -> int:
        """Frames the collectors report having stepped since :meth:`start`."""
        if self._collector is None:
            return 0
        stats = self._collector.stats(workers="per_worker")
        return sum(int(value) for key, value in stats.items() if key.endswith("/frames"))

    def close(self) -> None:
        """Stops the collectors (with a line saying how many frames they stepped) and the
        private Ray instance, or leaves the joined cluster; closing twice is harmless."""
        atexit.unregister(self.close)
        if self._collector is not None:
            print(f"ray: {self.workers} remote collectors stepped {self.frames_stepped()} "
                  "frames", flush=True)
            self._collector.shutdown()
            self._collector = self._batches = None
        if self._owns_ray:
            import ray

            ray.shutdown()
            self._owns_ray = False


def sample_seeds(seed: int, workers: int) -> list[int]:
    """The torch seed of each collector's policy samples: a 32-bit word from each of
    ``workers`` children of ``np.random.SeedSequence([seed, SAMPLE_STREAM])``, a stream apart
    from the simulations' spawn seeds (children of ``SeedSequence(seed)``)."""
    children = np.random.SeedSequence([seed, SAMPLE_STREAM]).spawn(workers)
    return [int(child.generate_state(1)[0]) for child in children]


def merge_batches(stacked: TensorDictBase) -> TensorDictBase:
    """The collectors' batches, stacked ``[W, n, T]`` in collector order, as one batch
    ``[W * n, T]`` with the keys of a local collection (without the collectors' own
    ``"collector"`` entries: trajectory ids), on the CPU."""
    workers, per_worker, steps = stacked.shape
    return stacked.exclude("collector").reshape(workers * per_worker, steps).to("cpu")


def join_ray(address: str | None, cpus: int) -> bool:
    """Connects this process to the Ray cluster whose head is at ``address`` (``host:port``),
    or starts a private Ray instance with ``cpus`` CPUs on 127.0.0.1. Returns whether this
    call connected, so that ``ray.shutdown()`` is the caller's (it stops a private instance
    and only leaves a joined cluster); a process already connected keeps its connection.

    Raises:
        RayClusterError: if nothing answers at ``address``, joining fails, or the cluster has
            fewer than ``cpus`` CPUs.
    """
    import ray

    if ray.is_initialized():
        return False
    if address is None:
        keep_ray_local()
        if os.environ.get("RAY_AUTH_MODE", "token") == "token":  # Ray's default: token auth
            os.environ.setdefault("RAY_AUTH_TOKEN", secrets.token_hex(32))  # not in ~/.ray
        ray.init(address="local", num_cpus=cpus, include_dashboard=False,
                 _node_ip_address="127.0.0.1")
        return True
    host, _, port = address.rpartition(":")
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as err:
        raise RayClusterError("ray_address", f"nothing answers at {address} "
                              f"({err.strerror or err})") from None
    if is_loopback(host):
        keep_ray_local()
    try:
        ray.init(address=address, include_dashboard=False)
    except Exception as err:  # Ray raises ConnectionError, RuntimeError, AuthenticationError...
        reason = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise RayClusterError("ray_address", f"cannot join the Ray cluster at {address}: "
                              f"{reason}") from None
    available = ray.cluster_resources().get("CPU", 0)
    if available < cpus:
        ray.shutdown()
        raise RayClusterError("workers", f"the Ray cluster at {address} has {available:g} CPUs, "
                              f"fewer than the {cpus} the remote collectors need")
    return True


def keep_ray_local() -> None:
    """Sets ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` for the Ray processes this process starts,
    and applies it to this process too (Ray read the variable when TorchRL imported it), so
    that Ray keeps 127.0.0.1 as this node's address instead of the machine's; and, unless set,
    ``RAY_USAGE_STATS_ENABLED=0`` (a local instance reports nothing)."""
    from ray._private import ray_constants

    os.environ.update(RAY_LOCAL_ONLY)
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray_constants.ENABLE_RAY_CLUSTER = False


def _batched(spec: Any, num_envs: int) -> Any:
    """``spec`` of batch ``[n, ...]`` as batch ``[num_envs, ...]``."""
    return spec.expand(num_envs, *spec.shape[1:])


__all__ = ["CPUS_PER_COLLECTOR", "RayClusterError",
           "RayLaneKeepingCollector", "is_loopback", "join_ray", "keep_ray_local",
           "merge_batches", "sample_seeds"]
