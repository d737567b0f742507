"""One recording's stream, step by step: the static scene once, then every control step of
sub-environment 0 (pose, trail, camera image, scalars) and every episode's start and end.

Timelines: ``step`` (control steps since the recording began), ``sim_time`` (``step`` x control
timestep), ``episode`` and, when given, ``iteration``. Per-step scalars are sent in columns
every :data:`_SCALAR_BATCH` steps and at each episode's end.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from crllk.envs.episodes import EpisodeStats
from crllk.maps import DuckietownMap, MapObject
from crllk.maps.markings import LANE_HEIGHT
from crllk.recording.blueprint import episode_ranges, make_blueprint
from crllk.recording.entities import (
    ACTION_ENTITY_PATHS,
    EPISODE_DISTANCE,
    EPISODE_LENGTH,
    EVENTS,
    HEADING_ERROR,
    IMAGE,
    LAGRANGE_PREFIX,
    LATERAL,
    MOVERS,
    REWARD,
    ROBOT,
    TRAIL,
    cost_path,
    episode_path,
)
from crllk.recording.scene import boxes, log_scene, log_series_styles
from crllk.recording.sinks import FLUSH_TIMEOUT_S
from crllk.sim import constants as C
from crllk.sim.physics import Physics
from crllk.tasks.config import CameraConfig
from crllk.tasks.constraints import Constraint

_SCALAR_BATCH = 30
"""Per-step scalars are sent every this many steps (1 s of simulation at 30 Hz) and at the end
of every episode."""


@dataclass
class Clock:
    """Accumulates the seconds spent inside ``with clock:`` blocks."""

    seconds: float = 0.0
    _start: float = field(default=0.0, repr=False)

    def __enter__(self) -> Clock:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds += time.perf_counter() - self._start


@dataclass
class Step:
    """The signals of sub-environment 0 after one control step."""

    pose: tuple[float, float, float]
    image: np.ndarray
    action: np.ndarray
    reward: float
    costs: dict[str, float]
    """Per-step cost by constraint name."""
    lateral: float
    heading_error: float
    movers: tuple[MapObject, ...] = ()
    """The task's moving agents' boxes (none without traffic)."""


class ScalarColumns:
    """Per-step scalars buffered and sent as columns (``send_columns``), which costs a tenth
    of logging them one by one."""

    def __init__(self, iteration: int | None) -> None:
        self.iteration = iteration
        self.times: dict[str, list[float]] = {"step": [], "sim_time": [], "episode": []}
        self.values: dict[str, list[float]] = {}

    def __len__(self) -> int:
        return len(self.times["step"])

    def add(self, step: int, sim_time: float, episode: int, values: dict[str, float]) -> None:
        for name, value in (("step", step), ("sim_time", sim_time), ("episode", episode)):
            self.times[name].append(value)
        for path, value in values.items():
            self.values.setdefault(path, []).append(float(value))

    def send(self, rec: rr.RecordingStream) -> None:
        """Send and clear the buffered rows."""
        if not len(self):
            return
        indexes = [rr.TimeColumn("step", sequence=self.times["step"]),
                   rr.TimeColumn("sim_time", duration=self.times["sim_time"]),
                   rr.TimeColumn("episode", sequence=self.times["episode"])]
        if self.iteration is not None:
            indexes.append(rr.TimeColumn("iteration", sequence=[self.iteration] * len(self)))
        for path, values in self.values.items():
            rec.send_columns(path, indexes=indexes, columns=rr.Scalars.columns(scalars=values))
        self.times = {name: [] for name in self.times}
        self.values = {}


class StepRecorder:
    """Logs one recording's map, steps and episode boundaries to a rerun stream."""

    def __init__(self, rec: rr.RecordingStream, control_timestep: float, action_type: str,
                 constraints: Sequence[Constraint], iteration: int | None,
                 multipliers: dict[str, float] | None) -> None:
        self.rec = rec
        self.constraints = tuple(constraints)
        self.dt = control_timestep
        self.action_type = action_type
        self.action_paths = ACTION_ENTITY_PATHS[action_type]
        self.iteration = iteration
        self.multipliers = {LAGRANGE_PREFIX + name: float(value)
                            for name, value in (multipliers or {}).items()}
        self.steps = 0
        self.episode = 0
        self.trail: list[tuple[float, float, float]] = []
        self.scalars = ScalarColumns(iteration)
        self.clock = Clock()
        self.episode_stats: list[EpisodeStats] = []

    def blueprint(self) -> rrb.Blueprint:
        """The layout for this recording's action type, multipliers and episodes so far."""
        return make_blueprint(self.action_type, self.constraints,
                              [path.removeprefix(LAGRANGE_PREFIX) for path in self.multipliers],
                              episode_ranges(self.episode_stats) if self.episode_stats else None)

    def log_static(self, dmap: DuckietownMap, physics: Physics, camera: CameraConfig) -> None:
        """The map, the robot's footprint and camera, and the series' names and colours."""
        log_scene(self.rec, dmap, physics, camera)
        log_series_styles(self.rec, self.constraints, self.multipliers, self.action_paths)

    def _set_time(self) -> None:
        self.rec.set_time("step", sequence=self.steps)
        self.rec.set_time("sim_time", duration=self.steps * self.dt)
        self.rec.set_time("episode", sequence=self.episode)
        if self.iteration is not None:
            self.rec.set_time("iteration", sequence=self.iteration)

    def start_episode(self, pose: tuple[float, float, float]) -> None:
        """An episode begins at ``pose`` (its spawn): clear the trail, log the event."""
        self.trail = [(pose[0], pose[1], LANE_HEIGHT)]
        self._set_time()
        x, y, yaw = pose
        self.rec.log(EVENTS, rr.TextLog(f"episode {self.episode} starts at x {x:.3f} m, "
                                        f"y {y:.3f} m, yaw {yaw:.3f} rad", level="INFO"))

    def log_step(self, step: Step) -> None:
        """One control step: pose, trail and camera image now, the scalars in batches."""
        rec = self.rec
        self.steps += 1
        self._set_time()
        x, y, yaw = step.pose
        self.trail.append((x, y, LANE_HEIGHT))
        rec.log(ROBOT, rr.Transform3D(translation=(x, y, C.WHEEL_RADIUS), quaternion=rr.Quaternion(
            xyzw=[0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])))
        rec.log(TRAIL, rr.LineStrips3D([self.trail]))
        rec.log(IMAGE, rr.Image(step.image))
        if step.movers:
            rec.log(MOVERS, boxes(step.movers))
        values = {REWARD: step.reward,
                  **{cost_path(name): value for name, value in step.costs.items()},
                  LATERAL: step.lateral,
                  HEADING_ERROR: step.heading_error,
                  **dict(zip(self.action_paths, step.action.tolist(), strict=True)),
                  **self.multipliers}
        self.scalars.add(self.steps, self.steps * self.dt, self.episode, values)
        if len(self.scalars) >= _SCALAR_BATCH:
            self.scalars.send(rec)

    def end_episode(self, stats: EpisodeStats, termination: str | None) -> None:
        """An episode ended (at the last logged step): its reason and statistics."""
        self.scalars.send(self.rec)
        reason = termination or "time limit"
        self.rec.log(EVENTS, rr.TextLog(
            f"episode {self.episode} ends ({reason}) after {stats.length} steps: "
            f"distance {stats.distance:.3f} m, "
            + ", ".join(f"{c.name} {stats.costs[c.name]:.3g} ({c.aggregate}, {c.unit})"
                        for c in self.constraints), level="WARN" if termination else "INFO"))
        for path, value in ((EPISODE_DISTANCE, stats.distance),
                            *((episode_path(c.name), stats.costs[c.name])
                              for c in self.constraints),
                            (EPISODE_LENGTH, stats.length)):
            self.rec.log(path, rr.Scalars(float(value)))
        self.episode_stats.append(stats)
        self.episode += 1

    def finish(self) -> str | None:
        """Send what is buffered and write everything out; returns the error of a flush that
        failed (a live viewer that went away: the file sink is still completed)."""
        self.scalars.send(self.rec)
        problem = None
        try:
            if self.episode_stats:  # the same layout, with the episode plots' ranges
                self.rec.send_blueprint(self.blueprint(), make_active=False, make_default=True)
            self.rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as err:
            problem = str(err)
        self.rec.disconnect()
        return problem


__all__ = ["Clock", "ScalarColumns", "Step", "StepRecorder"]
