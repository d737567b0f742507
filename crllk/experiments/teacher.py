"""``python -m crllk.experiments teacher``: what the privileged teacher buys. CRLLK-D from the
default configuration (the imitation weight falls from 1 to its floor, 0.3, and stays there),
with the teacher annealed to zero before the end, and without a teacher, on each map, every
seed judged on the test seed (sampled policy and deployed policy, each start direction apart).
An :class:`~crllk.experiments.aids.Ablation`, like the other training aids'."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from crllk.experiments.aids import Ablation, Variant, ablation_markdown, variants
from crllk.experiments.runs import Outcome, RunSpec, Settings

TEACHER_TASKS = ("obstacle_loop", "small_loop")
"""The maps of the ablation: the one with obstacles in a lane, and the paper's Table 1 map."""
TEACHER_VARIANTS = variants(
    Variant("floor 0.3 (default)"),
    Variant("annealed to 0 by 400k frames", "-teacher0",
            ("teacher.final=0", "teacher.frames=400000")),
    Variant("no teacher", "-noteacher", ("teacher.coeff=0",)),
)
"""Each variant's run-directory tag and trainer overrides: the default's weight falls from 1
to 0.3 over 150,000 frames and stays; annealed, it falls to 0 over 400,000 of the 500,000
frames, so the last 100,000 are Lagrangian PPO alone; without, it is 0 throughout."""
TEACHER = Ablation("teacher", "The teacher measured: CRLLK-D ({obs})", TEACHER_VARIANTS,
                   TEACHER_TASKS, label="teacher")


def teacher_specs(settings: Settings) -> list[RunSpec]:
    """CRLLK-D with each teacher variant, on every map and seed."""
    return TEACHER.specs(settings)


def teacher(settings: Settings) -> list[Path]:
    """Trains what is missing, evaluates on the test seed, writes ``teacher.json`` and
    ``teacher.md`` into ``<results>/<obs>/``."""
    return TEACHER.run(settings)


def teacher_document(outcome: Outcome, settings: Settings) -> dict[str, Any]:
    """Per map and variant: the aggregate across seeds of the sampled policy and of the
    mode (with each run's intervals and start directions)."""
    return TEACHER.document(outcome, settings)


def teacher_markdown(document: Mapping[str, Any]) -> str:
    """The ablation's Markdown from its JSON document: per map a row per variant and seed."""
    return ablation_markdown(document, TEACHER.label)


__all__ = ["TEACHER", "TEACHER_TASKS", "TEACHER_VARIANTS", "teacher", "teacher_document",
           "teacher_markdown", "teacher_specs"]
