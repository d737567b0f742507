"""Settings that change over a run: the imitation weight, the learning rate and the entropy
bonus."""

from __future__ import annotations

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.config import TrainConfig


def _linear(start: float, end: float, frames: int, over_frames: int) -> float:
    """``start`` moving linearly to ``end`` over ``over_frames`` frames, then ``end``."""
    fraction = min(frames / over_frames, 1.0)
    return start + fraction * (end - start)


def imitation_coeff(config: TrainConfig, frames: int) -> float:
    """Weight of the imitation term after ``frames``: ``teacher.coeff`` at first, linearly
    to ``teacher.final`` at ``teacher.frames``, then ``teacher.final``."""
    teacher = config.teacher
    if teacher.frames == 0:
        return teacher.final
    return _linear(teacher.coeff, teacher.final, frames, teacher.frames)


def learning_rate(config: TrainConfig, frames: int) -> float:
    """Adam's learning rate after ``frames``: ``ppo.lr``, or with ``ppo.anneal_lr`` falling
    linearly from it to ``ppo.lr × ppo.lr_final_fraction`` at ``total_frames``."""
    ppo = config.ppo
    if not ppo.anneal_lr:
        return ppo.lr
    return _linear(ppo.lr, ppo.lr * ppo.lr_final_fraction, frames, config.total_frames)


def entropy_coeff(config: TrainConfig, frames: int) -> float:
    """Weight of the entropy bonus after ``frames``: ``ppo.entropy_coeff`` falling linearly to
    ``ppo.entropy_coeff × ppo.entropy_final_fraction`` at ``total_frames``."""
    ppo = config.ppo
    final = ppo.entropy_coeff * ppo.entropy_final_fraction
    return _linear(ppo.entropy_coeff, final, frames, config.total_frames)
