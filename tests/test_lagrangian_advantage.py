"""The λ-combination with worked numbers: A = (A_r − Σ λ_i A_ci) / (1 + Σ λ_i)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from crllk.rl.lagrangian_advantage import LagrangianAdvantage, cost_advantage_key


def _advantages(reward: float, lane: float, collision: float, n: int = 3) -> TensorDict:
    return TensorDict({"advantage_reward": torch.full((n, 1), reward),
                       "advantage_lane": torch.full((n, 1), lane),
                       "advantage_collision": torch.full((n, 1), collision),
                       "observation": torch.zeros(n, 4)}, [n])


@pytest.mark.parametrize(("lagrange", "expected"), [
    ((0.0, 0.0), 1.0),               # (1 − 0 − 0) / 1: the reward's advantage
    ((2.0, 0.0), (1 - 6) / 3),       # (1 − 2·3) / (1 + 2)
    ((2.0, 1.0), (1 - 6 - 0.5) / 4),  # (1 − 2·3 − 1·0.5) / (1 + 2 + 1)
    ((0.0, 9.0), (1 - 4.5) / 10),    # (1 − 9·0.5) / (1 + 9)
])
def test_the_combination_follows_the_formula(lagrange, expected):
    td = LagrangianAdvantage(("lane", "collision"), lagrange=lagrange)(_advantages(1.0, 3.0, 0.5))
    torch.testing.assert_close(td["advantage"], torch.full((3, 1), expected))
    assert not td["advantage"].requires_grad
    # what it read is left as it was
    torch.testing.assert_close(td["advantage_reward"], torch.ones(3, 1))


def test_a_task_without_costs_passes_the_reward_advantage_through():
    td = TensorDict({"advantage_reward": torch.tensor([[0.25], [-2.0]])}, [2])
    out = LagrangianAdvantage(())(td)
    torch.testing.assert_close(out["advantage"], torch.tensor([[0.25], [-2.0]]))


def test_a_missing_advantage_is_named():
    td = _advantages(1.0, 3.0, 0.5).exclude(cost_advantage_key("collision"))
    with pytest.raises(KeyError, match="advantage_collision"):
        LagrangianAdvantage(("lane", "collision"))(td)


def test_set_multipliers_validates():
    combination = LagrangianAdvantage(("lane", "collision"))
    combination.set_multipliers(torch.tensor([0.5, 4.0]))
    assert combination.multipliers == {"lane": 0.5, "collision": 4.0}
    assert torch.equal(combination.state_dict()["lagrange"], torch.tensor([0.5, 4.0]))
    combination.set_multipliers({"collision": 1.0, "lane": 2.0})
    assert combination.multipliers == {"lane": 2.0, "collision": 1.0}
    with pytest.raises(ValueError, match="expected 2 multipliers"):
        combination.set_multipliers([1.0])
    with pytest.raises(ValueError, match="finite and >= 0"):
        combination.set_multipliers([1.0, -0.1])
    with pytest.raises(ValueError, match="finite and >= 0"):
        combination.set_multipliers([1.0, float("inf")])
    with pytest.raises(ValueError, match="must name"):
        combination.set_multipliers({"lane": 1.0})
    with pytest.raises(ValueError, match="identifiers"):
        LagrangianAdvantage(("lane", "two words"))
