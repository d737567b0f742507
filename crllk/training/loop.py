"""The training loop: :func:`train` trains or resumes one run.

One iteration (:func:`learn`, then the logs):

1. collect ``rollout_steps`` control steps in each of ``num_envs`` simulations (with
   ``collect_ahead``, the workers collected them during the previous update:
   :mod:`crllk.training.batches`);
2. update the multipliers λ from the episodes that finished (dual ascent);
3. the learner (:mod:`crllk.algos`, ``algo.learner``) learns from the batch with these
   multipliers (PPO-Lagrangian: GAE for the reward and each cost, PPO epochs on the combined
   advantage (A_r − Σλ_i A_ci) / (1 + Σλ_i));
4. append a row to ``metrics.csv``; every ``checkpoint_every`` iterations (and at the end)
   write ``checkpoints/last.pt`` atomically; at the end (``eval.final``) and every
   ``eval.every`` iterations append an evaluation to ``eval.csv`` (the same episodes as
   ``python -m crllk.evaluate``); every
   ``record_every`` iterations record one evaluation episode with rerun; with ``live`` send
   the row and the recordings to the run's live view (:mod:`crllk.recording.live`).

The checkpoint holds the networks, the optimiser, the multipliers, the counters, the random
generators, the simulations' full state, the running episode sums and the batch collected
ahead (``collect_ahead``), so ``resume=true``
continues exactly where the uninterrupted run would have been. With remote collectors
(``collector=ray``) the simulations' state stays on the collectors: a resumed run restores the
rest and starts fresh episodes.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from omegaconf import OmegaConf
from tensordict import TensorDictBase
from tqdm import tqdm

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.config import TrainConfig
from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats, summarise
from crllk.envs.parallel import LaneKeepingEnv
from crllk.errors import ConfigError
from crllk.files import atomic_write_text, remove_stale_temp_files
from crllk.rl.lagrange import Multiplier
from crllk.rl.rollout import EvaluationResult, run_episodes
from crllk.tasks.constraints import Constraint
from crllk.training.batches import BatchSource, first_carry
from crllk.training.build import Learner, TrainingEnv, build_env, build_eval_env, build_run
from crllk.training.checkpoints import (
    POLICY_FILE,
    checkpoint_state,
    load_checkpoint,
    policy_info,
    policy_state,
    restore,
    resumed_ahead,
    resumed_carry,
    save_checkpoint,
)
from crllk.training.logs import (
    CsvLog,
    action_columns,
    eval_columns,
    metric_columns,
    print_last_evaluation,
    progress_text,
)
from crllk.training.run_dir import SOURCE_RUN, lock_run_dir
from crllk.training.updates import shape_signals, update_multipliers

if TYPE_CHECKING:
    from crllk.recording.live import LiveView


FinalEvaluation = Callable[[Path, TrainConfig, LaneKeepingEnv, EvaluationResult,
                           dict[str, Any]], None]
"""Called with the run directory, its configuration, the evaluation env, the episodes of the
evaluation made at the end of training and the final policy's counters and multipliers
(``iteration``, ``frames``, ``elapsed_s``, ``multipliers``, as
:func:`crllk.training.runs.load_actor` gives them)."""


def train(config: TrainConfig, on_final_evaluation: FinalEvaluation | None = None) -> Path:
    """Trains (or resumes) one run; returns its directory. ``on_final_evaluation`` receives
    the evaluation made at the end of training, once the final checkpoint is saved
    (``python -m crllk.train`` writes it as ``eval.json``)."""
    run_dir = config.resolved_run_dir()
    checkpoint_path = run_dir / "checkpoints" / "last.pt"
    env, learner, multipliers, generator = build_run(config)
    constraints = env.constraints
    lock = lock_run_dir(run_dir)
    try:
        resuming = prepare_run_dir(config, run_dir, checkpoint_path)
    except ConfigError:
        lock.close()
        env.close()
        raise
    episodes = EpisodeAccumulator(config.num_envs, constraints)
    metrics = CsvLog(run_dir / "metrics.csv",
                     metric_columns(config.action.name, constraints, learner.diagnostic_names))
    evaluations = CsvLog(run_dir / "eval.csv", eval_columns(constraints))
    eval_env = record_env = final_result = None
    iteration, frames, elapsed = 0, 0, 0.0

    if resuming:
        state = load_checkpoint(checkpoint_path, resuming=True)
        # as the iteration before left it, so that the run collects as the straight one
        env.teacher_active = learner.needs_teacher(state["frames"])
        exact = restore(state, learner, multipliers, episodes, env, generator)
        batches = (BatchSource.for_run(config, env, learner, resumed_carry(state),
                                       resumed_ahead(state))
                   if exact else BatchSource.for_run(config, env, learner, first_carry(env)))
        iteration, frames, elapsed = state["iteration"], state["frames"], state["elapsed"]
        metrics.truncate_after(iteration)
        evaluations.truncate_after(iteration)
        print(f"resuming {run_dir} at iteration {iteration}, {frames} frames"
              + ("" if exact else " (fresh episodes: the checkpoint holds no simulator state)"),
              flush=True)
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.yaml", OmegaConf.to_yaml(OmegaConf.structured(config)))
        env.teacher_active = learner.needs_teacher(0)
        batches = BatchSource.for_run(config, env, learner, first_carry(env))
        print(f"run directory: {run_dir}", flush=True)
    live = open_live_view(config, run_dir, constraints, learner.diagnostic_names)

    bar = tqdm(total=config.total_frames, initial=frames, unit="frame", dynamic_ncols=True,
               disable=not config.progress, file=sys.stderr)
    started = time.perf_counter() - elapsed
    while frames < config.total_frames:
        iteration_start = time.perf_counter()
        batch, finished, losses = learn(config, env, learner, multipliers, generator,
                                        episodes, batches, frames)
        iteration += 1
        frames += batch.numel()

        row = {"iteration": iteration, "frames": frames,
               "time_s": time.perf_counter() - started,
               "frames_per_s": batch.numel() / (time.perf_counter() - iteration_start),
               **episode_columns(finished, constraints),
               **{f"lambda_{name}": m.value for name, m in multipliers.items()},
               **losses, **action_columns(batch, config.action.name)}
        metrics.append(row)
        if live is not None:
            live.log_iteration(row)
        bar.update(batch.numel())
        bar.set_postfix_str(progress_text(row, constraints), refresh=False)

        periodic = bool(config.eval.every) and iteration % config.eval.every == 0
        if periodic or (config.eval.final and frames >= config.total_frames):
            if eval_env is None:
                eval_env = build_eval_env(config, num_envs=config.eval.num_envs,
                                          seed=config.eval.seed)
            row, result = evaluate(config, eval_env, learner, iteration, frames,
                                   time.perf_counter() - started)
            evaluations.append(row)
            final_result = result if frames >= config.total_frames else None
        if config.record_every and iteration % config.record_every == 0:
            if record_env is None:
                record_env = build_env(config, num_envs=1, seed=config.eval.seed)
            recording = record_iteration(config, record_env, learner, multipliers, iteration)
            if live is not None and recording is not None:
                live.add_recording(recording)
        if iteration % config.checkpoint_every == 0 or frames >= config.total_frames:
            batches.settle()  # the simulations as the batch collected ahead left them
            state = checkpoint_state(
                config, learner, multipliers, episodes, env, generator, batches.carry,
                ahead=batches.pending(), iteration=iteration, frames=frames,
                elapsed=time.perf_counter() - started)
            save_checkpoint(checkpoint_path, state)
            save_checkpoint(run_dir / POLICY_FILE, policy_state(state))
            if final_result is not None and on_final_evaluation is not None:
                on_final_evaluation(run_dir, config, eval_env, final_result, policy_info(state))
    bar.close()
    if live is not None:
        live.close()
    for used in (env, eval_env, record_env):
        if used is not None:
            used.close()
    lock.close()
    print(f"done: {frames} frames in {iteration} iterations; run directory: {run_dir}",
          flush=True)
    print_last_evaluation(evaluations.path, config, constraints)
    return run_dir


def learn(config: TrainConfig, env: TrainingEnv, learner: Learner,
          multipliers: dict[str, Multiplier], generator: torch.Generator,
          episodes: EpisodeAccumulator, batches: BatchSource, frames: int
          ) -> tuple[TensorDictBase, list[EpisodeStats], dict[str, float]]:
    """One iteration of learning after ``frames``: the next batch of ``rollout_steps`` steps of
    every sub-environment, the multipliers updated from the episodes that finished, the
    learner's update on the batch (with ``collect_ahead``, while the workers collect the next
    one; after the last iteration that one waits in the final checkpoint, so that a run
    resumed to more frames learns as a longer one would). Returns the batch, the finished
    episodes and the learner's diagnostics."""
    batch = batches.next()
    finished = episodes.add_batch(batch)
    update_multipliers(multipliers, finished)
    learner.prepare(frames, {name: m.value for name, m in multipliers.items()})
    env.teacher_active = learner.needs_teacher(frames + batch.numel())
    batches.prefetch()
    shape_signals(batch, config, env.config)
    losses = learner.update(batch, generator)
    return batch, finished, losses


