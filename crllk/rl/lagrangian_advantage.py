"""The λ-combination: one advantage from a reward advantage and one per cost.

For costs C_1..C_n with multipliers λ_i >= 0 the policy maximises the Lagrangian
J_R − Σ_i λ_i J_Ci. Its advantage is combined from one advantage per signal::

    A = (A_r − Σ_i λ_i A_ci) / (1 + Σ_i λ_i)

Dividing by 1 + Σλ keeps the advantage (and so the step size) of the same order however large λ
grows, when advantages are used as they are; the direction is that of the penalised reward
r − Σ λ_i c_i. A loss that standardises its advantage per minibatch (TorchRL's
``normalize_advantage``, the trainer's default) undoes any positive scale: the division then
changes nothing, and the multipliers alone set the balance between reward and costs.

:class:`LagrangianAdvantage` writes A where any policy-gradient loss reads its advantage, so the
loss itself needs to know nothing of constraints. The combination is linear, so the same module
on per-step signals gives the penalised reward (r − Σ_i λ_i c_i) / (1 + Σ_i λ_i) that a
value-based learner's stock loss can learn from (:mod:`crllk.algos.sac_lagrangian`). The
multipliers are learned outside it (:mod:`crllk.rl.lagrange`) and handed over with
:meth:`LagrangianAdvantage.set_multipliers`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torch import nn

REWARD_ADVANTAGE = "advantage_reward"
"""Where the reward's own advantage (its GAE) is written, before the combination."""
ADVANTAGE = "advantage"
"""Where the combined advantage goes: the key TorchRL's policy-gradient losses read."""


def cost_advantage_key(name: str) -> str:
    """Where the advantage of cost ``name`` is written."""
    return f"advantage_{name}"


def check_cost_names(names: Sequence[str]) -> tuple[str, ...]:
    """``names`` as a tuple, if every one is a Python identifier.

    Raises:
        ValueError: naming the first that is not.
    """
    for name in names:
        if not (isinstance(name, str) and name.isidentifier()):
            raise ValueError(f"cost names must be Python identifiers, got {name!r}")
    return tuple(names)


class LagrangianAdvantage(nn.Module):
    """Writes A = (A_r − Σ_i λ_i A_ci) / (1 + Σ_i λ_i), detached, into ``out_key``.

    Args:
        cost_names: the costs, in the order of the ``lagrange`` buffer.
        reward_key: the reward advantage read.
        out_key: where the combined advantage is written.
        cost_keys: where each cost's advantage is read (default ``advantage_<cost>``).
        lagrange: initial multipliers (zeros by default).
    """

    def __init__(self, cost_names: Sequence[str], *, reward_key: NestedKey = REWARD_ADVANTAGE,
                 out_key: NestedKey = ADVANTAGE, cost_keys: Mapping[str, NestedKey] | None = None,
                 lagrange: Sequence[float] | None = None) -> None:
        super().__init__()
        self.cost_names = check_cost_names(cost_names)
        self.reward_key, self.out_key = reward_key, out_key
        cost_keys = cost_keys or {}
        self.cost_keys = [cost_keys.get(n, cost_advantage_key(n)) for n in self.cost_names]
        self.register_buffer("lagrange", torch.zeros(len(self.cost_names)))
        if lagrange is not None:
            self.set_multipliers(lagrange)

    def set_multipliers(self, values: Sequence[float] | Mapping[str, float] | torch.Tensor) -> None:
        """Copies λ into the ``lagrange`` buffer (in ``cost_names`` order, or by name).

        Raises:
            ValueError: on a wrong number of values, unknown names or negative / non-finite λ.
        """
        if isinstance(values, Mapping):
            if set(values) != set(self.cost_names):
                raise ValueError(f"multipliers must name {self.cost_names}, got {sorted(values)}")
            values = [values[name] for name in self.cost_names]
        tensor = torch.as_tensor(values, dtype=self.lagrange.dtype).reshape(-1)
        if tensor.numel() != len(self.cost_names):
            raise ValueError(f"expected {len(self.cost_names)} multipliers {self.cost_names}, "
                             f"got {tensor.numel()}")
        if not torch.isfinite(tensor).all() or (tensor < 0).any():
            raise ValueError(f"multipliers must be finite and >= 0, got {tensor.tolist()}")
        self.lagrange.copy_(tensor)

    @property
    def multipliers(self) -> dict[str, float]:
        """Current λ by cost name."""
        return dict(zip(self.cost_names, self.lagrange.tolist(), strict=True))

    def combine(self, reward: torch.Tensor, costs: Sequence[torch.Tensor]) -> torch.Tensor:
        """A from the reward advantage and the cost advantages (``cost_names`` order), all of
        one shape; detached."""
        penalty = torch.zeros_like(reward)
        for weight, cost in zip(self.lagrange, costs, strict=True):
            penalty = penalty + weight * cost
        return ((reward - penalty) / (1.0 + self.lagrange.sum())).detach()

    @torch.no_grad()
    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Writes the combined advantage into ``tensordict`` (in place) and returns it.

        Raises:
            KeyError: naming an advantage the batch lacks.
        """
        missing = [k for k in (self.reward_key, *self.cost_keys)
                   if tensordict.get(k, None) is None]
        if missing:
            raise KeyError(f"the λ-combination needs the entries {missing}, which the batch "
                           "lacks (for advantages: one GAE per signal writes them first)")
        costs = [tensordict.get(key) for key in self.cost_keys]
        tensordict.set(self.out_key, self.combine(tensordict.get(self.reward_key), costs))
        return tensordict
