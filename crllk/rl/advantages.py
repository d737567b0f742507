"""GAE for the reward and for every cost: the advantages the λ-combination reads and the
value targets the critics' losses read (:class:`~crllk.rl.loss.CriticsPPOLoss`).

One TorchRL ``GAE`` per signal, its keys remapped, so a cost's advantage needs no code of its
own.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torchrl.objectives.value import GAE

from crllk.rl.lagrangian_advantage import REWARD_ADVANTAGE, check_cost_names, cost_advantage_key
from crllk.tasks.constraints import cost_key


class LossKeys(Protocol):
    """The keys of the loss the advantages are for (as :class:`~crllk.rl.loss.CriticsPPOLoss`
    names them)."""

    tensor_keys: Any
    """Its fixed keys: ``value``, ``value_target``, ..."""

    def cost_keys(self, name: str) -> tuple[NestedKey, NestedKey]:
        """(value target, value) keys of cost ``name``."""
        ...


@dataclass(frozen=True)
class AdvantageModules:
    """One TorchRL ``GAE`` for the reward and one per cost; calling it runs them all."""

    reward: GAE
    costs: dict[str, GAE]

    @torch.no_grad()
    def __call__(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Writes every advantage and value target into ``tensordict`` (shape [*B, T])."""
        self.reward(tensordict)
        for module in self.costs.values():
            module(tensordict)
        return tensordict


def make_advantage_modules(
    gamma: float,
    lmbda: float,
    critic_network: TensorDictModule,
    cost_critics: Mapping[str, TensorDictModule],
    *,
    loss: LossKeys | None = None,
    average_gae: bool = False,
    cost_gamma: float | None = None,
) -> AdvantageModules:
    """GAE(γ, λ_GAE) for the reward and for each cost: the value targets the loss reads, and
    the advantages the λ-combination reads (:mod:`crllk.rl.lagrangian_advantage`: the reward's
    in ``advantage_reward``, each cost's in ``advantage_<cost>``).

    Per signal x (reward, or cost c_i read from ``("next", "cost_<name>")``)::

        δ_t = x_t + γ (1 − terminated_t) V(s_{t+1}) − V(s_t)
        A_t = δ_t + γ λ_GAE (1 − done_t) A_{t+1},      G_t = A_t + V(s_t)

    with γ the costs' own discount ``cost_gamma`` for the costs where one is given.

    Args:
        gamma: Discount γ.
        lmbda: GAE λ.
        critic_network: Reward critic.
        cost_critics: Cost critics by name, as given to the loss.
        loss: The loss the advantages are for (a :class:`~crllk.rl.loss.CriticsPPOLoss`), so
            that renamed keys agree (default: the loss's default keys).
        average_gae: Standardise each advantage (leave ``False`` to combine them unscaled).
        cost_gamma: The costs' discount γ_c in place of γ (None: γ).
    """
    cost_gamma = gamma if cost_gamma is None else cost_gamma
    if not all(0.0 <= x <= 1.0 for x in (gamma, lmbda, cost_gamma)) \
            or math.isnan(gamma + lmbda + cost_gamma):
        raise ValueError(f"gamma, cost_gamma and lmbda must lie in [0, 1], got {gamma}, "
                         f"{cost_gamma}, {lmbda}")
    names = check_cost_names(tuple(cost_critics))
    reward = GAE(gamma=gamma, lmbda=lmbda, value_network=critic_network, average_gae=average_gae)
    keys = None if loss is None else loss.tensor_keys
    reward.set_keys(
        value=critic_network.out_keys[0] if keys is None else keys.value,
        advantage=REWARD_ADVANTAGE,
        value_target="value_target" if keys is None else keys.value_target,
    )
    costs = {}
    for name in names:
        critic = cost_critics[name]
        advantage = cost_advantage_key(name)
        if loss is None:
            target, value = f"value_target_{name}", critic.out_keys[0]
        else:
            target, value = loss.cost_keys(name)
        module = GAE(gamma=cost_gamma, lmbda=lmbda, value_network=critic,
                     average_gae=average_gae)
        module.set_keys(
            reward=cost_key(name), value=value, advantage=advantage, value_target=target
        )
        costs[name] = module
    return AdvantageModules(reward=reward, costs=costs)


__all__ = ["AdvantageModules", "LossKeys", "make_advantage_modules"]