def prepare_run_dir(config: TrainConfig, run_dir: Path, checkpoint_path: Path) -> bool:
    """Whether the run resumes from ``checkpoint_path``; clears the logs of a run killed
    before its first checkpoint, and the temporary files of writes a kill interrupted (those
    whose writer is gone: an evaluation may be writing into the run meanwhile).

    Raises:
        ConfigError: if ``run_dir`` holds a run and ``resume`` is off.
    """
    for folder in (run_dir, checkpoint_path.parent, run_dir / "recordings"):
        remove_stale_temp_files(folder)
    resuming = config.resume and checkpoint_path.exists()
    if not resuming and (run_dir / "metrics.csv").exists():
        if not config.resume:
            raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} already holds a run; pass "
                              "resume=true to continue it or choose another run_dir")
        for stale in ("metrics.csv", "eval.csv"):
            (run_dir / stale).unlink(missing_ok=True)
    return resuming


def episode_columns(finished: Sequence[EpisodeStats], constraints: Sequence[Constraint]
                    ) -> dict[str, float]:
    """The iteration's episode metrics: from the task's own spawns, and each constraint's
    metric over the episodes that started in front of an obstacle (``<metric>_encounter``)."""
    summary = summarise([e for e in finished if not e.encounter], constraints)
    encounters = summarise([e for e in finished if e.encounter], constraints)
    return {"episodes": summary.episodes, "J_R": summary.J_R, **summary.J,
            "episode_length": summary.length, "encounter_episodes": encounters.episodes,
            **{f"{metric}_encounter": value for metric, value in encounters.J.items()}}


