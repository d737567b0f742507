"""The cost critic's calibration (``python -m crllk.analysis.cost_critics``): the realised
discounted cost-to-go, its bins and the lead before a cost, in worked numbers."""

from __future__ import annotations

import math

import torch

from crllk.analysis.cost_critics import calibration, discounted_costs_to_go, lead


def _flags(*values: int) -> torch.Tensor:
    return torch.tensor([values]).bool()


def test_costs_to_go_stop_at_a_termination_and_bootstrap_at_a_truncation():
    """γ = 0.5; a collision ends the episode at step 2, the horizon cuts the next at step 4,
    the collection ends at step 5: G = c + γ·G', 0 after the termination, the critic's next
    value (0.5, then 0.25) after the cut and the last step."""
    cost = torch.tensor([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]])
    next_value = torch.tensor([[9.0, 9.0, 9.0, 9.0, 0.5, 0.25]])
    returns = discounted_costs_to_go(cost, _flags(0, 0, 1, 0, 0, 0), _flags(0, 0, 0, 0, 1, 0),
                                     next_value, 0.5)
    assert returns.tolist() == [[0.25, 0.5, 1.0, 0.125, 0.25, 0.125]]


def test_calibration_bins_the_prediction_and_averages_what_followed():
    predicted = torch.tensor([[0.0005, 0.002, 0.002, 0.5]])
    realised = torch.tensor([[0.0, 0.01, 0.03, 1.0]])
    rows = calibration(predicted, realised, edges=(0.001, 0.01))
    assert [r["steps"] for r in rows] == [1, 2, 1]
    assert math.isclose(rows[1]["predicted"], 0.002, rel_tol=1e-6)
    assert math.isclose(rows[1]["realised"], 0.02, rel_tol=1e-6)
    assert (rows[0]["from"], rows[2]["to"]) == (None, None)  # unbounded, and valid JSON
    assert calibration(predicted, realised, edges=(0.001, 0.01, 0.1))[2]["realised"] is None


def test_lead_counts_steps_before_a_cost_within_its_episode():
    """Two episodes in one series: the first ends at step 2 without a cost, so its steps lead to
    none; in the second the cost is at step 5: steps 3, 4, 5 are 3, 2, 1 steps before it."""
    predicted = torch.arange(6.0).reshape(1, 6)
    cost = torch.tensor([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0]])
    rows = lead(predicted, torch.zeros(1, 6), cost, _flags(0, 0, 1, 0, 0, 1),
                windows=((1, 1), (2, 3), (4, 9)))
    assert [r["steps"] for r in rows] == [1, 2, 0]
    assert rows[0]["predicted"] == 5.0 and rows[1]["predicted"] == 3.5


def test_every_simulation_s_series_stands_alone():
    """Two simulations side by side: a cost in one never reaches the other's steps, and each
    bootstraps from its own last next value."""
    cost = torch.tensor([[0.0, 1.0], [0.0, 0.0]])
    terminated = torch.tensor([[False, True], [False, False]])
    truncated = torch.zeros(2, 2, dtype=torch.bool)
    next_value = torch.tensor([[7.0, 7.0], [0.0, 0.4]])
    returns = discounted_costs_to_go(cost, terminated, truncated, next_value, 0.5)
    assert torch.allclose(returns, torch.tensor([[0.5, 1.0], [0.1, 0.2]]))
    rows = lead(torch.tensor([[0.3, 0.6], [0.9, 0.9]]), returns, cost, terminated | truncated,
                windows=((1, 2),))
    assert rows[0]["steps"] == 2 and math.isclose(rows[0]["predicted"], 0.45, rel_tol=1e-6)
    assert math.isclose(rows[0]["realised"], 0.75, rel_tol=1e-6)
