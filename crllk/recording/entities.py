"""Where a recording puts things: entity paths, and the names their plots show."""

from __future__ import annotations

TILES = "world/map/tiles"

LANES = "world/map/lanes"

WHITE_MARKINGS = "world/map/markings/white"

YELLOW_MARKINGS = "world/map/markings/yellow"

OBJECTS = "world/map/objects"

ROBOT = "world/robot"

FOOTPRINT = "world/robot/footprint"

HEADING = "world/robot/heading"

CAMERA = "world/robot/camera"

IMAGE = "world/robot/camera/image"

TRAIL = "world/trail"

REWARD = "reward/progress"

COST_LANE = "cost/lane"

COST_COLLISION = "cost/collision"

LATERAL = "lane_pose/lateral"

HEADING_ERROR = "lane_pose/heading_error"

EVENTS = "events"

EPISODE_DISTANCE = "episode/distance"

EPISODE_LANE_COST = "episode/lane_cost"

EPISODE_COLLISIONS = "episode/collisions"

EPISODE_LENGTH = "episode/length"

CAMERA_VIEW = "robot camera"
"""Name of the view of the camera image in the layouts (:func:`scene_views`)."""

LAGRANGE_PREFIX = "lagrange/"
"""Multiplier ``name`` is logged at ``lagrange/<name>`` (``lagrange/lane``, ...)."""

MAP_ENTITY_PATHS = (TILES, LANES, WHITE_MARKINGS, YELLOW_MARKINGS, OBJECTS)

STEP_ENTITY_PATHS = (ROBOT, IMAGE, TRAIL, REWARD, COST_LANE, COST_COLLISION, LATERAL,
                     HEADING_ERROR)

EPISODE_ENTITY_PATHS = (EPISODE_DISTANCE, EPISODE_LANE_COST, EPISODE_COLLISIONS, EPISODE_LENGTH)

ENTITY_PATHS = (*MAP_ENTITY_PATHS, FOOTPRINT, HEADING, CAMERA, *STEP_ENTITY_PATHS, EVENTS,
                *EPISODE_ENTITY_PATHS)
"""Every entity path a recording holds, whatever the action type and multipliers."""

ACTION_ENTITY_PATHS = {"discrete": ("action/index",),
                       "continuous": ("action/velocity", "action/steering"),
                       "duckietown": ("action/velocity", "action/steering"),
                       "duty": ("action/duty_left", "action/duty_right")}
"""The action's scalar paths per action type (discrete: 0 left, 1 right, 2 straight)."""

ACTION_NAMES = {"action/index": "action (0 left, 1 right, 2 straight)",
                 "action/velocity": "velocity action [-1, 1]",
                 "action/steering": "steering action [-1, 1]",
                 "action/duty_left": "left wheel duty [-1, 1]",
                 "action/duty_right": "right wheel duty [-1, 1]"}

SERIES_NAMES = {REWARD: "progress (m)", COST_LANE: "lane cost (dm)",
                COST_COLLISION: "collision cost", LATERAL: "lateral offset (m, + right)",
                HEADING_ERROR: "heading error (rad)", EPISODE_DISTANCE: "episode distance (m)",
                EPISODE_LANE_COST: "episode mean lane cost (dm)",
                EPISODE_COLLISIONS: "episode collisions", EPISODE_LENGTH: "episode length (steps)"}
"""Series names with units; actions and multipliers are named by :func:`series_name`."""


def series_name(path: str) -> str:
    """The name of the scalar series at ``path``, as its plot shows it."""
    if path.startswith(LAGRANGE_PREFIX):
        return "λ_" + path.removeprefix(LAGRANGE_PREFIX)
    return SERIES_NAMES.get(path) or ACTION_NAMES.get(path, path)
