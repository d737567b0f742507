"""A fleet's traffic: in the simulation of each robot of a fleet, the other robots are its
vehicles, standing each step where their own simulations have them.

A fleet of N robots runs as N simulations of one map stepped together
(:mod:`crllk.evaluation.fleet`): in simulation i robot i drives with full physics and its own
camera, and the other N - 1 robots are the scene's mover Duckiebots (:mod:`crllk.sim.movers`),
placed before every step at the poses their own simulations hold (a :class:`FleetBoard` shared
by all). Collisions, the headway signal and the movers' features then work as with scripted
traffic (:class:`~crllk.tasks.traffic.Traffic`, whose measures this class keeps): robot i
touching robot j ends robot i's episode with a collision in its simulation, and the fleet
ends robot j's with it (:mod:`crllk.evaluation.fleet`). A robot whose episode has ended
leaves the road for the others: its mover stands :data:`PARKED`, beyond the camera's far
plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from crllk.maps import DuckietownMap, Lane
from crllk.tasks.traffic import Pose, Traffic, duckiebot_box, outline
from crllk.tasks.traffic_config import TrafficConfig

PARKED: Pose = (-1000.0, -1000.0, 0.0)
"""Where a robot that is off the road stands in the other simulations (m, m, rad): farther
from the map than any camera draws."""


@dataclass
class FleetBoard:
    """Where every robot of a fleet is (axle pose, (x, y, yaw)) and which are on the road."""

    poses: list[Pose]
    active: list[bool] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.active:
            self.active = [True] * len(self.poses)

    def others(self, robot: int) -> list[Pose]:
        """The poses of every robot but ``robot``, in robot order, :data:`PARKED` for those
        off the road."""
        return [tuple(pose) if active else PARKED  # type: ignore[misc]
                for k, (pose, active) in enumerate(zip(self.poses, self.active, strict=True))
                if k != robot]

    @staticmethod
    def robot_of_mover(robot: int, mover: int) -> int:
        """The robot that mover ``mover`` of robot ``robot``'s simulation stands for."""
        return mover if mover < robot else mover + 1

    @staticmethod
    def mover_of_robot(robot: int, other: int) -> int:
        """The mover that stands for robot ``other`` in robot ``robot``'s simulation."""
        return other if other < robot else other - 1


class FleetTraffic(Traffic):
    """Robot ``robot``'s view of the fleet on ``board``: the other robots as its vehicles, no
    pedestrians. ``config`` must declare one vehicle per other robot (the scene's movers)."""

    def __init__(self, config: TrafficConfig, dmap: DuckietownMap, control_timestep: float,
                 board: FleetBoard, robot: int):
        if config.vehicles.count != len(board.poses) - 1 or config.pedestrians.count:
            raise ValueError(f"a fleet of {len(board.poses)} robots needs "
                             f"{len(board.poses) - 1} vehicles and no pedestrians, got "
                             f"{config.vehicles.count} and {config.pedestrians.count}")
        super().__init__(config, dmap, control_timestep)
        self.board, self.robot = board, robot

    def reset(self, random: np.random.RandomState, lane: Lane, along: float) -> dict[str, Any]:
        """The other robots where the board has them (the task's generator is not drawn
        from: a fleet's spawns are those of its robots' simulations)."""
        others = self.board.others(self.robot)
        return {"seed": 0, "vehicles": [], "pedestrians": [],
                "poses": [list(pose) for pose in others],
                "velocities": [[0.0, 0.0] for _ in others]}

    def step(self, state: dict[str, Any], robot: Pose) -> list[Pose]:
        """The other robots moved to where the board has them now; their velocities (m/s)
        over the step (0 for a robot that left or came back to the road)."""
        before = self.poses(state)
        after = self.board.others(self.robot)
        state["poses"] = [list(pose) for pose in after]
        state["velocities"] = [
            [0.0, 0.0] if PARKED in (b, a) else [(a[0] - b[0]) / self.dt, (a[1] - b[1]) / self.dt]
            for b, a in zip(before, after, strict=True)]
        return after

    def poses(self, state: dict[str, Any]) -> list[Pose]:
        return [(x, y, yaw) for x, y, yaw in state["poses"]]

    def _vehicle_outlines(self, state: dict[str, Any]) -> list[list[tuple[float, float]]]:
        return [outline(duckiebot_box(*pose)) for pose in self.poses(state)]


__all__ = ["PARKED", "FleetBoard", "FleetTraffic"]
