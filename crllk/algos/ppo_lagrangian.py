"""PPO-Lagrangian, the paper's learner (``algo.learner=ppo_lagrangian``).

One update: GAE for the reward and every cost (:func:`crllk.rl.advantages.make_advantage_modules`),
the λ-combination of their advantages (:mod:`crllk.rl.lagrangian_advantage`), then ``ppo.epochs``
passes of minibatch PPO (:class:`crllk.rl.loss.CriticsPPOLoss`), each network's gradient clipped
on its own. The multipliers come from the trainer (learned by dual ascent or PID, or frozen at
fixed weights); the learning rate, the entropy bonus and the teacher's imitation weight follow
their schedules (:mod:`crllk.algos.schedules`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import torch
from tensordict import TensorDictBase

from crllk.algos.base import TrainingEnv
from crllk.algos.schedules import entropy_coeff, imitation_coeff, learning_rate
from crllk.config import TrainConfig
from crllk.rl.advantages import AdvantageModules, make_advantage_modules
from crllk.rl.gradients import clip_each_group_
from crllk.rl.lagrangian_advantage import LagrangianAdvantage
from crllk.rl.loss import CriticsPPOLoss
from crllk.rl.models import make_actor, make_critic, make_shared_critic
from crllk.rl.sampling import ActionNoise
from crllk.tasks.lane_keeping import state_feature_names


class PPOLagrangian:
    """The actor, a critic per signal (reward and each cost), the λ-combination, the PPO
    loss and its Adam optimiser (see the module's docs)."""

    name: ClassVar[str] = "ppo_lagrangian"

    def __init__(self, config: TrainConfig, actor: torch.nn.Module,
                 critics: dict[str, torch.nn.Module], cost_names: list[str]) -> None:
        ppo = config.ppo
        self.config = config
        self.actor = actor
        self.critics = critics  # "reward" and one per cost (one object when shared)
        self.loss = CriticsPPOLoss(actor, critics["reward"], {c: critics[c] for c in cost_names},
                                   clip_epsilon=ppo.clip_epsilon, entropy_coeff=ppo.entropy_coeff,
                                   critic_coeff=ppo.critic_coeff,
                                   normalize_advantage=ppo.normalize_advantage)
        self.advantages: AdvantageModules = make_advantage_modules(
            ppo.gamma, ppo.gae_lambda, critics["reward"], {c: critics[c] for c in cost_names},
            loss=self.loss, cost_gamma=ppo.cost_gamma)
        self.combination = LagrangianAdvantage(cost_names)
        # foreach: the same updates bit for bit, in fewer kernel launches (pixel update ~6 %)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=ppo.lr, foreach=True)
        self.action_noise = ActionNoise.seeded(config.seed, config.num_envs)
        # clip each network's gradient on its own, so large value errors do not shrink the
        # policy's step
        networks = {id(n): n for n in (actor, *critics.values())}
        self._gradient_groups = [list(n.parameters()) for n in networks.values()]

    @classmethod
    def build(cls, config: TrainConfig, env: TrainingEnv) -> PPOLagrangian:
        """Networks for ``env``'s observations (the critics see the privileged state with
        ``model.critic_input=state``), actions and constraints."""
        obs = config.obs.name
        shape = env.observation_spec[obs].shape[1:]
        model = config.model
        names = state_feature_names(env.config)
        commands_dim = env.observation_spec["commands"].shape[-1] if model.policy_commands else 0
        actor = make_actor(obs, shape, config.action.name, env.action_spec, model,
                           names if obs == "state" else None, commands_dim=commands_dim)
        costs = [c.name for c in env.constraints]
        value_keys = {"reward": "state_value", **{c: f"state_value_{c}" for c in costs}}
        critic_obs = "state" if model.critic_input == "state" else obs
        critic_shape = env.observation_spec[critic_obs].shape[1:]
        critic_names = names if critic_obs == "state" else None
        if model.shared_critic:
            shared = make_shared_critic(critic_obs, critic_shape, model,
                                        list(value_keys.values()), critic_names)
            critics = dict.fromkeys(value_keys, shared)
        else:
            critics = {name: make_critic(critic_obs, critic_shape, model, out_key=key,
                                         feature_names=critic_names)
                       for name, key in value_keys.items()}
        return cls(config, actor, critics, costs)

    @property
    def diagnostic_names(self) -> list[str]:
        return self.loss.out_keys

    def prepare(self, frames: int, multipliers: Mapping[str, float]) -> None:
        self.combination.set_multipliers(multipliers)
        self.loss.set_imitation_coeff(imitation_coeff(self.config, frames))
        self.loss.set_entropy_coeff(entropy_coeff(self.config, frames))
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate(self.config, frames)

    def needs_teacher(self, frames: int) -> bool:
        return imitation_coeff(self.config, frames) > 0

    def update(self, batch: TensorDictBase, generator: torch.Generator) -> dict[str, float]:
        """GAE for every signal, the λ-combination, then ``ppo.epochs`` passes of minibatch
        PPO; the mean of every loss term and diagnostic."""
        ppo = self.config.ppo
        self.advantages(batch)
        self.combination(batch)
        # only what the loss reads is indexed per minibatch (not the next observations)
        flat = batch.select(*self.loss.in_keys, self.loss.tensor_keys.teacher_action,
                            strict=False).reshape(-1)
        keys = self.loss.out_keys
        size, count = flat.shape[0], 0
        sums = torch.zeros(len(keys), dtype=torch.float64)
        for _ in range(ppo.epochs):
            # one gather per epoch; its minibatches are slices of it (the same rows)
            shuffled = flat[torch.randperm(size, generator=generator)]
            for start in range(0, size, ppo.minibatch_size):
                out = self.loss(shuffled[start:start + ppo.minibatch_size])
                total = sum(out[name] for name in self.loss.loss_names)
                self.optimizer.zero_grad(set_to_none=True)
                total.backward()
                clip_each_group_(self._gradient_groups, ppo.max_grad_norm)
                self.optimizer.step()
                sums += torch.stack([out[key].detach() for key in keys]).to("cpu", torch.float64)
                count += 1
        return {key: value / count for key, value in zip(keys, sums.tolist(), strict=True)}

    def state_dict(self) -> dict[str, Any]:
        return {"actor": self.actor.state_dict(),
                "critics": {name: critic.state_dict() for name, critic in self.critics.items()},
                "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.actor.load_state_dict(state["actor"])
        for name, critic in self.critics.items():
            critic.load_state_dict(state["critics"][name])
        self.optimizer.load_state_dict(state["optimizer"])


LEARNER = PPOLagrangian
