"""The learner seam (:mod:`crllk.algos`): learners found by name, a clear error for an unknown
one, a learner the trainer knows nothing about trains and resumes through the same loop, and
PPO-Lagrangian reproduces the metrics of the trainer before the seam existed."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import pytest
import torch
from tensordict import TensorDictBase
from tiny_runs import ROUNDING, assert_same_runs, read_rows, run_in_process

from crllk import algos
from crllk.algos.ppo_lagrangian import PPOLagrangian
from crllk.config import validate
from crllk.errors import ConfigError
from crllk.training.compose import compose_config

REFERENCES = Path(__file__).parent / "data" / "reference_metrics"
REFERENCE_OVERRIDES = ["obs=state", "task=obstacle_loop", "seed=3", "eval.final=false",
                       "encounters=0", "algo.constraints.lane.threshold=0.05"]
"""Six tiny iterations (``tiny_runs.TINY``) in which λ_lane rises from 0 (α1 0.05 dm is below
what the young policy drives) and the teacher's imitation term is on."""
REFERENCE_AGENTS = {"discrete": "action=discrete", "continuous": "action=continuous",
                    "PPO-D": "agent=PPO-D"}


def test_the_learners_are_found_by_name():
    assert algos.learners()["ppo_lagrangian"] is PPOLagrangian
    assert validate(compose_config([])).algo.learner == "ppo_lagrangian"


def test_an_unknown_learner_is_one_line_naming_the_known_ones():
    config = validate(compose_config(["obs=state", "num_envs=2", "algo.learner=sac"]))
    with pytest.raises(ConfigError) as error:
        algos.build_learner(config, None)
    assert str(error.value) == ("override: algo.learner: no learner 'sac' "
                                "(known: ppo_lagrangian, sac_lagrangian)"), str(error.value)


@pytest.mark.parametrize("agent", sorted(REFERENCE_AGENTS))
def test_ppo_lagrangian_reproduces_the_trainer_before_the_seam(tmp_path, agent):
    """The metrics of six tiny iterations equal those the trainer wrote before learners were a
    module of their own (``tests/data/reference_metrics``, written by ``tiny_runs.run_in_process``
    with :data:`REFERENCE_OVERRIDES` at the last commit before :mod:`crllk.algos`): equal in
    every printed digit on the machine that wrote them, and here up to the rounding by which
    CPUs' math kernels differ (``tiny_runs.ROUNDING``)."""
    run = run_in_process(tmp_path / agent, 6, [*REFERENCE_OVERRIDES, REFERENCE_AGENTS[agent]])
    reference = read_rows(REFERENCES / f"tiny-obstacle_loop-state-{agent}.csv")
    rows = read_rows(run / "metrics.csv")
    assert len(rows) == len(reference) == 6
    assert float(reference[-1]["lambda_lane"]) > 0.0  # the multiplier is exercised
    for row, expected in zip(rows, reference, strict=True):
        assert set(expected) <= set(row)
        for key, value in expected.items():
            a, b = float(row[key]), float(value)
            close = a == pytest.approx(b, rel=ROUNDING["rtol"], abs=ROUNDING["atol"])
            assert (math.isnan(a) and math.isnan(b)) or close, \
                (row["iteration"], key, row[key], value)


class StandStill:
    """A learner the package does not know: PPO-Lagrangian's networks, an update that only
    counts its batches."""

    name: ClassVar[str] = "stand_still"

    def __init__(self, inner: PPOLagrangian) -> None:
        self.actor, self.action_noise = inner.actor, inner.action_noise
        self.batches = torch.zeros(())
        self.seen: list[dict[str, float]] = []

    @classmethod
    def build(cls, config, env) -> StandStill:
        return cls(PPOLagrangian.build(config, env))

    @property
    def diagnostic_names(self) -> list[str]:
        return ["batches"]

    def prepare(self, frames: int, multipliers: Mapping[str, float]) -> None:
        self.seen.append(dict(multipliers))

    def needs_teacher(self, frames: int) -> bool:
        return False

    def update(self, batch: TensorDictBase, generator: torch.Generator) -> dict[str, float]:
        self.batches += 1
        return {"batches": float(self.batches)}

    def state_dict(self) -> dict[str, Any]:
        return {"actor": self.actor.state_dict(), "batches": self.batches.clone()}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.actor.load_state_dict(state["actor"])
        self.batches = state["batches"].clone()


def test_a_learner_the_trainer_does_not_know_trains_and_resumes(tmp_path, monkeypatch):
    """Registered under a new name, a learner trains through the same loop: its diagnostics
    are the metrics' columns (no PPO term among them), it receives the multipliers, its state
    goes into the checkpoint and a resumed run continues its count."""
    monkeypatch.setitem(algos.learners(), StandStill.name, StandStill)
    overrides = ["obs=state", "algo.learner=stand_still", "eval.final=false"]
    run = run_in_process(tmp_path / "run", 2, overrides)
    run_in_process(run, 3, [*overrides, "resume=true"])
    rows = read_rows(run / "metrics.csv")
    assert [r["batches"] for r in rows] == ["1", "2", "3"]
    assert not any(key.startswith("loss_") for key in rows[0])
    assert {"lambda_lane", "lambda_collision"} <= set(rows[0])


def test_a_run_whose_teacher_stops_resumes_exactly(tmp_path):
    """The teacher annealed to zero after two tiny iterations: a run stopped there collects its
    next batches without it, as the straight run does (no teacher action left over from before,
    none computed for a batch that does not use it)."""
    teacher = ["obs=state", "eval.final=false", "ppo.anneal_lr=false", "teacher.coeff=1.0",
               "teacher.frames=32", "teacher.final=0.0"]
    stopped = run_in_process(tmp_path / "stopped", 2, teacher)
    run_in_process(stopped, 4, [*teacher, "resume=true"])
    straight = run_in_process(tmp_path / "straight", 4, teacher)
    assert_same_runs(straight, stopped, 4)
    rows = read_rows(straight / "metrics.csv")
    assert float(rows[0]["loss_imitation"]) > 0 and float(rows[-1]["loss_imitation"]) == 0
