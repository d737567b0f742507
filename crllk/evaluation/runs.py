"""Evaluating trained runs and the scripted drivers, and recording them."""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from crllk.config import TrainConfig, algo_thresholds
from crllk.envs.batched import make_env
from crllk.envs.parallel import LaneKeepingEnv
from crllk.errors import ConfigError
from crllk.evaluation import community
from crllk.evaluation.report import result_document
from crllk.files import atomic_write_text, output_lock
from crllk.protocol import VALIDATION_SEED
from crllk.rl.import_probes import settle_import_probes
from crllk.rl.rollout import EvaluationResult, run_episodes
from crllk.tasks.config import load_task_config
from crllk.tasks.follower import FollowerGains, FollowerPolicy
from crllk.training.build import build_env, build_eval_env
from crllk.training.run_dir import EVAL_RECORDING
from crllk.training.runs import (
    EVAL_FILE,
    deployed_form,
    load_actor,
    load_run_config,
    played_action,
)

EVALUATION_ENVS = 10
"""Simulations of an evaluation (episode k runs in simulation k mod this): ``crllk.evaluate``'s
default and the trainer's (``eval.num_envs``)."""


@dataclass
class EvaluationConfig(TrainConfig):
    """A run's configuration with its task's settings changed for one evaluation
    (``evaluation_overrides``). The env is built from :meth:`task_overrides`, so the changes
    apply to a run of a named task and of a task file (``task=<file>.yaml``) alike: a task file
    run keeps its settings in the file, and in ``task`` only the default task's, which its env
    never reads."""

    evaluation_overrides: dict[str, Any] = field(default_factory=dict)

    def task_overrides(self) -> dict[str, Any]:
        merged = OmegaConf.merge(super().task_overrides(), self.evaluation_overrides)
        return OmegaConf.to_container(merged)  # type: ignore[return-value]


UNCHANGEABLE_TASK_SETTINGS = ("map", "name")
"""Task settings an evaluation cannot change: the run's map is its task's."""


def evaluation_config(run_dir: str | Path, overrides: Mapping[str, Any] | None = None,
                      workers: int | None = None) -> TrainConfig:
    """The run's configuration for an evaluation with its task's settings changed by
    ``overrides`` (checked here, before any work) and in ``workers`` processes (default: the
    run's).

    Raises:
        ConfigError: for a run that cannot be read, or ``<run_dir>: overrides.<key>:
            <problem>`` for a change the task refuses.
    """
    config = load_run_config(run_dir)
    if workers is not None:
        config.workers = workers
    if not overrides:
        return config
    for key in UNCHANGEABLE_TASK_SETTINGS:
        if key in overrides:
            raise ConfigError(run_dir, f"overrides.{key}", "cannot be changed for an "
                              "evaluation (the run's task keeps its map and name)")
    values = {f.name: getattr(config, f.name) for f in fields(config)}
    changed = EvaluationConfig(**values, evaluation_overrides=dict(overrides))
    check_task_overrides(changed.task_source(), changed.task_overrides(), overrides, run_dir)
    return changed


def check_task_overrides(task: str | Path, settings: Mapping[str, Any],
                         overrides: Mapping[str, Any], source: str | Path) -> None:
    """Reads ``task`` with ``settings`` (its changed settings, ``overrides`` among them).

    Raises:
        ConfigError: ``<source>: overrides.<key>: <problem>`` for a change the task refuses;
            the task's own error for anything else.
    """
    try:
        load_task_config(task, settings)
    except ConfigError as err:
        if err.field.split(".")[0].split("[")[0] not in overrides:
            raise
        raise ConfigError(source, f"overrides.{err.field}", err.problem) from None


def result_path(run_dir: str | Path, name: str | None = None) -> Path:
    """Where an evaluation of the run goes: ``<run_dir>/eval.json`` or ``<name>.json``."""
    return Path(run_dir) / (EVAL_FILE if name is None else f"{name}.json")


def evaluate_run(run_dir: str | Path, *, episodes: int, deterministic: bool = False,
                 seed: int | None = None, num_envs: int = EVALUATION_ENVS,
                 overrides: Mapping[str, Any] | None = None,
                 name: str | None = None, workers: int | None = None) -> dict[str, Any]:
    """Plays the run's last policy and writes ``<run_dir>/eval.json`` (or ``<name>.json``);
    returns its content. ``overrides`` change the run's task settings for this evaluation
    (e.g. ``{"randomize": {...}}`` or ``{"camera": {"robot_frames": True}}``); the
    simulations step in the run's ``workers`` processes, or in ``workers`` (the same
    episodes either way).

    The result file's lock (:func:`crllk.files.output_lock`) is held from before the policy is
    loaded until the file is written: a second evaluation into the same file waits for this
    one, then evaluates the policy as it is by then; evaluations into other files, and the
    trainer, go on meanwhile (:mod:`crllk.training.run_dir`).
    """
    settle_import_probes()
    config = evaluation_config(run_dir, overrides, workers)
    seed = config.eval.seed if seed is None else seed
    with output_lock(result_path(run_dir, name)):
        env = build_eval_env(config, num_envs=num_envs, seed=seed,
                             action=played_action(config, deterministic))
        try:
            actor, info = load_actor(run_dir, env, deployed=deterministic)
            result = run_episodes(env, actor, episodes, deterministic=deterministic,
                                  sample_seed=seed)
        finally:
            env.close()
        return write_evaluation(run_dir, config, env, result, info,
                                settings=policy_settings(config, deterministic, {
                                    "episodes": episodes, "seed": seed, "num_envs": num_envs}),
                                overrides=overrides, name=name)


