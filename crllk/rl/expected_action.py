"""A Gaussian policy deployed as its expected action.

A continuous policy samples ``tanh(x)``, x ~ N(loc, scale), at 30 Hz, and its actions map to
wheel duties linearly (:func:`crllk.tasks.actions.drive_turn_duty`) through motors whose delay
and first-order filters are linear in the duties. So the trained policy drives about as its
expected action E[tanh(x)] would, not as tanh(loc), the squashed mean TorchRL plays as its
deterministic action, which steers harder whenever the noise is large. :class:`ExpectedAction`
computes E[tanh(x)] per action dimension by the trapezoid rule on a fixed grid of standard
normal points (:data:`GRID_POINTS` over ±:data:`GRID_HALF_WIDTH`; within 1e-11 of the exact
integral in float64 for scales up to 3: a state-dependent spread is bounded below that,
:data:`~crllk.rl.model_config.STATE_LOG_STD_RANGE`, and every learned one so far ended below 1).
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import ProbabilisticActor

GRID_POINTS = 121
"""Points of :class:`ExpectedAction`'s standard normal grid."""
GRID_HALF_WIDTH = 7.0
"""Half width of that grid, in standard deviations."""


class ExpectedAction(nn.Module):
    """``(loc, scale)`` of a tanh-squashed Gaussian -> E[low + (high - low)(tanh(x) + 1) / 2],
    x ~ N(loc, scale), elementwise."""

    def __init__(self, low: torch.Tensor | float = -1.0, high: torch.Tensor | float = 1.0,
                 points: int = GRID_POINTS):
        super().__init__()
        grid = np.linspace(-GRID_HALF_WIDTH, GRID_HALF_WIDTH, points)
        weights = np.exp(-0.5 * grid**2)
        # the grid in double precision (cast to the input's dtype): float32 inputs get the
        # float32 rounding of exact weights
        self.register_buffer("points", torch.tensor(grid, dtype=torch.float64))
        self.register_buffer("weights", torch.tensor(weights / weights.sum(), dtype=torch.float64))
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32))
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32))

    def forward(self, loc: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
        points = self.points.to(loc.dtype)
        squashed = torch.tanh(loc.unsqueeze(-1) + scale.unsqueeze(-1) * points)
        mean = squashed @ self.weights.to(loc.dtype)
        low, high = self.low.to(loc.dtype), self.high.to(loc.dtype)
        return low + (high - low) * (mean + 1.0) / 2.0


def expected_action_policy(actor: ProbabilisticActor) -> TensorDictSequential:
    """The Gaussian ``actor`` as a module writing its expected action to ``"action"``; it
    ignores the exploration type: it never samples."""
    params = actor.module[0]
    if params.out_keys != ["loc", "scale"]:
        raise ValueError(f"expected a Gaussian policy writing 'loc' and 'scale', "
                         f"got {params.out_keys}")
    space = actor.spec["action"].space
    expected = ExpectedAction(space.low, space.high)
    return TensorDictSequential(params, TensorDictModule(expected, in_keys=["loc", "scale"],
                                                         out_keys=["action"]))
