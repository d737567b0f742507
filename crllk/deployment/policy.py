"""The deterministic policy of a run as one network: an observation in, wheel duties out.

The input is what the trained policy reads, without a batch dimension: one camera image as
uint8 H×W×3 RGB (pixel runs) or the state features as float32 (state runs). The output is the
two wheel duty cycles (left, right) as float32, through the run's own action mapping
(:mod:`crllk.tasks.actions`), of the policy's deployed action: the expected duties of the
three discrete actions under the policy's probabilities (:mod:`crllk.rl.expected_duty`), or the
expected action of a Gaussian policy, the mean of its tanh-squashed actions
(:mod:`crllk.rl.expected_action`).
"""

from __future__ import annotations

import torch
from torch import nn
from torchrl.modules import ProbabilisticActor

from crllk.deployment.onnx_names import EXPORTABLE_ACTIONS
from crllk.rl.expected_action import ExpectedAction
from crllk.rl.expected_duty import ExpectedDuty
from crllk.sim.constants import WHEEL_DISTANCE, WHEEL_RADIUS
from crllk.tasks import actions


class DeployedPolicy(nn.Module):
    """``forward(observation) -> duty[2]`` of a trained actor (see the module docstring)."""

    def __init__(self, actor: ProbabilisticActor, action: str):
        super().__init__()
        if action not in EXPORTABLE_ACTIONS:
            raise ValueError(f"action must be one of {EXPORTABLE_ACTIONS}, got {action!r}")
        network = actor.module[0].module
        if len(actor.module[0].in_keys) != 1:
            raise ValueError("the policy reads its own recent commands (model.policy_commands); "
                             "only policies that read the observation alone can be deployed")
        self.network = network
        self.action = action
        self.expected_duty = ExpectedDuty()
        space = actor.spec["action"].space if action != "discrete" else None
        if space is not None and not (bool((space.low == -1).all()) and
                                      bool((space.high == 1).all())):
            raise ValueError(f"expected a Gaussian policy over [-1, 1]^2, got {space}")
        self.expected_action = ExpectedAction()

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        batch = observation.unsqueeze(0)
        if self.action == "discrete":
            return self.expected_duty(self.network(batch))[0]
        loc, scale = self.network(batch)
        velocity, steering = self.expected_action(loc[0], scale[0]).clamp(-1.0, 1.0).unbind(-1)
        if self.action in actions.LEAST_MEAN_DUTY:
            return drive_turn_duties(velocity, steering, actions.LEAST_MEAN_DUTY[self.action])
        return velocity_steering_duties(velocity, steering)


def drive_turn_duties(velocity: torch.Tensor, steering: torch.Tensor,
                      least: float = actions.MIN_MEAN_DUTY) -> torch.Tensor:
    """:func:`crllk.tasks.actions.drive_turn_duty` on tensors."""
    low, high = least, actions.MAX_MEAN_DUTY
    mean = low + 0.5 * (velocity + 1.0) * (high - low)
    half_difference = 0.5 * steering * actions.MAX_DUTY_DIFFERENCE
    return torch.stack([mean - half_difference, mean + half_difference])


def velocity_steering_duties(velocity: torch.Tensor, steering: torch.Tensor) -> torch.Tensor:
    """:func:`crllk.tasks.actions.velocity_steering_duty` on tensors."""
    rate_right = (velocity + 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    rate_left = (velocity - 0.5 * steering * WHEEL_DISTANCE) / WHEEL_RADIUS
    duty_left = rate_left * (actions.GAIN - actions.TRIM) / actions.MOTOR_CONSTANT
    duty_right = rate_right * (actions.GAIN + actions.TRIM) / actions.MOTOR_CONSTANT
    return torch.stack([duty_left, duty_right]).clamp(-actions.LIMIT, actions.LIMIT)