def policy_settings(config: TrainConfig, deterministic: bool,
                    settings: Mapping[str, Any]) -> dict[str, Any]:
    """An evaluation's ``settings`` with how the policy acted: ``deterministic``, and for the
    deployed policy its form (``deployed``: :func:`crllk.training.runs.deployed_form`)."""
    played = {"deterministic": deterministic}
    if deterministic:
        played["deployed"] = deployed_form(config.action.name)
    return {**settings, **played}


def write_evaluation(run_dir: str | Path, config: TrainConfig, env: LaneKeepingEnv,
                     result: EvaluationResult, info: dict[str, Any], *,
                     settings: dict[str, Any], overrides: Mapping[str, Any] | None = None,
                     name: str | None = None,
                     extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Writes the evaluation document of a run's episodes ``result`` (played in ``env`` with
    ``settings``) to ``<run_dir>/eval.json`` (or ``<name>.json``) and returns it; ``info``
    holds the policy's counters and multipliers, ``extra`` more sections of the document."""
    source = {"run_dir": str(run_dir), "task": config.task_name, "algo": config.algo.name,
              "action": config.action.name, "obs": config.obs.name, "train_seed": config.seed,
              **info}
    settings = dict(settings)
    if overrides:
        settings["task_overrides"] = dict(overrides)
    thresholds = {c.name: config.algo.constraints[c.name].threshold
                  for c in env.config.constraints}
    document = result_document(result, env.action_type, thresholds=thresholds,
                               settings=settings, source=source,
                               objects=env.config.map.objects,
                               scales=community.Scales.of(env.config))
    document.update(extra or {})
    atomic_write_text(result_path(run_dir, name), json.dumps(document, indent=1) + "\n")
    return document


def write_final_evaluation(run_dir: Path, config: TrainConfig, env: LaneKeepingEnv,
                           result: EvaluationResult, info: dict[str, Any]) -> None:
    """``eval.json`` from the evaluation the trainer makes at the end of training
    (``eval.episodes`` sampled episodes from ``eval.seed``): what ``python -m crllk.evaluate
    run=DIR`` would write of the final policy with those settings, without playing the
    episodes again. Written under the file's lock: an evaluation of the run writing it
    meanwhile finishes first."""
    with output_lock(result_path(run_dir)):
        write_evaluation(run_dir, config, env, result, info,
                         settings={"episodes": config.eval.episodes, "seed": config.eval.seed,
                                   "num_envs": config.eval.num_envs, "deterministic": False})


def evaluate_follower(task: str | Path, *, episodes: int, seed: int = VALIDATION_SEED,
                      num_envs: int = EVALUATION_ENVS, thresholds: dict[str, float] | None = None,
                      avoid_obstacles: bool = False, action: str = "duty",
                      margin: float = FollowerGains.avoid_margin,
                      overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The scripted lane follower through the same episodes and metrics as a run; with
    ``avoid_obstacles`` the training teacher, which swerves around obstacles ``margin`` (m)
    clear (``teacher.margin`` of a run). ``action``: the
    action type it answers in (its wheel duties, or the nearest action of a policy's type, as
    the teacher answers during training). ``overrides`` change the task's settings."""
    env = make_env(task, num_envs=num_envs, observation="state", action=action, seed=seed,
                   overrides=dict(overrides) if overrides else None, lane_pose=True)
    try:
        policy = FollowerPolicy(env, avoid_obstacles=avoid_obstacles, margin=margin)
        result = run_episodes(env, policy, episodes)
    finally:
        env.close()
    objects = env.config.map.objects
    return result_document(
        result, action, thresholds=thresholds or algo_thresholds(),
        settings={"episodes": episodes, "seed": seed, "num_envs": num_envs,
                  "deterministic": True, **({"margin": margin} if avoid_obstacles else {}),
                  **({"task_overrides": dict(overrides)} if overrides else {})},
        source={"task": str(task), "algo": "teacher" if avoid_obstacles else "follower",
                "action": action, "obs": "state"},
        objects=objects, scales=community.Scales.of(env.config))


def record_run(run_dir: str | Path, *, episodes: int, seed: int | None = None,
               deterministic: bool = True, viewer: str = "none",
               overrides: Mapping[str, Any] | None = None) -> Path:
    """Records ``episodes`` evaluation episodes of the run's policy (from the same spawn seed as
    :func:`evaluate_run`, with the same task ``overrides``) to ``<run_dir>/recordings/eval.rrd``
    (under its lock, as :func:`evaluate_run` writes); returns the path.

    Raises:
        crllk.errors.RecordingError: if the file cannot be written (a ConfigError).
    """
    from crllk.recording.recorder import record_episodes

    config = evaluation_config(run_dir, overrides)
    path = Path(run_dir) / EVAL_RECORDING
    with output_lock(path):
        env = build_env(config, num_envs=1, seed=config.eval.seed if seed is None else seed,
                        action=played_action(config, deterministic))
        try:
            actor, info = load_actor(run_dir, env, deployed=deterministic)
            report = record_episodes(env, actor, episodes, path, deterministic=deterministic,
                                     viewer=viewer, multipliers=info["multipliers"],
                                     recording_id=f"crllk-eval-{Path(run_dir).resolve()}")
        finally:
            env.close()
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    print(f"recording: {path} ({report.episodes} episodes, {report.steps} steps)", flush=True)
    return path
