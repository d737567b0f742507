"""Tiny training runs for tests: two sub-environments, eight steps per iteration."""

from __future__ import annotations

from pathlib import Path

import crllk  # noqa: F401  (headless GL before torchrl)
from crllk.train import resolve_config
from crllk.training.compose import compose_config
from crllk.training.loop import train

NUM_ENVS, ROLLOUT = 2, 8
FRAMES_PER_ITERATION = NUM_ENVS * ROLLOUT
TINY = [f"num_envs={NUM_ENVS}", f"rollout_steps={ROLLOUT}", "ppo.minibatch_size=8",
        "ppo.epochs=2", "task.horizon=12", "progress=false", "checkpoint_every=1"]


def run_in_process(run_dir: Path, iterations: int, extra: list[str] = (), *,
                   frames_per_iteration: int = FRAMES_PER_ITERATION) -> Path:
    """Trains ``iterations`` tiny iterations into ``run_dir`` and returns it."""
    cfg = compose_config([*TINY, f"run_dir={run_dir}",
                          f"total_frames={iterations * frames_per_iteration}", *extra])
    return train(resolve_config(cfg))
