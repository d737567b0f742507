"""A task's constraints, as data.

A constraint names a per-step signal the task computes (:data:`SIGNALS`) and how an episode
aggregates it (``mean`` over its steps or ``sum``); the constrained quantity is the mean of that
episode value over episodes, reported under the constraint's metric name. Everything downstream
(the environment's cost entries ``cost_<name>``, episode statistics, multipliers, the loss,
``metrics.csv``, evaluations, recordings, experiment verdicts) iterates over a task's
declaration, so adding a constraint is a change of the task's settings, not of the code:

    constraints: [lane, collision]             # the paper's two (the default)
    constraints: [lane, collision, crossing]   # and the lane-crossing cost of C-CRLLK
    constraints: [lane, collision, headway]    # and tailgating, with traffic
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

AGGREGATES = ("mean", "sum")
"""How an episode turns a constraint's per-step signal into one value."""

SIGNALS = {
    "lane_deviation": "|lateral offset| from the lane centre (dm); the task's off_road_lane_cost "
                      "off the road",
    "collision": "1 on the step that ends on an obstacle, a moving agent (another Duckiebot, a "
                 "pedestrian) or off the road, else 0",
    "lane_crossing": "1 on a step where the robot's centre crosses a lane line (the yellow "
                     "centre line or the white edge line), else 0",
    "headway": "1 on a step that ends with the gap from the robot's front to the nearest "
               "vehicle ahead in its lane below the task's traffic.headway (m), else 0",
}
"""Per-step signals the lane-keeping task computes, by name."""


def cost_key(name: str) -> str:
    """The per-step entry of constraint ``name``'s cost, in the environment's observations, the
    batches (under ``next``), episode rows and Gymnasium's ``info`` (``cost_<name>``)."""
    return f"cost_{name}"


@dataclass(frozen=True)
class Constraint:
    """One constraint: E[episode aggregate of ``signal``] <= a threshold (set by the trainer)."""

    name: str
    """Identifier: cost entry ``cost_<name>``, multiplier ``algo.constraints.<name>``."""
    signal: str
    """The per-step signal (a key of :data:`SIGNALS`)."""
    aggregate: str
    """``mean`` (per-step average of an episode) or ``sum`` (episode total)."""
    unit: str
    """Unit of the episode value, for tables and plots."""
    metric: str
    """Name of the constrained quantity in logs and tables (``J_clane``)."""

    @property
    def cost_key(self) -> str:
        """The environment's per-step entry of this constraint's cost."""
        return cost_key(self.name)

    def episode_value(self, total: float, length: int) -> float:
        """The episode's value from the sum of its per-step signal over ``length`` steps."""
        return total / length if self.aggregate == "mean" else total


BUILTIN = {
    "lane": Constraint("lane", "lane_deviation", "mean", "dm", "J_clane"),
    "collision": Constraint("collision", "collision", "sum", "per episode", "J_coll"),
    "crossing": Constraint("crossing", "lane_crossing", "sum", "per episode", "J_ccross"),
    "headway": Constraint("headway", "headway", "mean", "fraction of steps", "J_chead"),
}
"""Constraints a task may name without spelling them out."""
DEFAULT = ("lane", "collision")
"""The paper's constraints: mean lane deviation and collisions per episode."""


def names(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    return tuple(c.name for c in constraints)


def by_name(constraints: Sequence[Constraint]) -> Mapping[str, Constraint]:
    return {c.name: c for c in constraints}


__all__ = ["AGGREGATES", "BUILTIN", "DEFAULT", "SIGNALS", "Constraint", "by_name", "names"]
