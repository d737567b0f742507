"""Evaluating trained runs and the scripted drivers, and recording them."""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from crllk.envs.batched import make_env
from crllk.envs.parallel import LaneKeepingEnv
from crllk.evaluation.report import result_document
from crllk.files import atomic_write_text
from crllk.protocol import VALIDATION_SEED
from crllk.rl.import_probes import settle_import_probes
from crllk.rl.rollout import EvaluationResult, run_episodes
from crllk.tasks.follower import FollowerGains, FollowerPolicy
from crllk.training.build import build_env, build_eval_env
from crllk.training.config import TrainConfig, algo_thresholds
from crllk.training.run_dir import EVAL_RECORDING
from crllk.training.runs import EVAL_FILE, load_actor, load_run_config

EVALUATION_ENVS = 10
"""Simulations of an evaluation (episode k runs in simulation k mod this): ``crllk.evaluate``'s
default and the trainer's (``eval.num_envs``)."""


def evaluate_run(run_dir: str | Path, *, episodes: int, deterministic: bool = False,
                 seed: int | None = None, num_envs: int = EVALUATION_ENVS,
                 overrides: Mapping[str, Any] | None = None,
                 name: str | None = None, workers: int | None = None) -> dict[str, Any]:
    """Plays the run's last policy and writes ``<run_dir>/eval.json`` (or ``<name>.json``);
    returns its content. ``overrides`` change the run's task settings for this evaluation
    (e.g. ``{"randomize": {...}}`` or ``{"camera": {"robot_frames": True}}``); the
    simulations step in the run's ``workers`` processes, or in ``workers`` (the same
    episodes either way)."""
    settle_import_probes()
    config = load_run_config(run_dir)
    if workers is not None:
        config.workers = workers
    if overrides:
        config.task = OmegaConf.to_container(OmegaConf.merge(config.task, dict(overrides)))
    seed = config.eval.seed if seed is None else seed
    env = build_eval_env(config, num_envs=num_envs, seed=seed)
    try:
        actor, info = load_actor(run_dir, env)
        result = run_episodes(env, actor, episodes, deterministic=deterministic,
                              sample_seed=seed)
    finally:
        env.close()
    return write_evaluation(run_dir, config, env, result, info,
                            settings={"episodes": episodes, "seed": seed, "num_envs": num_envs,
                                      "deterministic": deterministic},
                            overrides=overrides, name=name)


def write_evaluation(run_dir: str | Path, config: TrainConfig, env: LaneKeepingEnv,
                     result: EvaluationResult, info: dict[str, Any], *,
                     settings: dict[str, Any], overrides: Mapping[str, Any] | None = None,
                     name: str | None = None) -> dict[str, Any]:
    """Writes the evaluation document of a run's episodes ``result`` (played in ``env`` with
    ``settings``) to ``<run_dir>/eval.json`` (or ``<name>.json``) and returns it; ``info``
    holds the policy's counters and multipliers."""
    source = {"run_dir": str(run_dir), "task": config.task_name, "algo": config.algo.name,
              "action": config.action.name, "obs": config.obs.name, "train_seed": config.seed,
              **info}
    settings = dict(settings)
    if overrides:
        settings["task_overrides"] = dict(overrides)
    thresholds = {c.name: config.algo.constraints[c.name].threshold
                  for c in env.config.constraints}
    document = result_document(result, config.action.name, thresholds=thresholds,
                               settings=settings, source=source,
                               objects=env.config.map.objects)
    out = Path(run_dir) / (EVAL_FILE if name is None else f"{name}.json")
    atomic_write_text(out, json.dumps(document, indent=1) + "\n")
    return document


def write_final_evaluation(run_dir: Path, config: TrainConfig, env: LaneKeepingEnv,
                           result: EvaluationResult, info: dict[str, Any]) -> None:
    """``eval.json`` from the evaluation the trainer makes at the end of training
    (``eval.episodes`` sampled episodes from ``eval.seed``): what ``python -m crllk.evaluate
    run=DIR`` would write of the final policy with those settings, without playing the
    episodes again."""
    write_evaluation(run_dir, config, env, result, info,
                     settings={"episodes": config.eval.episodes, "seed": config.eval.seed,
                               "num_envs": config.eval.num_envs, "deterministic": False})


def evaluate_follower(task: str | Path, *, episodes: int, seed: int = VALIDATION_SEED,
                      num_envs: int = EVALUATION_ENVS, thresholds: dict[str, float] | None = None,
                      avoid_obstacles: bool = False, action: str = "duty",
                      margin: float = FollowerGains.avoid_margin) -> dict[str, Any]:
    """The scripted lane follower through the same episodes and metrics as a run; with
    ``avoid_obstacles`` the training teacher, which swerves around obstacles ``margin`` (m)
    clear (``teacher.margin`` of a run). ``action``: the
    action type it answers in (its wheel duties, or the nearest action of a policy's type, as
    the teacher answers during training)."""
    env = make_env(task, num_envs=num_envs, observation="state", action=action, seed=seed)
    try:
        policy = FollowerPolicy(env, avoid_obstacles=avoid_obstacles, margin=margin)
        result = run_episodes(env, policy, episodes)
    finally:
        env.close()
    objects = env.config.map.objects
    return result_document(
        result, action, thresholds=thresholds or algo_thresholds(),
        settings={"episodes": episodes, "seed": seed, "num_envs": num_envs,
                  "deterministic": True, **({"margin": margin} if avoid_obstacles else {})},
        source={"task": str(task), "algo": "teacher" if avoid_obstacles else "follower",
                "action": action, "obs": "state"},
        objects=objects)


def record_run(run_dir: str | Path, *, episodes: int, seed: int | None = None,
               deterministic: bool = True, viewer: str = "none") -> Path:
    """Records ``episodes`` evaluation episodes of the run's policy (from the same spawn seed as
    :func:`evaluate_run`) to ``<run_dir>/recordings/eval.rrd``; returns the path.

    Raises:
        crllk.errors.RecordingError: if the file cannot be written (a ConfigError).
    """
    from crllk.recording.recorder import record_episodes

    config = load_run_config(run_dir)
    env = build_env(config, num_envs=1, seed=config.eval.seed if seed is None else seed)
    path = Path(run_dir) / EVAL_RECORDING
    try:
        actor, info = load_actor(run_dir, env)
        report = record_episodes(env, actor, episodes, path, deterministic=deterministic,
                                 viewer=viewer, multipliers=info["multipliers"],
                                 recording_id=f"crllk-eval-{Path(run_dir).resolve()}")
    finally:
        env.close()
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    print(f"recording: {path} ({report.episodes} episodes, {report.steps} steps)", flush=True)
    return path
