"""The training loop."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omegaconf import OmegaConf
from tqdm import tqdm

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.envs.batched import BatchedLaneKeepingEnv
from crllk.envs.episodes import EpisodeAccumulator, summarise
from crllk.errors import ConfigError
from crllk.files import atomic_write_text
from crllk.rl.lagrange import Multiplier
from crllk.rl.rollout import collect, run_episodes
from crllk.tasks.constraints import COSTS
from crllk.training.build import Learner, build_env, build_run
from crllk.training.checkpoints import checkpoint_state, load_checkpoint, restore, save_checkpoint
from crllk.training.config import TrainConfig
from crllk.training.logs import (
    EVAL_COLUMNS,
    CsvLog,
    action_columns,
    metric_columns,
    print_last_evaluation,
    progress_text,
)
from crllk.training.run_dir import SOURCE_RUN, lock_run_dir
from crllk.training.schedules import imitation_coeff, learning_rate
from crllk.training.updates import ppo_update, shape_signals, update_multipliers

if TYPE_CHECKING:
    from crllk.recording.live import LiveView


def train(config: TrainConfig) -> Path:
    """Trains (or resumes) one run; returns its directory."""
    run_dir = config.resolved_run_dir()
    checkpoint_path = run_dir / "checkpoints" / "last.pt"
    resuming = config.resume and checkpoint_path.exists()
    if not resuming and (run_dir / "metrics.csv").exists():
        if not config.resume:
            raise ConfigError(SOURCE_RUN, "run_dir", f"{run_dir} already holds a run; pass "
                              "resume=true to continue it or choose another run_dir")
        for stale in ("metrics.csv", "eval.csv"):  # killed before its first checkpoint
            (run_dir / stale).unlink(missing_ok=True)
    env, learner, multipliers, generator = build_run(config)
    lock = lock_run_dir(run_dir)
    episodes = EpisodeAccumulator(config.num_envs)
    metrics = CsvLog(run_dir / "metrics.csv", metric_columns(config.action.name))
    evaluations = CsvLog(run_dir / "eval.csv", EVAL_COLUMNS)
    eval_env = record_env = None
    iteration, frames, elapsed = 0, 0, 0.0

    if resuming:
        state = load_checkpoint(checkpoint_path)
        restore(state, learner, multipliers, episodes, env, generator)
        carry = state["carry"]
        iteration, frames, elapsed = state["iteration"], state["frames"], state["elapsed"]
        metrics.truncate_after(iteration)
        evaluations.truncate_after(iteration)
        print(f"resuming {run_dir} at iteration {iteration}, {frames} frames", flush=True)
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(run_dir / "config.yaml", OmegaConf.to_yaml(OmegaConf.structured(config)))
        carry = env.reset()
        print(f"run directory: {run_dir}", flush=True)
    live = open_live_view(config, run_dir)

    bar = tqdm(total=config.total_frames, initial=frames, unit="frame", dynamic_ncols=True,
               disable=not config.progress, file=sys.stderr)
    started = time.perf_counter() - elapsed
    while frames < config.total_frames:
        iteration_start = time.perf_counter()
        batch, carry = collect(env, learner.actor, carry, config.rollout_steps)
        finished = episodes.add_batch(batch)
        update_multipliers(multipliers, finished)
        learner.loss.set_multipliers([multipliers[c].value for c in COSTS])
        learner.loss.set_imitation_coeff(imitation_coeff(config, frames))
        for group in learner.optimizer.param_groups:
            group["lr"] = learning_rate(config, frames)
        env.teacher_active = imitation_coeff(config, frames + batch.numel()) > 0
        shape_signals(batch, config, env.config.off_road_lane_cost)
        losses = ppo_update(learner, batch, config, generator)
        iteration += 1
        frames += batch.numel()

        summary = summarise([e for e in finished if not e.encounter])
        encounters = summarise([e for e in finished if e.encounter])
        row = {"iteration": iteration, "frames": frames,
               "time_s": time.perf_counter() - started,
               "frames_per_s": batch.numel() / (time.perf_counter() - iteration_start),
               "episodes": summary.episodes, "J_R": summary.J_R, "J_clane": summary.J_clane,
               "J_coll": summary.J_coll, "episode_length": summary.length,
               "encounter_episodes": encounters.episodes, "J_coll_encounter": encounters.J_coll,
               "lambda_lane": multipliers["lane"].value,
               "lambda_collision": multipliers["collision"].value,
               **losses, **action_columns(batch, config.action.name)}
        metrics.append(row)
        if live is not None:
            live.log_iteration(row)
        bar.update(batch.numel())
        bar.set_postfix_str(progress_text(row), refresh=False)

        if config.eval.every and (iteration % config.eval.every == 0
                                  or frames >= config.total_frames):
            if eval_env is None:
                eval_env = build_env(config, num_envs=config.eval.num_envs, seed=config.eval.seed)
            evaluations.append(evaluate(config, eval_env, learner, iteration, frames,
                                        time.perf_counter() - started))
        if config.record_every and iteration % config.record_every == 0:
            if record_env is None:
                record_env = build_env(config, num_envs=1, seed=config.eval.seed)
            recording = record_iteration(config, record_env, learner, multipliers, iteration)
            if live is not None and recording is not None:
                live.add_recording(recording)
        if iteration % config.checkpoint_every == 0 or frames >= config.total_frames:
            save_checkpoint(checkpoint_path, checkpoint_state(
                config, learner, multipliers, episodes, env, generator, carry,
                iteration=iteration, frames=frames, elapsed=time.perf_counter() - started))
    bar.close()
    if live is not None:
        live.close()
    env.close()
    for extra_env in (eval_env, record_env):
        if extra_env is not None:
            extra_env.close()
    lock.close()
    print(f"done: {frames} frames in {iteration} iterations; run directory: {run_dir}",
          flush=True)
    print_last_evaluation(evaluations.path, config)
    return run_dir


def evaluate(config: TrainConfig, env: BatchedLaneKeepingEnv, learner: Learner, iteration: int,
             frames: int, time_s: float) -> dict[str, Any]:
    """Episodes of the sampled policy from the evaluation seed (spawns and action samples),
    as ``python -m crllk.evaluate`` plays them; whether both constraints hold."""
    began = time.perf_counter()
    env.set_seed(config.eval.seed)
    summary = run_episodes(env, learner.actor, config.eval.episodes, deterministic=False,
                           sample_seed=config.eval.seed).summary
    satisfied = (summary.J_clane <= config.algo.lane.threshold
                 and summary.J_coll <= config.algo.collision.threshold)
    return {"iteration": iteration, "frames": frames, "time_s": time_s, **summary.as_row(),
            "episode_length": summary.length, "satisfied": int(satisfied),
            "evaluation_s": time.perf_counter() - began}


def open_live_view(config: TrainConfig, run_dir: Path) -> LiveView | None:
    """The run's live view (``live``), or None; rerun is imported only when it is on. A live
    view that cannot start is a warning: training goes on."""
    if config.live == "none":
        return None
    from crllk.recording.live import live_url, open_live

    live, problems = open_live(config.live, config.live_port, f"crllk-live-{run_dir.resolve()}",
                               {"J_clane": config.algo.lane.threshold,
                                "J_coll": config.algo.collision.threshold})
    for message in problems:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    if live is not None:
        print(f"live view: rerun --bind 127.0.0.1 --connect {live_url(config.live_port)}",
              flush=True)
    return live


def record_iteration(config: TrainConfig, env: BatchedLaneKeepingEnv, learner: Learner,
                     multipliers: dict[str, Multiplier], iteration: int) -> Path | None:
    """Records one deterministic evaluation episode to
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
