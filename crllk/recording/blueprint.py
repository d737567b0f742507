"""The review layout of a recording (a rerun blueprint): map, chase view, camera, one plot per
signal, the episode table."""

from __future__ import annotations

from collections.abc import Sequence

import rerun.blueprint as rrb

from crllk.envs.episodes import EpisodeStats
from crllk.recording.entities import (
    ACTION_ENTITY_PATHS,
    CAMERA,
    CAMERA_VIEW,
    EPISODE_DISTANCE,
    EPISODE_LENGTH,
    EVENTS,
    HEADING_ERROR,
    LAGRANGE_PREFIX,
    LATERAL,
    REWARD,
    ROBOT,
    cost_path,
    episode_path,
    episode_paths,
    series_name,
)
from crllk.tasks.constraints import Constraint

_EPISODE_HEADROOM = 1.2
"""The per-episode plots reach this many times the largest value."""
_CHASE_EYE = (-0.9, 0.0, 0.6)
"""Eye of the chase view in the robot's frame (m): behind and above the robot."""
_CHASE_TARGET = (0.4, 0.0, 0.0)
"""Point the chase view looks at, in the robot's frame (m): ahead on the road."""


def _plots(paths: Sequence[str], constraints: Sequence[Constraint],
           ranges: dict[str, tuple[float, float]] | None = None) -> list[rrb.TimeSeriesView]:
    """One plot per series, so that each gets an axis of its own scale (``ranges``: fixed y
    ranges by path); time axes linked, zooming one zooms all."""
    ranges = ranges or {}
    return [rrb.TimeSeriesView(
        origin=path, name=series_name(path, constraints),
        plot_legend=rrb.PlotLegend(visible=False), axis_x=rrb.TimeAxis(link="LinkToGlobal"),
        axis_y=rrb.ScalarAxis(range=ranges[path]) if path in ranges else None)
        for path in paths]


def episode_ranges(stats: Sequence[EpisodeStats]) -> dict[str, tuple[float, float]]:
    """y ranges of the per-episode plots, from :data:`_EPISODE_HEADROOM` times the smallest
    value (or 0) to as much times the largest (or 1), so that no point sits on an edge."""
    values = {EPISODE_DISTANCE: [s.distance for s in stats],
              EPISODE_LENGTH: [s.length for s in stats]}
    for name in stats[0].costs if stats else ():
        values[episode_path(name)] = [s.costs[name] for s in stats]
    ranges = {}
    for path, column in values.items():
        low, high = (_EPISODE_HEADROOM * f([*column, 0.0]) for f in (min, max))
        ranges[path] = (low, high if high > low else low + 1.0)
    return ranges


def scene_views() -> rrb.Vertical:
    """The whole map in 3D, a chase view riding behind the robot beside the robot camera, and
    the event log."""
    chase = rrb.Spatial3DView(origin=ROBOT, contents="/world/**", name="chase view",
                              eye_controls=rrb.EyeControls3D(
                                  position=_CHASE_EYE, look_target=_CHASE_TARGET,
                                  eye_up=(0.0, 0.0, 1.0)))
    return rrb.Vertical(
        rrb.Spatial3DView(origin="world", name="map"),
        rrb.Horizontal(chase, rrb.Spatial2DView(origin=CAMERA, name=CAMERA_VIEW)),
        rrb.TextLogView(origin=EVENTS, name="events"), row_shares=[5, 4, 2])


def make_blueprint(action_type: str, constraints: Sequence[Constraint],
                   multipliers: Sequence[str] = (),
                   ranges: dict[str, tuple[float, float]] | None = None) -> rrb.Blueprint:
    """The review layout: the whole map, a chase view riding with the robot, the camera and
    the event log on the left; on the right one plot per step signal, one per episode
    summary and a table of the episodes (one row each, on the ``episode`` timeline).

    Args:
        action_type: selects the action plots (:data:`ACTION_ENTITY_PATHS`).
        constraints: the task's constraints, a cost plot and an episode plot each.
        multipliers: constraint names with a ``lagrange/<name>`` plot each.
        ranges: fixed y ranges of plots by path (:func:`episode_ranges`).
    """
    step_paths = [REWARD, *(cost_path(c.name) for c in constraints), LATERAL, HEADING_ERROR,
                  *ACTION_ENTITY_PATHS[action_type],
                  *(LAGRANGE_PREFIX + name for name in multipliers)]
    table = rrb.DataframeView(origin="episode", name="episodes", query=rrb.archetypes.
                              DataframeQuery(timeline="episode", select=[
                                  "episode", *(rrb.components.ComponentColumnSelector(
                                      entity_path=path, component="Scalars:scalars")
                                      for path in episode_paths(constraints))]))
    right = rrb.Vertical(
        rrb.Grid(*_plots(step_paths, constraints), grid_columns=2),
        rrb.Grid(*_plots(episode_paths(constraints), constraints, ranges), grid_columns=2),
        table,
        row_shares=[8, 4, 3])
    return rrb.Blueprint(
        rrb.Horizontal(scene_views(), right, column_shares=[1, 1]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="sim_time", state="collapsed"))
