"""Rerun recordings of lane-keeping episodes: the map, the robot, its camera and every signal.

    python -m crllk.record --task obstacle_loop --episodes 1 --out rec.rrd [--viewer spawn]

:func:`record_episodes` plays episodes of sub-environment 0 of a
:class:`~crllk.envs.batched.BatchedLaneKeepingEnv` and logs them to a ``.rrd`` file and/or a
live viewer. The rerun package is imported here and by the modules built on it
(:mod:`crllk.recording.live`, :mod:`crllk.screenshots`): the map's lane and marking polylines
come from :mod:`crllk.maps.markings` (numpy) and the viewer process (probing the port, running
the ``rerun`` executable) from :mod:`crllk.recording.viewer`.

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

import math
import time
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
import torch
from rerun.chunk import RrdReader
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.envs.batched import TERMINATIONS
from crllk.envs.episodes import EpisodeAccumulator, EpisodeStats
from crllk.errors import RecordingError
from crllk.files import WriteError, atomic_output, write_problem
from crllk.maps import DuckietownMap
from crllk.maps.markings import (
    LANE_HEIGHT,
    WHITE_WIDTH,
    lane_centre_strips,
    white_marking_strips,
    yellow_marking_strips,
)
from crllk.recording.blueprint import episode_ranges, make_blueprint
from crllk.recording.entities import (
    ACTION_ENTITY_PATHS,
    CAMERA,
    EPISODE_DISTANCE,
    EPISODE_LENGTH,
    EVENTS,
    FOOTPRINT,
    HEADING,
    HEADING_ERROR,
    IMAGE,
    LAGRANGE_PREFIX,
    LANES,
    LATERAL,
    OBJECTS,
    REWARD,
    ROBOT,
    TILES,
    TRAIL,
    WHITE_MARKINGS,
    YELLOW_MARKINGS,
    cost_path,
    episode_path,
    episode_paths,
    series_name,
)
from crllk.recording.viewer import (
    VIEWER_HOST,
    VIEWER_PORT,
    check_port_free,
    spawn_viewer,
    viewer_listening,
)
from crllk.rl.rollout import Rollout
from crllk.sim import constants as C
from crllk.sim.physics import Physics
from crllk.sim.texture import DECOR_RGB, ROAD_RGB, WHITE_RGB, YELLOW_RGB
from crllk.tasks.config import CameraConfig
from crllk.tasks.constraints import Constraint

if TYPE_CHECKING:
    from crllk.envs.batched import BatchedLaneKeepingEnv

Policy = Callable[[TensorDictBase], TensorDictBase]
"""Writes ``"action"`` into the tensordict it is given (a TensorDict module)."""

# ----- constants --------------------------------------------------------------------------
VIEWERS = ("none", "spawn", "serve")
FLUSH_TIMEOUT_S = 60.0
"""The longest the final flush may wait for its sinks (s): rerun's own default is unbounded,
and a sink that never answers must not hang a training run or a test."""
_FAILED_VIEWERS: set[str] = set()
"""Viewer modes that failed in this process and are not tried again (``"spawn"``)."""
_TILE_THICKNESS = 0.002
"""Tiles are flat boxes this thick, top face at z = 0 (m)."""
_SCALAR_BATCH = 30
"""Per-step scalars are sent every this many steps (1 s of simulation at 30 Hz) and at the end
of every episode."""
_CAMERA_PLANE = 0.08
"""Distance of the camera image plane drawn in 3D from the camera (m)."""
_HEADING_LENGTH = 0.2
"""Length of the arrow drawn along the robot's heading, from its footprint's top (m)."""
_ROBOT_LABEL = "robot"
"""Label of the recorded robot (the map's own duckiebots are labelled ``duckiebot``)."""
_LANE_RGB = (230, 40, 200)
_TRAIL_RGB = (40, 170, 255)
_ROBOT_RGB = (0, 230, 255)
"""Cyan: no map object, tile or marking has this colour."""
_EPISODE_MARKER_SIZE = 6.0
"""Radius of the per-episode summary points in the plots (ui points)."""
_OBJECT_RGB = {"duckie": (250, 215, 40), "cone": (245, 105, 15), "barrier": (220, 30, 30),
               "duckiebot": (40, 40, 45), "bus": (240, 190, 25), "truck": (50, 100, 200),
               "tree": (50, 140, 50), "sign_blank": (235, 235, 235)}
"""Box colour of each object kind (the main colour of its parts in the MuJoCo scene)."""
_SERIES_RGB = {REWARD: (60, 180, 75), LATERAL: (0, 130, 200), HEADING_ERROR: (245, 130, 48)}
_COST_RGB = ((230, 25, 75), (255, 99, 71), (145, 30, 180), (70, 200, 200))
"""Colours of the constraints' cost series, in the task's constraint order (repeating)."""


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


# ----- map boxes --------------------------------------------------------------------------
def tile_boxes(dmap: DuckietownMap) -> rr.Boxes3D:
    """Every tile as a flat solid box coloured as the floor texture colours it."""
    s = dmap.tile_size
    tiles = [t for row in dmap.spec.tiles for t in row]
    centres = [((t.column + 0.5) * s, (dmap.rows - t.row - 0.5) * s, -_TILE_THICKNESS / 2)
               for t in tiles]
    colours = [ROAD_RGB if t.drivable else DECOR_RGB[t.kind] for t in tiles]
    half_size = (s / 2, s / 2, _TILE_THICKNESS / 2)
    return rr.Boxes3D(centers=centres, half_sizes=[half_size] * len(tiles), colors=colours,
                      fill_mode="solid", labels=[t.label for t in tiles], show_labels=False)


def object_boxes(dmap: DuckietownMap) -> rr.Boxes3D:
    """The map's objects as their collision boxes (length along their yaw)."""
    objs = dmap.objects
    return rr.Boxes3D(
        centers=[(o.x, o.y, o.height / 2) for o in objs],
        half_sizes=[(o.length / 2, o.width / 2, o.height / 2) for o in objs],
        rotation_axis_angles=[rr.RotationAxisAngle(axis=(0, 0, 1), radians=o.yaw) for o in objs],
        colors=[_OBJECT_RGB.get(o.kind, (128, 128, 128)) for o in objs], fill_mode="solid",
        labels=[o.kind for o in objs])


def focal_length(fovy_degrees: float, height: int) -> float:
    """Focal length (px) of a pinhole camera with square pixels whose vertical field of view
    is ``fovy_degrees`` over an image ``height`` pixels high: f = h / 2 / tan(fovy / 2).

    The pinhole is given in pixels: rerun 0.41 replaces the resolution of a pinhole logged
    with ``fov_y`` and ``aspect_ratio`` by ``[aspect_ratio, 1]``.
    """
    return 0.5 * height / math.tan(math.radians(fovy_degrees) / 2)


# ----- recording --------------------------------------------------------------------------
@dataclass
class _Clock:
    """Accumulates the seconds spent inside ``with clock:`` blocks."""

    seconds: float = 0.0
    _start: float = field(default=0.0, repr=False)

    def __enter__(self) -> _Clock:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds += time.perf_counter() - self._start


@dataclass
class _Step:
    """The signals of sub-environment 0 after one control step."""

    pose: tuple[float, float, float]
    image: np.ndarray
    action: np.ndarray
    reward: float
    costs: dict[str, float]
    """Per-step cost by constraint name."""
    lateral: float
    heading_error: float


class _ScalarColumns:
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


class _Recorder:
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
        self.scalars = _ScalarColumns(iteration)
        self.clock = _Clock()
        self.episode_stats: list[EpisodeStats] = []

    def blueprint(self) -> rrb.Blueprint:
        """The layout for this recording's action type, multipliers and episodes so far."""
        return make_blueprint(self.action_type, self.constraints,
                              [path.removeprefix(LAGRANGE_PREFIX) for path in self.multipliers],
                              episode_ranges(self.episode_stats) if self.episode_stats else None)

    def log_static(self, dmap: DuckietownMap, physics: Physics, camera: CameraConfig) -> None:
        """The map, the robot's footprint and camera, and the series' names and colours."""
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log(TILES, tile_boxes(dmap), static=True)
        rec.log(LANES, rr.LineStrips3D(lane_centre_strips(dmap), colors=_LANE_RGB, radii=0.004),
                static=True)
        rec.log(WHITE_MARKINGS, rr.LineStrips3D(white_marking_strips(dmap), colors=WHITE_RGB,
                                                radii=WHITE_WIDTH / 2), static=True)
        rec.log(YELLOW_MARKINGS, rr.LineStrips3D(yellow_marking_strips(dmap), colors=YELLOW_RGB,
                                                 radii=0.012), static=True)
        rec.log(OBJECTS, object_boxes(dmap), static=True)
        rec.log(TRAIL, rr.LineStrips3D.from_fields(colors=_TRAIL_RGB, radii=0.006), static=True)
        self._log_robot_parts(physics)
        self._log_pinhole(camera, float(physics.named.model.cam_fovy[C.CAMERA]))
        self._log_series_styles()

    def _log_robot_parts(self, physics: Physics) -> None:
        """Labelled footprint box, heading arrow and camera pose in the robot's frame (x
        forward), from the MuJoCo model."""
        model = physics.named.model
        centre, half = model.geom_pos[C.FOOTPRINT_GEOM], model.geom_size[C.FOOTPRINT_GEOM]
        self.rec.log(FOOTPRINT, rr.Boxes3D(centers=[centre], half_sizes=[half],
                                           colors=_ROBOT_RGB, fill_mode="solid",
                                           labels=_ROBOT_LABEL, show_labels=True), static=True)
        self.rec.log(HEADING, rr.Arrows3D(origins=[(centre[0], 0.0, centre[2] + half[2])],
                                          vectors=[(_HEADING_LENGTH, 0.0, 0.0)],
                                          colors=_ROBOT_RGB, radii=0.012), static=True)
        w, x, y, z = model.cam_quat[C.CAMERA]
        self.rec.log(CAMERA, rr.Transform3D(translation=model.cam_pos[C.CAMERA],
                                            quaternion=rr.Quaternion(xyzw=[x, y, z, w])),
                     static=True)

    def _log_pinhole(self, camera: CameraConfig, fovy_degrees: float) -> None:
        """The robot camera as a pinhole in pixels (MuJoCo cameras look along -z: right, up,
        back); see :func:`focal_length`."""
        self.rec.log(CAMERA, rr.Pinhole(focal_length=focal_length(fovy_degrees, camera.height),
                                        width=camera.width, height=camera.height,
                                        camera_xyz=rr.ViewCoordinates.RUB,
                                        image_plane_distance=_CAMERA_PLANE), static=True)

    def _log_series_styles(self) -> None:
        """Names and colours of the series (:func:`series_name`); per-episode points large."""
        colours = {**_SERIES_RGB, **{cost_path(c.name): _COST_RGB[k % len(_COST_RGB)]
                                     for k, c in enumerate(self.constraints)}}
        for path, colour in colours.items():
            self.rec.log(path, rr.SeriesLines(names=series_name(path, self.constraints),
                                              colors=colour), static=True)
        for path in self.multipliers:
            self.rec.log(path, rr.SeriesLines(names=series_name(path)), static=True)
        for path in self.action_paths:
            self.rec.log(path, rr.SeriesPoints(names=series_name(path), marker_sizes=2.0),
                         static=True)
        for path in episode_paths(self.constraints):
            self.rec.log(path, rr.SeriesPoints(names=series_name(path, self.constraints),
                                               markers="diamond",
                                               marker_sizes=_EPISODE_MARKER_SIZE), static=True)

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

    def log_step(self, step: _Step) -> None:
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


# ----- sinks ------------------------------------------------------------------------------
def check_writable(path: str | Path) -> Path:
    """Create ``path``'s directory and check that a file can be written in it, so that a
    recording fails before stepping, not halfway. The file itself is left alone: it is written
    beside it and renamed over it at the end (:func:`crllk.files.atomic_output`), so a link
    planted at ``path`` is replaced, never written through.

    Raises:
        RecordingError: naming the path when the directory or the file cannot be created.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise RecordingError(path, err.strerror or str(err)) from None
    problem = write_problem(path)
    if problem:
        raise RecordingError(path, problem)
    return path


def _open_sinks(sink_path: Path | None, path: Path | None, viewer: str, problems: list[str]
                ) -> tuple[list, str | None]:
    """The sinks for ``sink_path`` (written as the file ``path``) and ``viewer``; an
    unreachable viewer becomes a warning.

    A viewer that could not be spawned is reported once per process: later recordings only
    reuse a viewer that answers by then (started by hand), and say nothing otherwise.
    """
    sinks: list = [rr.FileSink(sink_path)] if sink_path is not None else []
    url = None
    try:
        if viewer == "spawn":
            if "spawn" in _FAILED_VIEWERS and not viewer_listening(VIEWER_PORT):
                return sinks, None
            url = spawn_viewer(VIEWER_PORT)
            sinks.append(rr.GrpcSink(url))
        elif viewer == "serve":
            check_port_free(VIEWER_PORT)  # rerun's server would fail later, at the flush
            server = rr.GrpcServerSink(VIEWER_HOST, VIEWER_PORT)
            url = server.uri
            sinks.append(server)
    except Exception as err:  # any viewer failure must not stop the recording
        if viewer not in _FAILED_VIEWERS:
            problems.append(f"rerun viewer ({viewer}) unavailable, "
                            f"{'writing only ' + str(path) if path else 'nothing recorded'}: "
                            f"{err}")
        if viewer == "spawn":
            _FAILED_VIEWERS.add(viewer)
    return sinks, url


# ----- playing ----------------------------------------------------------------------------
def _camera_image(env: BatchedLaneKeepingEnv, nxt: TensorDictBase, clock: _Clock) -> np.ndarray:
    """Sub-environment 0's camera image: the observation, or rendered for state envs."""
    if env.observation_type == "pixels":
        return nxt["pixels"][0].numpy()
    cam = env.config.camera
    with clock:
        return env.physics[0].render_camera(cam.height, cam.width, cam.supersample)


def _read_step(env: BatchedLaneKeepingEnv, stepped: TensorDictBase, clock: _Clock) -> _Step:
    nxt, outcome = stepped["next"], env.tasks[0].outcome
    return _Step(pose=env.physics[0].pose(), image=_camera_image(env, nxt, clock),
                 action=np.atleast_1d(stepped["action"][0].detach().cpu().numpy()).astype(
                     np.float64),
                 reward=float(nxt["reward"][0]),
                 costs={c.name: float(nxt[c.cost_key][0]) for c in env.constraints},
                 lateral=outcome.lateral,
                 heading_error=outcome.heading_error)


def _play(env: BatchedLaneKeepingEnv, policy: Policy, episodes: int, recorder: _Recorder,
          render_clock: _Clock) -> list[EpisodeStats]:
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
        deterministic: take the policy's mode instead of sampling.
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
    sinks, url = _open_sinks(written, file, viewer, problems)
    if not sinks:
        return RecordingReport(None, 0, 0, 0.0, warnings=tuple(problems))
    recorder = _Recorder(rr.RecordingStream(application_id, recording_id=recording_id),
                         env.config.control_timestep, env.action_type, env.constraints,
                         iteration, multipliers)
    render_clock = _Clock()
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
        _flush_failed(problem, file, viewer, problems)
    return RecordingReport(file, recorder.steps, len(stats), recorder.clock.seconds,
                           render_clock.seconds, tuple(problems), tuple(stats), url)


def _check_arguments(episodes: int, path: str | Path | None, viewer: str) -> None:
    if viewer not in VIEWERS:
        raise ValueError(f"viewer must be one of {VIEWERS}, got {viewer!r}")
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    if path is None and viewer == "none":
        raise ValueError("nothing to record to: give a path or a viewer")


def _flush_failed(problem: str, file: Path | None, viewer: str, problems: list[str]) -> None:
    """A failed final flush: the file's error without a viewer, else a lost viewer."""
    if viewer == "none" and file is not None:
        raise RecordingError(file, problem)
    problems.append(f"rerun viewer ({viewer}) lost while recording"
                    f"{', the file is complete' if file else ''}: {problem}")


# ----- reading back -----------------------------------------------------------------------
def read_recording(path: str | Path) -> dict[str, list[pa.RecordBatch]]:
    """The record batches of the file's first recording, by entity path without the leading
    ``/`` (``rerun.chunk.RrdReader``; static rows have no time columns)."""
    chunks: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).stream():
        chunks.setdefault(chunk.entity_path.lstrip("/"), []).append(chunk.to_record_batch())
    return chunks

__all__ = ["VIEWERS", "RecordingError", "RecordingReport", "check_writable", "focal_length",
           "read_recording", "record_episodes", "spawn_viewer"]