def evaluate(config: TrainConfig, env: LaneKeepingEnv, learner: Learner, iteration: int,
             frames: int, time_s: float) -> tuple[dict[str, Any], EvaluationResult]:
    """Episodes of the sampled policy from the evaluation seed (spawns and action samples),
    as ``python -m crllk.evaluate`` plays them: the ``eval.csv`` row (with whether every
    constraint holds) and the episodes."""
    began = time.perf_counter()
    env.set_seed(config.eval.seed)
    result = run_episodes(env, learner.actor, config.eval.episodes, deterministic=False,
                          sample_seed=config.eval.seed)
    summary = result.summary
    satisfied = all(summary.J[c.metric] <= config.algo.constraints[c.name].threshold
                    for c in env.constraints)
    return {"iteration": iteration, "frames": frames, "time_s": time_s, **summary.as_row(),
            "episode_length": summary.length, "satisfied": int(satisfied),
            "evaluation_s": time.perf_counter() - began}, result


def open_live_view(config: TrainConfig, run_dir: Path, constraints: Sequence[Constraint],
                   diagnostics: Sequence[str]) -> LiveView | None:
    """The run's live view (``live``) with a plot per learner ``diagnostics``, or None; rerun
    is imported only when it is on. A live view that cannot start is a warning: training goes
    on."""
    if config.live == "none":
        return None
    from crllk.recording.live import live_url, open_live

    live, problems = open_live(config.live, config.live_port, f"crllk-live-{run_dir.resolve()}",
                               constraints, {c.name: config.algo.constraints[c.name].threshold
                                             for c in constraints}, diagnostics)
    for message in problems:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    if live is not None:
        print(f"live view: rerun --bind 127.0.0.1 --connect {live_url(config.live_port)}",
              flush=True)
    return live


def record_iteration(config: TrainConfig, env: BatchedLaneKeepingEnv, learner: Learner,
                     multipliers: dict[str, Multiplier], iteration: int) -> Path | None:
    """Records one evaluation episode of the policy's most probable action (in the training's
    own action type; a discrete run's deployed policy, its expected duties, is recorded by
    ``python -m crllk.evaluate record=true``) to
    ``<run_dir>/recordings/iteration_<iteration>.rrd`` (and the viewer of ``viewer``, if any)
    and returns its path. Files of one run share a recording id, so opened together they line
    up on the ``iteration`` timeline. A recording that fails is a warning (and None): training
    goes on."""
    from crllk.recording.recorder import record_episodes  # rerun is imported only when recording

    run_dir = config.resolved_run_dir()
    path = run_dir / "recordings" / f"iteration_{iteration:06d}.rrd"
    env.set_seed(config.eval.seed)
    try:
        report = record_episodes(env, learner.actor, 1, path, viewer=config.viewer,
                                 iteration=iteration,
                                 multipliers={c: m.value for c, m in multipliers.items()},
                                 recording_id=f"crllk-train-{run_dir.resolve()}")
    except Exception as err:  # a recording never ends a training run
        print(f"warning: recording at iteration {iteration} failed: {err}", file=sys.stderr,
              flush=True)
        return None
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    return path
