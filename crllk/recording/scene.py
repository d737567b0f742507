"""What a recording logs once, as static data: the map, the robot's parts and the series' styles.

The map's tiles and objects become solid boxes coloured as in the MuJoCo scene, its lanes and
markings line strips (:mod:`crllk.maps.markings`); the robot gets a labelled footprint, a
heading arrow and its camera as a pinhole in pixels (:func:`focal_length`), all in its own frame
under ``world/robot``; every scalar series gets its name and colour.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import rerun as rr

from crllk.maps import DuckietownMap, MapObject
from crllk.maps.markings import (
    WHITE_WIDTH,
    lane_centre_strips,
    white_marking_strips,
    yellow_marking_strips,
)
from crllk.recording.entities import (
    CAMERA,
    FOOTPRINT,
    HEADING,
    HEADING_ERROR,
    LANES,
    LATERAL,
    OBJECTS,
    REWARD,
    TILES,
    TRAIL,
    WHITE_MARKINGS,
    YELLOW_MARKINGS,
    cost_path,
    episode_paths,
    series_name,
)
from crllk.sim import constants as C
from crllk.sim.physics import Physics
from crllk.sim.texture import DECOR_RGB, ROAD_RGB, WHITE_RGB, YELLOW_RGB
from crllk.tasks.config import CameraConfig
from crllk.tasks.constraints import Constraint

_TILE_THICKNESS = 0.002
"""Tiles are flat boxes this thick, top face at z = 0 (m)."""
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
    return boxes(dmap.objects)


def boxes(objs: Sequence[MapObject]) -> rr.Boxes3D:
    """Objects (map objects, moving agents) as their boxes (length along their yaw)."""
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


# ----- static logs ------------------------------------------------------------------------
def log_scene(rec: rr.RecordingStream, dmap: DuckietownMap, physics: Physics,
              camera: CameraConfig) -> None:
    """The map, the trail's style, and the robot's footprint and camera."""
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
    _log_robot_parts(rec, physics)
    _log_pinhole(rec, camera, float(physics.named.model.cam_fovy[C.CAMERA]))


def _log_robot_parts(rec: rr.RecordingStream, physics: Physics) -> None:
    """Labelled footprint box, heading arrow and camera pose in the robot's frame (x
    forward), from the MuJoCo model."""
    model = physics.named.model
    centre, half = model.geom_pos[C.FOOTPRINT_GEOM], model.geom_size[C.FOOTPRINT_GEOM]
    rec.log(FOOTPRINT, rr.Boxes3D(centers=[centre], half_sizes=[half], colors=_ROBOT_RGB,
                                  fill_mode="solid", labels=_ROBOT_LABEL, show_labels=True),
            static=True)
    rec.log(HEADING, rr.Arrows3D(origins=[(centre[0], 0.0, centre[2] + half[2])],
                                 vectors=[(_HEADING_LENGTH, 0.0, 0.0)],
                                 colors=_ROBOT_RGB, radii=0.012), static=True)
    w, x, y, z = model.cam_quat[C.CAMERA]
    rec.log(CAMERA, rr.Transform3D(translation=model.cam_pos[C.CAMERA],
                                   quaternion=rr.Quaternion(xyzw=[x, y, z, w])), static=True)


def _log_pinhole(rec: rr.RecordingStream, camera: CameraConfig, fovy_degrees: float) -> None:
    """The robot camera as a pinhole in pixels (MuJoCo cameras look along -z: right, up,
    back); see :func:`focal_length`."""
    rec.log(CAMERA, rr.Pinhole(focal_length=focal_length(fovy_degrees, camera.height),
                               width=camera.width, height=camera.height,
                               camera_xyz=rr.ViewCoordinates.RUB,
                               image_plane_distance=_CAMERA_PLANE), static=True)


def log_series_styles(rec: rr.RecordingStream, constraints: Sequence[Constraint],
                      multiplier_paths: Iterable[str], action_paths: Iterable[str]) -> None:
    """Names and colours of the series (:func:`~crllk.recording.entities.series_name`);
    per-episode points large."""
    colours = {**_SERIES_RGB, **{cost_path(c.name): _COST_RGB[k % len(_COST_RGB)]
                                 for k, c in enumerate(constraints)}}
    for path, colour in colours.items():
        rec.log(path, rr.SeriesLines(names=series_name(path, constraints), colors=colour),
                static=True)
    for path in multiplier_paths:
        rec.log(path, rr.SeriesLines(names=series_name(path)), static=True)
    for path in action_paths:
        rec.log(path, rr.SeriesPoints(names=series_name(path), marker_sizes=2.0), static=True)
    for path in episode_paths(constraints):
        rec.log(path, rr.SeriesPoints(names=series_name(path, constraints), markers="diamond",
                                      marker_sizes=_EPISODE_MARKER_SIZE), static=True)


__all__ = ["boxes", "focal_length", "log_scene", "log_series_styles", "object_boxes",
           "tile_boxes"]
