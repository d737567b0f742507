"""Where a recording puts things: entity paths, and the names their plots show."""

from __future__ import annotations

from collections.abc import Sequence

from crllk.tasks.constraints import Constraint

TILES = "world/map/tiles"
LANES = "world/map/lanes"
WHITE_MARKINGS = "world/map/markings/white"
YELLOW_MARKINGS = "world/map/markings/yellow"
OBJECTS = "world/map/objects"
MOVERS = "world/movers"
"""The task's moving agents (other Duckiebots, pedestrians), as boxes at every step."""
ROBOT = "world/robot"
FOOTPRINT = "world/robot/footprint"
HEADING = "world/robot/heading"
CAMERA = "world/robot/camera"
IMAGE = "world/robot/camera/image"
TRAIL = "world/trail"
REWARD = "reward/progress"
LATERAL = "lane_pose/lateral"
HEADING_ERROR = "lane_pose/heading_error"
EVENTS = "events"
EPISODE_DISTANCE = "episode/distance"
EPISODE_LENGTH = "episode/length"
CAMERA_VIEW = "robot camera"
"""Name of the view of the camera image in the layouts (:func:`scene_views`)."""

LAGRANGE_PREFIX = "lagrange/"
"""Multiplier ``name`` is logged at ``lagrange/<name>`` (``lagrange/lane``, ...)."""

MAP_ENTITY_PATHS = (TILES, LANES, WHITE_MARKINGS, YELLOW_MARKINGS, OBJECTS)

COST_PREFIX = "cost/"
"""Constraint ``name``'s per-step cost is logged at ``cost/<name>``."""
EPISODE_PREFIX = "episode/"
"""Per-episode values: ``episode/distance``, ``episode/length`` and ``episode/<name>`` per
constraint."""


def cost_path(name: str) -> str:
    return COST_PREFIX + name


def episode_path(name: str) -> str:
    return EPISODE_PREFIX + name


def step_paths(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """The per-step entities: robot, camera, trail, progress, each cost, the lane pose."""
    return (ROBOT, IMAGE, TRAIL, REWARD, *(cost_path(c.name) for c in constraints), LATERAL,
            HEADING_ERROR)


def episode_paths(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """The per-episode scalars: distance, each constraint's episode value, length."""
    return (EPISODE_DISTANCE, *(episode_path(c.name) for c in constraints), EPISODE_LENGTH)


def entity_paths(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """Every entity path a recording holds, whatever the action type and multipliers."""
    return (*MAP_ENTITY_PATHS, FOOTPRINT, HEADING, CAMERA, *step_paths(constraints), EVENTS,
            *episode_paths(constraints))

ACTION_ENTITY_PATHS = {"discrete": ("action/index",),
                       "continuous": ("action/velocity", "action/steering"),
                       "stoppable": ("action/velocity", "action/steering"),
                       "duckietown": ("action/velocity", "action/steering"),
                       "duty": ("action/duty_left", "action/duty_right")}
"""The action's scalar paths per action type (discrete: 0 left, 1 right, 2 straight)."""

ACTION_NAMES = {"action/index": "action (0 left, 1 right, 2 straight)",
                 "action/velocity": "velocity action [-1, 1]",
                 "action/steering": "steering action [-1, 1]",
                 "action/duty_left": "left wheel duty [-1, 1]",
                 "action/duty_right": "right wheel duty [-1, 1]"}

SERIES_NAMES = {REWARD: "progress (m)", LATERAL: "lateral offset (m, + right)",
                HEADING_ERROR: "heading error (rad)", EPISODE_DISTANCE: "episode distance (m)",
                EPISODE_LENGTH: "episode length (steps)"}
"""Names with units of the series every recording has; costs, actions and multipliers are
named by :func:`series_name`."""


def series_name(path: str, constraints: Sequence[Constraint] = ()) -> str:
    """The name of the scalar series at ``path``, as its plot shows it; ``constraints`` name
    their cost and episode series (``lane cost``, ``episode lane (mean, dm)``)."""
    if path.startswith(LAGRANGE_PREFIX):
        return "λ_" + path.removeprefix(LAGRANGE_PREFIX)
    for c in constraints:
        if path == cost_path(c.name):
            return f"{c.name} cost"
        if path == episode_path(c.name):
            return f"episode {c.name} ({c.aggregate}, {c.unit})"
    return SERIES_NAMES.get(path) or ACTION_NAMES.get(path, path)
