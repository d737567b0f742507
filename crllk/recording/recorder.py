"""Rerun recordings of lane-keeping episodes: the map, the robot, its camera and every signal.

    python -m crllk.record --task obstacle_loop --episodes 1 --out rec.rrd [--viewer spawn]

:func:`record_episodes` plays episodes of sub-environment 0 of a
:class:`~crllk.envs.batched.BatchedLaneKeepingEnv` and logs them to a ``.rrd`` file and/or a
live viewer. The rerun package is imported here and by the modules built on it
(:mod:`crllk.recording.live`, :mod:`crllk.screenshots`): the static scene comes from
:mod:`crllk.recording.scene` (the map's lane and marking polylines from
:mod:`crllk.maps.markings`, numpy), the per-step logging from :mod:`crllk.recording.steps`,
the sinks (checking the path, opening file and viewer sinks, reading a file back) from
:mod:`crllk.recording.sinks` and the viewer process (probing the port, running the ``rerun``
executable) from :mod:`crllk.recording.viewer`.

Timelines: ``step`` (control steps since the recording began), ``sim_time`` (simulated seconds
since the recording began, ``step`` x control timestep), ``episode`` (index of the episode in
the recording) and, when given, ``iteration`` (the training iteration: one value per file, so
that files of one training run sharing a ``recording_id`` line up on it when opened together).

Entity paths (:func:`~crllk.recording.entities.entity_paths`, plus
:data:`~crllk.recording.entities.ACTION_ENTITY_PATHS` for the env's action type and
``lagrange/<name>`` per multiplier): the map under ``world/map`` (static), the robot's pose
``world/robot`` (one row per step) with its labelled footprint, heading arrow and camera (a
pinhole in pixels carrying the camera image), the trail of the current episode
``world/trail``, per-step scalars ``reward/...``, ``cost/...``, ``lane_pose/...``,
``action/...``, ``lagrange/...``, per-episode scalars ``episode/...`` and the text events
``events`` (episode starts, ends and their reasons).
Per-step scalars are sent in columns every 30 steps and at each episode's end. The layout
(:func:`make_blueprint`) travels with the recording.

Viewers listen on 127.0.0.1 only. ``viewer="spawn"`` reuses a viewer already answering on
``127.0.0.1:VIEWER_PORT`` (start one with ``rerun --bind 127.0.0.1`` to watch a training run
across recordings) or starts ``rerun --bind 127.0.0.1``; ``viewer="serve"`` hosts a gRPC server
for ``rerun --bind 127.0.0.1 --connect`` while the recording runs (without ``--bind``, even a
connecting viewer listens on 0.0.0.0). A viewer that cannot be reached, or that goes away, is
a warning in :attr:`RecordingReport.warnings` (a viewer that cannot be spawned, once per
process): the file is written all the same. A path that cannot be written raises
:class:`RecordingError` before the first step.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr
import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.envs.batched import TERMINATIONS
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats
from crllk.errors import RecordingError
from crllk.files import WriteError, atomic_output
from crllk.recording.scene import focal_length
from crllk.recording.sinks import (
    VIEWERS,
    check_writable,
    flush_failed,
    open_sinks,
    read_recording,
)
from crllk.recording.steps import Clock, Step, StepRecorder
from crllk.recording.viewer import spawn_viewer
from crllk.rl.rollout import Rollout

if TYPE_CHECKING:
    from crllk.envs.batched import BatchedLaneKeepingEnv

Policy = Callable[[TensorDictBase], TensorDictBase]
"""Writes ``"action"`` into the tensordict it is given (a TensorDict module)."""


@dataclass(frozen=True)
class RecordingReport:
    """What :func:`record_episodes` did."""

    path: Path | None
    """The ``.rrd`` file written (None: live viewer only)."""
    steps: int
    """Control steps logged (one ``world/robot`` row each)."""
    episodes: int
    """Episodes of sub-environment 0 played and logged."""
    logging_seconds: float
    """Time spent inside rerun calls, sinks, static map and final flush included (s)."""
    render_seconds: float = 0.0
    """Time spent rendering camera images for state observations (s)."""
    warnings: tuple[str, ...] = ()
    """Problems that did not stop the recording (an unreachable viewer)."""
    episode_stats: tuple[EpisodeStats, ...] = ()
    """The logged episodes' statistics, as :class:`~crllk.envs.episodes.EpisodeAccumulator` sums."""
    viewer_url: str | None = None
    """Where a live viewer received or served the recording."""


# ----- playing ----------------------------------------------------------------------------
def _camera_image(env: BatchedLaneKeepingEnv, nxt: TensorDictBase, clock: Clock) -> np.ndarray:
    """Sub-environment 0's camera image: the observation, or rendered for state envs."""
    if env.observation_type == "pixels":
        return nxt["pixels"][0].numpy()
    cam = env.config.camera
    with clock:
        return env.physics[0].render_camera(cam.height, cam.width, cam.supersample)


def _read_step(env: BatchedLaneKeepingEnv, stepped: TensorDictBase, clock: Clock) -> Step:
    nxt, outcome = stepped["next"], env.tasks[0].outcome
    return Step(pose=env.physics[0].pose(), image=_camera_image(env, nxt, clock),
                action=np.atleast_1d(stepped["action"][0].detach().cpu().numpy()).astype(
                    np.float64),
                reward=float(nxt["reward"][0]),
                costs={c.name: float(nxt[c.cost_key][0]) for c in env.constraints},
                lateral=outcome.lateral,
                heading_error=outcome.heading_error,
                movers=tuple(env.tasks[0].mover_boxes))


