"""The PPO clip loss of a policy whose advantage comes combined, with a value loss per critic.

The loss reads a ready advantage (for constrained learning the λ-combination of
:mod:`crllk.rl.lagrangian_advantage` writes it), optionally standardises it per minibatch, and
adds one value loss for the reward critic and one per cost critic, and an imitation term. The
advantages and value targets come from the GAE modules of
:func:`~crllk.rl.advantages.make_advantage_modules`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModule
from tensordict.utils import NestedKey
from torch import nn
from torch.distributions import Distribution
from torchrl.modules import ProbabilisticActor, TanhNormal
from torchrl.objectives import LossModule

from crllk.rl.advantages import AdvantageModules, make_advantage_modules
from crllk.rl.direct import actor_distribution, run_module
from crllk.rl.lagrangian_advantage import check_cost_names

_ADVANTAGE_STD_EPS = 1e-6  # floor of the advantage std when standardising (advantage units)
_TEACHER_MARGIN = 1e-3  # continuous teacher actions are clamped this far inside [-1, 1]


def _cost_key_defaults(name: str) -> dict[str, str]:
    """Accepted-key field name -> default tensordict key, for one cost."""
    return {
        f"value_target_{name}": f"value_target_{name}",
        f"value_{name}": f"state_value_{name}",
    }


class CriticsPPOLoss(LossModule):
    """PPO clip loss on a given advantage, with a value loss for every critic.

    Per sample, with ratio ρ = π_θ(a|s) / π_old(a|s) and the advantage A read from the batch
    (optionally standardised over the minibatch when ``normalize_advantage``)::

        loss_objective   = −mean(min(ρ·A, clip(ρ, 1−ε, 1+ε)·A))
        loss_critic      = c_v · mean((V_r(s) − G_r)²)
        loss_cost_critic = c_v · Σ_i mean((V_ci(s) − G_ci)²)
        loss_entropy     = −c_H · mean(H[π_θ(·|s)])
        loss_imitation   = −c_I · mean(log π_θ(a_teacher|s))

