"""A discrete policy deployed as its expected wheel duties.

The three discrete actions are wheel duty pairs (:data:`crllk.tasks.actions.DISCRETE_DUTIES`).
Sampled at 30 Hz through the motors' delay and first-order filters, which are linear in the
duties, the trained policy drives about as its probability-weighted mean duty
Σ_i p_i · duty_i would; its most probable action alone is a bang-bang controller that training
never played. So the deployed policy of a discrete run, in evaluation and on the robot, is
that mean: :class:`ExpectedDuty` maps the policy's logits to it.
"""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import ProbabilisticActor

from crllk.tasks.actions import DISCRETE_DUTIES


class ExpectedDuty(nn.Module):
    """Logits ``[*B, 3]`` of the discrete actions -> expected wheel duties ``[*B, 2]``
    (left, right): softmax(logits) @ :data:`~crllk.tasks.actions.DISCRETE_DUTIES`."""

    def __init__(self):
        super().__init__()
        self.register_buffer("duties", torch.tensor(DISCRETE_DUTIES, dtype=torch.float32))

    def forward(self, logits: torch.Tensor) -> torch.Tensor:
        return torch.softmax(logits, dim=-1) @ self.duties.to(logits.dtype)


def expected_duty_policy(actor: ProbabilisticActor) -> TensorDictSequential:
    """The discrete ``actor`` as a module writing its expected duties to ``"action"`` (for an
    environment of ``duty`` actions); it ignores the exploration type: it never samples."""
    logits = actor.module[0]
    if logits.out_keys != ["logits"]:
        raise ValueError(f"expected a discrete policy writing 'logits', got {logits.out_keys}")
    return TensorDictSequential(logits, TensorDictModule(ExpectedDuty(), in_keys=["logits"],
                                                         out_keys=["action"]))
