"""What the environments over simulations stepped elsewhere (worker processes, remote
collectors) share: the teacher flag kept here and sent on to the workers, and the workers'
snapshots merged into the one a single :class:`~crllk.envs.batched.BatchedLaneKeepingEnv`
holding them all would take, and split again.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch

SNAPSHOT_ARRAYS = ("observations", "states", "history_images")
"""The per-simulation arrays of a snapshot (the last one only with a frame history)."""


class MirroredTeacherFlag:
    """:attr:`teacher_active` of simulations stepped elsewhere (worker processes, remote
    collectors): kept here, and a change is sent to them by :meth:`_send_teacher_active`."""

    _teacher_active = False

    @property
    def teacher_active(self) -> bool:
        """Whether observations carry the teacher's action (set in every worker)."""
        return self._teacher_active

    @teacher_active.setter
    def teacher_active(self, active: bool) -> None:
        if bool(active) != self._teacher_active:
            self._send_teacher_active(bool(active))
            self._teacher_active = bool(active)

    def _send_teacher_active(self, active: bool) -> None:
        """Sets :meth:`~crllk.envs.batched.BatchedLaneKeepingEnv.set_teacher_active` in every
        worker."""
        raise NotImplementedError


def merge_sim_states(states: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One :meth:`~crllk.envs.batched.BatchedLaneKeepingEnv.sim_state` from the snapshots of
    consecutive slices of the simulations (workers in order): the snapshot one env holding them
    all would take."""
    first = states[0]
    merged = {key: first[key] for key in ("task", "observation", "action", "privileged_state",
                                          "teacher", "commands", "history") if key in first}
    for state in states[1:]:
        for key, value in merged.items():
            if state.get(key) != value:
                raise ValueError(f"snapshots disagree on {key}: {value!r}, {state.get(key)!r}")
    merged["num_envs"] = sum(state["num_envs"] for state in states)
    for key in ("seeds", "step_counts", "sub_envs"):
        merged[key] = [item for state in states for item in state[key]]
    for key in SNAPSHOT_ARRAYS:
        if key in first:
            merged[key] = torch.cat([state[key] for state in states])
    return merged


def split_sim_state(state: dict[str, Any], sizes: Sequence[int]) -> list[dict[str, Any]]:
    """The inverse of :func:`merge_sim_states`: one snapshot per slice of ``sizes``
    simulations.

    Raises:
        ValueError: if ``sizes`` do not add up to the snapshot's ``num_envs``.
    """
    if sum(sizes) != state.get("num_envs"):
        raise ValueError(f"snapshot num_envs is {state.get('num_envs')!r}, this env has "
                         f"{sum(sizes)}: restore into an env built with the same arguments")
    parts, start = [], 0
    for size in sizes:
        part = dict(state, num_envs=size)
        for key in ("seeds", "step_counts", "sub_envs", *SNAPSHOT_ARRAYS):
            if key in state:
                part[key] = state[key][start:start + size]
        parts.append(part)
        start += size
    return parts


__all__ = ["SNAPSHOT_ARRAYS", "MirroredTeacherFlag", "merge_sim_states", "split_sim_state"]