The imitation term pulls the policy towards a teacher's action ``teacher_action`` recorded for
each state (:mod:`crllk.tasks.teacher`); its weight c_I (``imitation_coeff``, settable between
updates) is 0 by default, and then the term is 0 and needs no teacher key. For a tanh-Gaussian
policy the term moves only the mean: the scale enters it detached, because a scripted teacher
says what to do, not how sure the policy should be, and its corrections at the edge of the box
(atanh of nearly ±1) would otherwise inflate the policy's noise.

    The sum of the ``loss_*`` entries is the quantity to minimise (:attr:`loss_names`).
    Diagnostics (detached): ``entropy``, ``kl_approx`` = mean((ρ − 1) − log ρ) (the
    non-negative "k3" estimator, where TorchRL's ``ClipPPOLoss`` reports mean(−log ρ)),
    ``clip_fraction``, ``explained_variance`` and ``explained_variance_<cost>``. The objective
    and entropy terms equal TorchRL's ``ClipPPOLoss`` on the same data.

    Keys (see ``set_keys``): ``advantage``, ``value_target``, ``value``, ``sample_log_prob``,
    ``action``, and per cost ``value_target_<cost>``, ``value_<cost>`` (defaults
    ``"value_target_<cost>"``, the critic's output key). A value entry may have the batch shape
    or the batch shape plus a trailing 1.

    Args:
        actor_network: A single-head probabilistic actor (``get_dist`` on a tensordict).
        critic_network: Reward critic writing one value key.
        cost_critics: One critic per cost, by cost name (an identifier). Every critic must
            write its own value key.
        clip_epsilon: ε of the ratio clip.
        entropy_coeff: c_H.
        critic_coeff: c_v, shared by reward and cost critics.
        normalize_advantage: standardise the advantage over the minibatch.
    """

    loss_names = ("loss_objective", "loss_critic", "loss_cost_critic", "loss_entropy",
                  "loss_imitation")
    """The terms whose sum is minimised."""

    @dataclass
    class _AcceptedKeys:
        """Tensordict keys read by the loss, apart from the per-cost ones (:meth:`cost_keys`)."""

        advantage: NestedKey = "advantage"
        value_target: NestedKey = "value_target"
        value: NestedKey = "state_value"
        sample_log_prob: NestedKey = "action_log_prob"
        action: NestedKey = "action"
        teacher_action: NestedKey = "teacher_action"

    default_keys = _AcceptedKeys
    tensor_keys: _AcceptedKeys
    _schedulable_buffers = frozenset({"clip_epsilon", "entropy_coeff", "critic_coeff",
                                      "imitation_coeff"})

    actor_network: ProbabilisticActor
    critic_network: TensorDictModule
    cost_critics: nn.ModuleDict

    def __init__(
        self,
        actor_network: ProbabilisticActor,
        critic_network: TensorDictModule,
        cost_critics: Mapping[str, TensorDictModule],
        *,
        clip_epsilon: float = 0.2,
        entropy_coeff: float = 0.01,
        critic_coeff: float = 1.0,
        normalize_advantage: bool = False,
    ) -> None:
        super().__init__()
        self.cost_names: tuple[str, ...] = check_cost_names(tuple(cost_critics))
        self.actor_network = actor_network
        self.critic_network = critic_network
        self.cost_critics = nn.ModuleDict(dict(cost_critics))
        self._init_keys()
        if not 0.0 < clip_epsilon < 1.0:
            raise ValueError(f"clip_epsilon must lie in (0, 1), got {clip_epsilon}")
        self.register_coeff_buffer("clip_epsilon", clip_epsilon)
        self.register_coeff_buffer("entropy_coeff", entropy_coeff)
        self.register_coeff_buffer("critic_coeff", critic_coeff)
        self.register_coeff_buffer("imitation_coeff", 0.0)
        self.normalize_advantage = normalize_advantage

    @property
    def functional(self) -> bool:
        """The networks are used as they are (no functional parameter copies)."""
        return False

    # ---------------------------------------------------------------- keys

    def _init_keys(self) -> None:
        """The fixed keys (TorchRL's ``tensor_keys``) and three per cost, by field name."""
        self._cost_tensor_keys: dict[str, NestedKey] = {
            name: default for cost in self.cost_names
            for name, default in _cost_key_defaults(cost).items()}
        self._take_keys_from_networks()

    def set_keys(self, **kwargs: NestedKey) -> None:
        """TorchRL's ``set_keys``, which also takes the per-cost fields ``value_target_<cost>``
        and ``value_<cost>``; an unknown field raises ValueError."""
        for name in [k for k in kwargs if k in self._cost_tensor_keys]:
            self._cost_tensor_keys[name] = kwargs.pop(name)
        if kwargs:
            super().set_keys(**kwargs)

    def _take_keys_from_networks(self) -> None:
        """Reads action, log-prob and value keys from the networks, as TorchRL's PPO does."""
        log_prob_keys = getattr(self.actor_network, "log_prob_keys", [])
        sample_keys = getattr(self.actor_network, "dist_sample_keys", [])
        if len(log_prob_keys) == 1 and len(sample_keys) == 1:
            self.set_keys(sample_log_prob=log_prob_keys[0], action=sample_keys[0])
        critics = {"value": self.critic_network}
        critics.update({f"value_{name}": self.cost_critics[name] for name in self.cost_names})
        for field_name, critic in critics.items():
            out_keys = getattr(critic, "out_keys", [])
            if len(out_keys) == 1:
                self.set_keys(**{field_name: out_keys[0]})
        value_keys = [self.tensor_keys.value, *(self.cost_keys(n)[1] for n in self.cost_names)]
        if len(set(value_keys)) != len(value_keys):
            raise ValueError(
                f"every critic must write its own value key, got {value_keys}; e.g. "
                "ValueOperator(net, in_keys=[...], out_keys=['state_value_lane'])"
            )

    def _forward_value_estimator_keys(self, **kwargs: Any) -> None:
        """No value estimator lives inside this loss; advantages come precomputed."""

    def cost_keys(self, name: str) -> tuple[NestedKey, NestedKey]:
        """(value target, value) keys of cost ``name``."""
        keys = self._cost_tensor_keys
        return keys[f"value_target_{name}"], keys[f"value_{name}"]

    @property
    def in_keys(self) -> list[NestedKey]:
        keys = [*self.actor_network.in_keys, *self.critic_network.in_keys]
        for critic in self.cost_critics.values():
            keys += critic.in_keys
        k = self.tensor_keys
        keys += [k.action, k.sample_log_prob, k.advantage, k.value_target]
        for name in self.cost_names:
            keys.append(self.cost_keys(name)[0])
        return list(dict.fromkeys(keys))

    @property
    def out_keys(self) -> list[str]:
        names = [*self.loss_names, "entropy", "kl_approx", "clip_fraction", "explained_variance"]
        return names + [f"explained_variance_{name}" for name in self.cost_names]

    # ------------------------------------------------------------ the loss

    def advantage(self, tensordict: TensorDictBase) -> torch.Tensor:
        """The batch's advantage, standardised if asked; shape [*B, 1]."""
        advantage = _column(_get(tensordict, self.tensor_keys.advantage),
                            tensordict.batch_size).detach()
        if self.normalize_advantage and advantage.numel() > 1:
            advantage = (advantage - advantage.mean()) / advantage.std().clamp_min(
                _ADVANTAGE_STD_EPS
            )
        return advantage

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Computes the losses and diagnostics on a batch of transitions (see class docs)."""
        td = tensordict.clone(False)  # the networks write their outputs here, not in the input
        advantage = self.advantage(td)
        log_ratio, dist = self._log_ratio(td)
        loss_objective, clip_fraction = self._clip_objective(log_ratio, advantage)
        entropy = _entropy(dist)
        self.evaluate_critics(td)
        loss_critic, explained = self._value_loss(
            td, self.tensor_keys.value, self.tensor_keys.value_target
        )
        out = {
            "loss_objective": loss_objective,
            "loss_critic": loss_critic,
            "loss_cost_critic": torch.zeros_like(loss_critic),
            "loss_entropy": -self.entropy_coeff * entropy.mean(),
            "loss_imitation": self._imitation_loss(td, dist),
            "entropy": entropy.detach().mean(),
            "kl_approx": (log_ratio.exp() - 1.0 - log_ratio).detach().mean(),
            "clip_fraction": clip_fraction,
            "explained_variance": explained,
        }
        for name in self.cost_names:
            target_key, value_key = self.cost_keys(name)
            loss, explained = self._value_loss(td, value_key, target_key)
            out["loss_cost_critic"] = out["loss_cost_critic"] + loss
            out[f"explained_variance_{name}"] = explained
        return TensorDict(out, batch_size=[])

    def set_entropy_coeff(self, value: float) -> None:
        """Sets c_H, the weight of the entropy bonus."""
        self.entropy_coeff.fill_(_non_negative("entropy_coeff", value))

    def set_imitation_coeff(self, value: float) -> None:
        """Sets c_I, the weight of the imitation term (0 switches it off)."""
        self.imitation_coeff.fill_(_non_negative("imitation_coeff", value))

    def _imitation_loss(self, td: TensorDictBase, dist: Distribution) -> torch.Tensor:
        """−c_I · mean(log π_θ(a_teacher|s)); 0 when c_I is 0. Continuous teacher actions are
        kept just inside the box, where a tanh-squashed policy's density is finite, and the
        tanh-Gaussian's scale is detached (the term trains its mean only)."""
        if float(self.imitation_coeff) == 0.0:
            return torch.zeros((), dtype=self.imitation_coeff.dtype)
        target = _get(td, self.tensor_keys.teacher_action)
        if target.is_floating_point():
            target = target.clamp(-1.0 + _TEACHER_MARGIN, 1.0 - _TEACHER_MARGIN)
        if isinstance(dist, TanhNormal):
            dist = TanhNormal(dist.loc, dist.scale.detach(), upscale=dist.upscale, low=dist.low,
                              high=dist.high, tanh_loc=dist.tanh_loc)
        return -self.imitation_coeff * dist.log_prob(target).mean()

    def _log_ratio(self, td: TensorDictBase) -> tuple[torch.Tensor, Distribution]:
        """log ρ = log π_θ(a|s) − log π_old(a|s), shape [*B, 1], and the current π_θ."""
        dist = actor_distribution(self.actor_network, td)
        log_prob = dist.log_prob(_get(td, self.tensor_keys.action).detach())
        old_log_prob = _get(td, self.tensor_keys.sample_log_prob).detach()
        return _column(log_prob - old_log_prob, td.batch_size), dist

    def _clip_objective(
        self, log_ratio: torch.Tensor, advantage: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """−mean(min(ρ·A, clip(ρ, 1−ε, 1+ε)·A)) and the fraction of clipped ratios."""
        bounds = ((-self.clip_epsilon).log1p(), self.clip_epsilon.log1p())
        clipped = log_ratio.clamp(*bounds)
        gain = torch.minimum(log_ratio.exp() * advantage, clipped.exp() * advantage)
        clip_fraction = (clipped != log_ratio).to(log_ratio.dtype).mean().detach()
        return -gain.mean(), clip_fraction

    def evaluate_critics(self, td: TensorDictBase) -> None:
        """Runs every distinct critic once on ``td``; one network with several value heads
        (shared by the reward and the costs) runs only once."""
        seen: set[int] = set()
        for critic in (self.critic_network, *self.cost_critics.values()):
            if id(critic) not in seen:
                seen.add(id(critic))
                run_module(critic, td)

    def _value_loss(
        self, td: TensorDictBase, value_key: NestedKey, target_key: NestedKey
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """c_v · mean((V(s) − G)²) and the explained variance 1 − Var(G − V) / Var(G)."""
        target = _column(_get(td, target_key), td.batch_size).detach()
        value = _column(_get(td, value_key), td.batch_size)
        loss = self.critic_coeff * (value - target).pow(2).mean()
        return loss, explained_variance(value.detach(), target)


def explained_variance(prediction: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """1 − Var(target − prediction) / Var(target) over all elements (1 is perfect, 0 useless)."""
    eps = torch.finfo(target.dtype).eps
    residual = torch.var(target - prediction, correction=0)
    return 1.0 - residual / (torch.var(target, correction=0) + eps)


def _entropy(dist: Distribution) -> torch.Tensor:
    """Analytic entropy per sample, or a one-sample estimate −log π(x), x ~ π, without one."""
    try:
        entropy = dist.entropy()
    except NotImplementedError:  # e.g. TanhNormal
        entropy = None
    if entropy is None or not torch.isfinite(entropy).all():
        sample = dist.rsample() if dist.has_rsample else dist.sample()
        entropy = -dist.log_prob(sample)
    return entropy


def _get(td: TensorDictBase, key: NestedKey) -> torch.Tensor:
    value = td.get(key, None)
    if value is None:
        raise KeyError(
            f"the loss needs the entry {key!r}, which the batch lacks (advantages and value "
            "targets come from make_advantage_modules; renamed keys go through set_keys)"
        )
    return value


def _column(value: torch.Tensor, batch_shape: torch.Size) -> torch.Tensor:
    """Returns ``value`` with shape [*batch_shape, 1] (accepts [*B] or [*B, 1])."""
    if value.shape == batch_shape:
        return value.unsqueeze(-1)
    if value.shape == (*batch_shape, 1):
        return value
    expected = f"{[*batch_shape]} or {[*batch_shape, 1]}"
    raise ValueError(f"expected an entry of shape {expected}, got {[*value.shape]}")


def _non_negative(name: str, value: float) -> float:
    """``value`` if it is finite and >= 0; a ValueError naming ``name`` otherwise."""
    if not (value >= 0.0 and math.isfinite(value)):
        raise ValueError(f"{name} must be finite and >= 0, got {value}")
    return value


__all__ = ["AdvantageModules", "CriticsPPOLoss", "explained_variance", "make_advantage_modules"]
