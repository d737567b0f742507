"""Car following: the rule by which a Duckiebot keeps its distance to what is ahead in its lane,
shared by the traffic's vehicles (:mod:`crllk.tasks.traffic`) and the scripted follower
(:mod:`crllk.tasks.follower`).

A vehicle looks :data:`LOOKAHEAD` along its lane for anything within its half-width plus
:data:`CORRIDOR_MARGIN` of the lane centre and drives no faster than closes the gap from its
front down to the gap it keeps in :data:`FOLLOW_TIME` (:func:`following_speed`). The scripted
follower slows by the same rule for what is in its own path ahead, which it measures its own
way (:meth:`~crllk.tasks.follower.LaneFollower.mover_speed_limit`: its width about its own
offset, where the movers are and will be, and a gap of its own). A :class:`Mover` is what the
follower sees of another agent.
"""

from __future__ import annotations

from typing import NamedTuple

from crllk.maps import MapObject
from crllk.sim import constants as C

FRONT = C.FOOTPRINT_LENGTH / 2 - C.FOOTPRINT_CENTRE_BEHIND_AXLE
"""Reach of a Duckiebot's footprint ahead of its axle (m)."""
FOLLOW_GAP = 0.1
"""Gap (m) a vehicle keeps, standing, behind what is ahead in its lane."""
FOLLOW_TIME = 1.0
"""Time (s) a Duckiebot takes to close the gap beyond the one it keeps: its speed is at most
(gap - kept gap) / FOLLOW_TIME."""
LOOKAHEAD = 1.0
"""How far ahead (m) a vehicle looks for what is in its lane."""
CORRIDOR_MARGIN = 0.03
"""A vehicle slows for what comes within its half-width plus this (m) of its lane centre."""


class Mover(NamedTuple):
    """A moving agent now."""

    box: MapObject
    """Its footprint."""
    velocity: tuple[float, float]
    """Its velocity (m/s, world x and y) over the last control step."""


def following_speed(gap: float, keep: float) -> float:
    """Highest speed (m/s) with a ``gap`` (m) from the front to what is ahead, to keep ``keep``
    (m): (gap - keep) / :data:`FOLLOW_TIME`, never negative."""
    return max(gap - keep, 0.0) / FOLLOW_TIME


__all__ = ["CORRIDOR_MARGIN", "FOLLOW_GAP", "FOLLOW_TIME", "FRONT", "LOOKAHEAD", "Mover",
           "following_speed"]
