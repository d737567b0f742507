"""A Gaussian policy's expected action E[tanh(x)], x ~ N(loc, scale): worked numbers against
an independent integral, and the policy a continuous actor plays as it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import integrate
from tensordict import TensorDict
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, set_exploration_type

from crllk.rl.expected_action import ExpectedAction, expected_action_policy
from crllk.rl.model_config import ModelConfig
from crllk.rl.models import make_actor


def _integral(loc: float, scale: float) -> float:
    """E[tanh(loc + scale·z)], z ~ N(0, 1), by adaptive quadrature."""
    density = 1.0 / math.sqrt(2.0 * math.pi)
    return integrate.quad(lambda z: math.tanh(loc + scale * z) * density * math.exp(-z * z / 2),
                          -12.0, 12.0, limit=400, epsabs=1e-12)[0]


@pytest.mark.parametrize("scale", [1e-4, 0.3, 0.95, 2.0, 3.0])
def test_expected_action_matches_the_integral(scale):
    locs = np.linspace(-4.0, 4.0, 17)
    module = ExpectedAction()
    got = module(torch.tensor(locs), torch.full((len(locs),), scale, dtype=torch.float64))
    assert got.tolist() == pytest.approx([_integral(m, scale) for m in locs], abs=1e-9)


def test_expected_action_worked_numbers():
    """Without noise it is tanh(loc); symmetric noise keeps 0 at 0; noise shrinks a turn:
    loc 1 with scale 0.95 (a trained CRLLK-C's steering noise) gives 0.564, not tanh(1) =
    0.762; the box [low, high] maps [-1, 1] affinely."""
    module = ExpectedAction()
    assert module(torch.tensor([1.0]), torch.tensor([1e-6])).item() == pytest.approx(
        math.tanh(1.0), abs=1e-6)
    assert module(torch.tensor([0.0]), torch.tensor([2.0])).item() == pytest.approx(0.0,
                                                                                  abs=1e-7)
    assert module(torch.tensor([1.0]), torch.tensor([0.95])).item() == pytest.approx(
        0.5639, abs=1e-4)
    boxed = ExpectedAction(low=torch.tensor([0.0]), high=torch.tensor([2.0]))
    assert boxed(torch.tensor([0.0]), torch.tensor([0.5])).item() == pytest.approx(1.0,
                                                                                 abs=1e-6)


def test_a_continuous_actor_plays_its_expected_action_whatever_the_exploration():
    spec = Bounded(-1.0, 1.0, shape=(4, 2))
    actor = make_actor("state", (5,), "continuous", spec, ModelConfig(encoder="mlp"))
    td = TensorDict({"state": torch.randn(4, 5)}, batch_size=[4])
    params = actor(td.clone())
    expected = ExpectedAction()(params["loc"], params["scale"])
    policy = expected_action_policy(actor)
    for exploration in (ExplorationType.RANDOM, ExplorationType.DETERMINISTIC):
        with set_exploration_type(exploration):
            assert torch.allclose(policy(td.clone())["action"], expected, atol=1e-6)
    boxed = make_actor("state", (5,), "continuous", Bounded(0.0, 2.0, shape=(4, 2)),
                       ModelConfig(encoder="mlp"))
    params = boxed(td.clone())
    with set_exploration_type(ExplorationType.DETERMINISTIC):
        assert torch.allclose(expected_action_policy(boxed)(td.clone())["action"],
                              1.0 + ExpectedAction()(params["loc"], params["scale"]),
                              atol=1e-6)
    with pytest.raises(ValueError, match="Gaussian policy"):
        expected_action_policy(make_actor("state", (5,), "discrete", spec,
                                          ModelConfig(encoder="mlp")))
