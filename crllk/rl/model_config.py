"""The sizes and shape of the policy and value networks: the ``model`` settings of a run,
read without importing torch (:mod:`crllk.rl.models` builds the networks from them)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from crllk.settings import one_of, positive, setting

STATE_LOG_STD_RANGE = (-5.0, 1.0)
"""Bounds of a state-dependent log standard deviation (σ from 0.007 to 2.7 before the tanh,
within the scales whose expected action :mod:`crllk.rl.expected_action` integrates to 1e-11)."""


@dataclass
class ModelConfig:
    """Sizes of the networks.

    Attributes:
        encoder: ``"fast"`` or ``"original"`` for pixels; state always uses ``"mlp"``.
        hidden: width of the hidden layers of the state MLP and of the heads.
        feature_dim: width of the pixel encoder's output layer.
        initial_log_std: log standard deviation of the continuous actor's first actions
            (before the tanh squashing).
        max_log_std: the most that log standard deviation may be (None: no bound); the learned
            parameter (or, with ``state_dependent_std``, each observation's value) is clamped
            to it where the actor is evaluated, so above it no gradient flows.
        shared_critic: one encoder with a value head for the reward and each cost, instead
            of one network per critic.
        critic_input: what the critics read: ``"observation"`` (the policy's input) or
            ``"state"`` (the lane-relative features, also with pixel policies: an asymmetric
            actor-critic; critics only shape training, so the policy still drives from pixels).
        policy_commands: the policy also reads its own wheel commands of the last steps (those
            still in flight through the motor delay), which a robot knows without sensing.
        state_dependent_std: the continuous actor's log standard deviations are outputs of
            its network (per observation, starting at ``initial_log_std`` everywhere, within
            :data:`STATE_LOG_STD_RANGE`) instead of one learned parameter per action.
    """

    encoder: str = setting("fast", check=one_of("fast", "original"))
    hidden: int = setting(64, check=positive)
    feature_dim: int = setting(256, check=positive)
    initial_log_std: float = -0.5
    max_log_std: float | None = None
    shared_critic: bool = False
    critic_input: str = setting("observation", check=one_of("observation", "state"))
    policy_commands: bool = False
    state_dependent_std: bool = False

    def problems(self) -> Iterator[tuple[str, str]]:
        if not self.state_dependent_std:
            return
        low, high = STATE_LOG_STD_RANGE
        if self.max_log_std is not None:
            high = min(high, self.max_log_std)
            if self.max_log_std < low:
                yield "max_log_std", (f"must be at least {low} with state_dependent_std, got "
                                      f"{self.max_log_std}")
                return
        if not low <= self.initial_log_std <= high:
            yield "initial_log_std", (f"must lie in [{low}, {high}] with state_dependent_std "
                                      f"(and max_log_std), got {self.initial_log_std}")


__all__ = ["STATE_LOG_STD_RANGE", "ModelConfig"]
