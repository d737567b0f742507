"""The parts of a run: its environments, its learner (:mod:`crllk.algos`) and multipliers."""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence

import torch

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.algos import Learner, build_learner
from crllk.algos.base import TrainingEnv
from crllk.config import CLUSTER_EXTRA, SOURCE, TrainConfig
from crllk.envs.batched import BatchedLaneKeepingEnv, make_env, sub_env_seeds
from crllk.envs.distributed import RayClusterError, RayLaneKeepingCollector
from crllk.envs.parallel import LaneKeepingEnv, ParallelLaneKeepingEnv
from crllk.errors import ConfigError
from crllk.rl.import_probes import settle_import_probes
from crllk.rl.lagrange import Multiplier, make_multiplier
from crllk.tasks.constraints import Constraint


def build_env(config: TrainConfig, *, num_envs: int, seed: int,
              training: bool = False, action: str | None = None) -> BatchedLaneKeepingEnv:
    """The run's environment; the ``training`` one starts ``encounters`` of its episodes in
    front of an obstacle, the others keep the task's own spawns and report the lane pose the
    community's metrics need. ``action``: the action type it takes (default the run's; a
    discrete run's deployed policy plays in ``duty``, see
    :func:`crllk.training.runs.played_action`)."""
    overrides = config.task_overrides()
    if training and config.encounters > 0:
        spawn = {**overrides.get("spawn", {}), "encounters": config.encounters}
        if config.encounter_horizon:
            spawn["encounter_horizon"] = config.encounter_horizon
        if config.encounter_curve_weight != 1.0:
            spawn["encounter_curve_weight"] = config.encounter_curve_weight
        overrides = {**overrides, "spawn": spawn}
    return make_env(config.task_source(), num_envs=num_envs, observation=config.obs.name,
                    action=action or config.action.name, seed=seed, overrides=overrides,
                    privileged_state=config.model.critic_input == "state",
                    teacher=training and (config.teacher.coeff > 0 or config.teacher.final > 0),
                    teacher_margin=config.teacher.margin,
                    commands=config.model.policy_commands, history=config.obs.history,
                    history_stride=config.obs.history_stride, lane_pose=not training)


def build_training_env(config: TrainConfig) -> TrainingEnv:
    """The ``num_envs`` training simulations: stepped in this process (``workers=1`` without
    ``collect_ahead``), split among ``workers`` processes (:class:`ParallelLaneKeepingEnv`;
    one worker process with ``workers=1`` and ``collect_ahead``), or among ``workers`` remote
    collectors (``collector=ray``; started by :func:`build_run`). Simulation ``i`` spawns from
    the same seed every way.

    Raises:
        ConfigError: for ``collector=ray`` without Ray installed.
    """
    share = config.num_envs // config.workers
    shares = [{"config": config, "first": w * share, "count": share}
              for w in range(config.workers)]
    if config.collector == "ray":
        if importlib.util.find_spec("ray") is None:
            raise ConfigError(SOURCE, "collector", f"'ray' needs Ray, from {CLUSTER_EXTRA}")
        spec_env = build_env(config, num_envs=1, seed=config.seed, training=True)
        try:
            return RayLaneKeepingCollector(worker_env, shares, spec_env, num_envs=config.num_envs,
                                           address=config.ray_address, seed=config.seed)
        finally:
            spec_env.close()
    if config.workers == 1 and not config.collect_ahead:
        return build_env(config, num_envs=config.num_envs, seed=config.seed, training=True)
    return ParallelLaneKeepingEnv(worker_env, shares, num_threads=config.threads)


def build_eval_env(config: TrainConfig, *, num_envs: int, seed: int,
                   action: str | None = None) -> LaneKeepingEnv:
    """An evaluation's environment (:func:`build_env`), split among the run's ``workers``
    processes like its training simulations when they divide ``num_envs`` (and the run
    collects locally); simulation ``i`` spawns from the same seed either way, so the episodes
    are the same. ``action``: as :func:`build_env`'s."""
    workers = config.workers
    if workers == 1 or config.collector != "local" or num_envs % workers:
        return build_env(config, num_envs=num_envs, seed=seed, action=action)
    share = num_envs // workers
    shares = [{"config": config, "first": w * share, "count": share, "seed": seed,
               "num_envs": num_envs, "training": False, "action": action}
              for w in range(workers)]
    return ParallelLaneKeepingEnv(worker_env, shares)


def worker_env(config: TrainConfig, first: int, count: int, seed: int | None = None,
               num_envs: int | None = None, training: bool = True,
               action: str | None = None) -> BatchedLaneKeepingEnv:
    """A worker's share of the training simulations (or, with ``seed`` and ``num_envs``, of an
    evaluation's, taking ``action``): ``count`` of them from simulation ``first``, each with
    the spawn seed it has in the one-process env (runs in the worker)."""
    seed = config.seed if seed is None else seed
    num_envs = config.num_envs if num_envs is None else num_envs
    env = build_env(config, num_envs=count, seed=seed, training=training, action=action)
    env.set_spawn_seeds(sub_env_seeds(seed, num_envs)[first:first + count])
    return env


def build_multipliers(config: TrainConfig, constraints: Sequence[Constraint]
                      ) -> dict[str, Multiplier]:
    """One multiplier per constraint of the task, from ``algo.constraints.<name>``.

    Raises:
        ConfigError: if a constraint has no settings there.
    """
    algo = config.algo
    multipliers = {}
    for name in (c.name for c in constraints):
        if name not in algo.constraints:
            raise ConfigError("override", f"algo.constraints.{name}",
                              f"the task constrains {name!r} but no multiplier is set for it "
                              f"(set: {', '.join(algo.constraints) or 'none'})")
        c = algo.constraints[name]
        common = {"threshold": c.dual_target(), "initial": c.initial, "max_value": c.max_value,
                  "schedule": algo.schedule, "frozen": algo.frozen}
        if algo.multiplier == "pid":
            multipliers[name] = make_multiplier("pid", kp=c.kp, ki=c.step_size, kd=c.kd, **common)
        else:
            multipliers[name] = make_multiplier("dual", step_size=c.step_size, **common)
    return multipliers


def build_run(config: TrainConfig) -> tuple[TrainingEnv, Learner, dict[str, Multiplier],
                                            torch.Generator]:
    """Seeds torch and builds the environment, the learner, the multipliers and the generator
    of minibatch orders, in this order (a resumed run rebuilds them the same way); remote
    collectors start with the learner's policy.

    Raises:
        ConfigError: if the Ray cluster cannot host the remote collectors.
    """
    settle_import_probes()
    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    env = build_training_env(config)
    learner = build_learner(config, env)
    multipliers = build_multipliers(config, env.constraints)
    if isinstance(env, RayLaneKeepingCollector):
        try:
            env.start(learner.actor, config.rollout_steps)
        except RayClusterError as err:
            env.close()
            raise ConfigError(SOURCE, err.setting, err.problem) from None
    return env, learner, multipliers, generator


def keeps_snapshots(env: TrainingEnv) -> bool:
    """Whether checkpoints hold the simulations' state, so that a resumed run continues its
    episodes exactly (not with remote collectors)."""
    return getattr(env, "keeps_snapshots", True)
