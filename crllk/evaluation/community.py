"""The Duckietown community's lane-following metrics, beside the paper's.

The AI Driving Olympics' leaderboards (lane following, with vehicles, with pedestrians) score
the median over episodes of: the survival time, the distance travelled along the lane (in
tiles), the lateral deviation from the lane centre and the time spent outside the drivable lane.
An evaluation reports each episode's values in its rows, and their medians and means with the
collisions counted by what was hit (an obstacle's kind, a vehicle or a pedestrian).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from crllk.maps import MapObject
from crllk.rl.rollout import EvaluationResult
from crllk.tasks.config import TaskConfig

FORMATS = {"survival_time_s": ("survival", "s", 1), "distance_tiles": ("distance", "tiles", 2),
           "lateral_deviation_m": ("lateral deviation", "m", 3),
           "outside_lane_s": ("outside the lane", "s", 2)}
"""Each episode's community metrics (row keys) in the leaderboards' order, with the label,
unit and digits they are shown with."""
METRICS = tuple(FORMATS)


@dataclass(frozen=True)
class Scales:
    """What turns an episode's steps and metres into the community's units."""

    control_timestep: float
    """Seconds per control step."""
    tile_size: float
    """Metres per map tile."""
    vehicles: int
    """Moving agents before the pedestrians in a ``hit_mover`` index."""

    @classmethod
    def of(cls, config: TaskConfig) -> Scales:
        """The scales of a task."""
        traffic = config.traffic
        return cls(config.control_timestep, config.map.tile_size,
                   0 if traffic is None else traffic.vehicles.count)


def episode_metrics(result: EvaluationResult, scales: Scales,
                    objects: Sequence[MapObject] = ()) -> list[dict[str, Any]]:
    """Per episode: :data:`METRICS` (the lane pose ones None where the env did not report it)
    and ``collided_with``: the kind of obstacle hit, ``"vehicle"``, ``"pedestrian"`` or None."""
    rows = []
    for k, stats in enumerate(result.episodes):
        lateral = at_or_none(result.lateral_deviations, k)
        outside = at_or_none(result.outside_lane_steps, k)
        rows.append({
            "survival_time_s": stats.length * scales.control_timestep,
            "distance_tiles": stats.distance / scales.tile_size,
            "lateral_deviation_m": lateral,
            "outside_lane_s": None if outside is None else outside * scales.control_timestep,
            "collided_with": _collided_with(at_or_none(result.hit_objects, k),
                                            at_or_none(result.hit_movers, k), scales, objects),
        })
    return rows


def summary(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The median and mean of each of :data:`METRICS` over the episode ``rows`` (those that
    report it), and the collisions counted by what was hit."""
    out: dict[str, Any] = {"episodes": len(rows)}
    for metric in METRICS:
        values = [row[metric] for row in rows if row.get(metric) is not None]
        out[metric] = ({"median": float(np.median(values)), "mean": float(np.mean(values))}
                       if values else None)
    kinds = Counter(row["collided_with"] for row in rows if row.get("collided_with"))
    out["collisions_by_kind"] = dict(sorted(kinds.items()))
    return out


def format_summary(community: dict[str, Any]) -> str:
    """One line: the medians (the leaderboards' figures) and the collisions by kind."""
    parts = [f"{label} {community[metric]['median']:.{digits}f} {unit}"
             for metric, (label, unit, digits) in FORMATS.items() if community.get(metric)]
    kinds = community.get("collisions_by_kind") or {}
    hits = ", ".join(f"{kind} ×{count}" for kind, count in kinds.items()) or "none"
    return f"community medians: {', '.join(parts)}; collisions: {hits}"


def _collided_with(hit_object: int | None, hit_mover: int | None, scales: Scales,
                   objects: Sequence[MapObject]) -> str | None:
    if hit_mover is not None:
        return "vehicle" if hit_mover < scales.vehicles else "pedestrian"
    if hit_object is not None:
        return objects[hit_object].kind if hit_object < len(objects) else "object"
    return None


def at_or_none(values: Sequence[Any], k: int) -> Any:
    """``values[k]``, or None where the result keeps fewer (a per-episode field it lacks)."""
    return values[k] if k < len(values) else None


__all__ = ["FORMATS", "METRICS", "Scales", "at_or_none", "episode_metrics", "format_summary",
           "summary"]
