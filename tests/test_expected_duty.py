"""A discrete policy deployed as its expected wheel duties: worked numbers, and the policy a
discrete actor plays in a duty environment (a run's evaluation: ``tests/test_evaluate.py``)."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.rl.expected_duty import ExpectedDuty, expected_duty_policy
from crllk.rl.model_config import ModelConfig
from crllk.rl.models import make_actor
from crllk.tasks.actions import DISCRETE_DUTIES
from crllk.training.runs import deployed_form


def test_expected_duty_worked_numbers():
    """Probabilities 0.6 / 0.2 / 0.2 (left, right, straight) drive
    left 0.6·0.04 + 0.2·0.4 + 0.2·0.3 = 0.164 and right 0.6·0.4 + 0.2·0.04 + 0.2·0.3 = 0.308;
    one certain action drives its own pair."""
    logits = torch.tensor([[math.log(3.0), 0.0, 0.0], [0.0, 50.0, 0.0]])
    duty = ExpectedDuty()(logits)
    assert duty[0].tolist() == pytest.approx([0.164, 0.308], abs=1e-6)
    assert duty[1].tolist() == pytest.approx(DISCRETE_DUTIES[1].tolist(), abs=1e-6)


def test_a_discrete_actor_built_for_duty_actions_keeps_its_three_actions():
    """Built on a duty env's spec, a discrete actor still has three logits and samples an
    index; as the expected-duty policy it writes the duties for every exploration type."""
    from torchrl.data import Bounded

    spec = Bounded(-1.0, 1.0, shape=(4, 2))
    actor = make_actor("state", (5,), "discrete", spec, ModelConfig(encoder="mlp"))
    td = TensorDict({"state": torch.randn(4, 5)}, batch_size=[4])
    sampled = actor(td.clone())
    assert sampled["action"].shape == (4,) and sampled["logits"].shape == (4, 3)
    policy = expected_duty_policy(actor)
    expected = torch.softmax(sampled["logits"], -1) @ torch.tensor(DISCRETE_DUTIES,
                                                                     dtype=torch.float32)
    for exploration in (ExplorationType.RANDOM, ExplorationType.DETERMINISTIC):
        with set_exploration_type(exploration):
            assert torch.allclose(policy(td.clone())["action"], expected, atol=1e-6)


def test_deployed_form():
    assert deployed_form("discrete") == "expected_duty"
    assert deployed_form("continuous") == deployed_form("stoppable") == "expected_action"