def _play(env: BatchedLaneKeepingEnv, policy: Policy, episodes: int, recorder: StepRecorder,
          render_clock: Clock) -> list[EpisodeStats]:
    """Step ``env`` until sub-environment 0 finished ``episodes`` episodes, logging it."""
    accumulator = EpisodeAccumulator(1, env.constraints)
    finished: list[EpisodeStats] = []

    def log(stepped: TensorDictBase) -> None:
        """Sub-environment 0's step, before a finished episode resets."""
        step = _read_step(env, stepped, render_clock)
        with recorder.clock:
            recorder.log_step(step)
        ended = accumulator.add_transition(stepped["next"][:1])
        if ended:
            termination = TERMINATIONS[int(stepped["next", "termination"][0])]
            with recorder.clock:
                recorder.end_episode(ended[0], termination)
            finished.append(ended[0])

    rollout = Rollout(env, policy)
    with recorder.clock:
        recorder.start_episode(env.physics[0].pose())
    while len(finished) < episodes:
        before = len(finished)
        rollout.step(log)
        if before < len(finished) < episodes:
            with recorder.clock:  # the next episode's spawn
                recorder.start_episode(env.physics[0].pose())
    return finished


def record_episodes(env: BatchedLaneKeepingEnv, policy: Policy, episodes: int,
                    path: str | Path | None, *, deterministic: bool = True,
                    viewer: str = "none", iteration: int | None = None,
                    multipliers: dict[str, float] | None = None,
                    recording_id: str | None = None,
                    application_id: str = "crllk") -> RecordingReport:
    """Play ``episodes`` episodes of sub-environment 0 of ``env`` from a fresh reset and record
    them (the other sub-environments step along, unrecorded).

    Args:
        env: a :class:`crllk.envs.batched.BatchedLaneKeepingEnv` (any batch size).
        policy: writes ``"action"`` into the tensordict it is given.
        episodes: episodes of sub-environment 0 to play and log.
        path: the ``.rrd`` file to write (its directory is created); None: viewer only.
        deterministic: take the policy's deterministic action instead of sampling (a run's
            deployed policy, its expected duties or expected action, never samples).
        viewer: ``"none"`` (file only), ``"spawn"`` (start or reuse a native viewer on
            127.0.0.1:``VIEWER_PORT``) or ``"serve"`` (a gRPC server on 127.0.0.1 for
            ``rerun --bind 127.0.0.1 --connect``, alive while recording).
        iteration: the training iteration, logged on the ``iteration`` timeline.
        multipliers: Lagrange multipliers by constraint name (``{"lane": .., "collision":
            ..}``), logged as ``lagrange/<name>`` every step.
        recording_id: share one id between the files of a run to merge them in the viewer.
        application_id: the rerun application (viewers keep one blueprint per application).

    Raises:
        RecordingError: before stepping, when ``path`` cannot be written.
        ValueError: for a bad ``viewer`` or ``episodes``, or with neither path nor viewer.
    """
    _check_arguments(episodes, path, viewer)
    file = check_writable(path) if path is not None else None
    try:
        with atomic_output(file) if file is not None else nullcontext() as written:
            return _record(env, policy, episodes, file, written, deterministic=deterministic,
                           viewer=viewer, iteration=iteration, multipliers=multipliers,
                           recording_id=recording_id, application_id=application_id)
    except WriteError as err:
        raise RecordingError(file or "", err.strerror) from None


def _record(env: BatchedLaneKeepingEnv, policy: Policy, episodes: int, file: Path | None,
            written: Path | None, *, deterministic: bool, viewer: str, iteration: int | None,
            multipliers: dict[str, float] | None, recording_id: str | None,
            application_id: str) -> RecordingReport:
    """:func:`record_episodes`, with rerun's file sink writing ``written`` (a temporary path,
    renamed to ``file`` afterwards)."""
    problems: list[str] = []
    sinks, url = open_sinks(written, file, viewer, problems)
    if not sinks:
        return RecordingReport(None, 0, 0, 0.0, warnings=tuple(problems))
    recorder = StepRecorder(rr.RecordingStream(application_id, recording_id=recording_id),
                            env.config.control_timestep, env.action_type, env.constraints,
                            iteration, multipliers)
    render_clock = Clock()
    exploration = ExplorationType.DETERMINISTIC if deterministic else ExplorationType.RANDOM
    try:
        with recorder.clock:
            recorder.rec.set_sinks(*sinks, default_blueprint=recorder.blueprint())
            recorder.log_static(env.config.map, env.physics[0], env.config.camera)
        with torch.no_grad(), set_exploration_type(exploration):
            stats = _play(env, policy, episodes, recorder, render_clock)
    finally:
        with recorder.clock:
            problem = recorder.finish()
    if problem:
        flush_failed(problem, file, viewer, problems)
    return RecordingReport(file, recorder.steps, len(stats), recorder.clock.seconds,
                           render_clock.seconds, tuple(problems), tuple(stats), url)


def _check_arguments(episodes: int, path: str | Path | None, viewer: str) -> None:
    if viewer not in VIEWERS:
        raise ValueError(f"viewer must be one of {VIEWERS}, got {viewer!r}")
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if path is None and viewer == "none":
        raise ValueError("nothing to record to: give a path or a viewer")


__all__ = ["VIEWERS", "RecordingError", "RecordingReport", "check_writable", "focal_length",
           "read_recording", "record_episodes", "spawn_viewer"]
