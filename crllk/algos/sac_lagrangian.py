"""SAC-Lagrangian, off-policy (``algo=sac_lagrangian``, or ``algo.learner=sac_lagrangian``).

Soft actor-critic on the penalised reward (r − Σ_i λ_i c_i) / (1 + Σ_i λ_i): every collected
transition goes into a replay buffer with its reward and costs; each update samples minibatches
from it, combines reward and costs with the multipliers of that moment
(:class:`crllk.rl.lagrangian_advantage.LagrangianAdvantage` on per-step signals), and takes a
step of TorchRL's ``DiscreteSACLoss`` (discrete actions) or ``SACLoss`` (continuous) as they
are, twin Q-networks with Polyak-averaged targets and the entropy temperature tuned to a target
entropy. Because λ is applied when a transition is sampled, a transition stored long ago is
judged with today's multipliers. The multipliers are the trainer's (dual ascent or PID on the
episodes' costs, or frozen); the policy is the same network as PPO-Lagrangian's, so
evaluation, recording and export do not change. No teacher: its imitation term belongs to
PPO-Lagrangian.

From state only (``obs=state``): a buffer of camera images at this size (200,000 frames of
30×40×3) would hold 720 MB and go into every checkpoint.

Its settings are ``algo.options.*`` (:class:`SACSettings`, their values in
``crllk/conf/algo/sac_lagrangian.yaml``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.objectives import DiscreteSACLoss, SACLoss, SoftUpdate, ValueEstimators

from crllk.algos.base import TrainingEnv
from crllk.config import SOURCE, TrainConfig
from crllk.errors import ConfigError
from crllk.rl.lagrangian_advantage import LagrangianAdvantage
from crllk.rl.models import make_actor, make_encoder
from crllk.rl.plain import tensordict_from_plain, tensordict_to_plain
from crllk.rl.sampling import ActionNoise
from crllk.settings import non_negative, open_unit_interval, parse, positive, setting, unit_interval
from crllk.tasks.actions import DISCRETE_DUTIES
from crllk.tasks.constraints import cost_key
from crllk.tasks.lane_keeping import state_feature_names

OPTIONS = "algo.options."
PENALISED_REWARD = "penalised_reward"
"""The entry of ``next`` the Q-targets read: the λ-combination of reward and costs."""


@dataclass
class SACSettings:
    """SAC-Lagrangian's settings (``algo.options.<name>``); their values are in
    ``crllk/conf/algo/sac_lagrangian.yaml``, so that composing a command's configuration does
    not import the learners."""

    def problems(self) -> list[tuple[str, str]]:
        if self.buffer_frames < max(self.warmup_frames, self.batch_size):
            return [("buffer_frames", f"must hold warmup_frames ({self.warmup_frames}) and "
                     f"batch_size ({self.batch_size}), got {self.buffer_frames}")]
        return []

    gamma: float = setting(check=unit_interval)
    """Discount of the soft Q-values."""
    lr: float = setting(check=positive)
    """Adam's learning rate, for the policy, the Q-networks and the temperature."""
    batch_size: int = setting(check=positive)
    """Transitions per gradient step."""
    buffer_frames: int = setting(check=positive)
    """Replay capacity (frames); the oldest are overwritten."""
    warmup_frames: int = setting(check=non_negative)
    """No gradient step until the buffer holds this many frames."""
    updates_per_frame: float = setting(check=positive)
    """Gradient steps per collected frame (0.125: 128 per iteration of 1,024 frames)."""
    tau: float = setting(check=open_unit_interval)
    """Polyak step of the target Q-networks."""
    alpha_init: float = setting(check=positive)
    """Initial entropy temperature."""
    target_entropy_fraction: float = setting(check=open_unit_interval)
    """Discrete actions: the target entropy as a fraction of the uniform policy's (log of the
    number of actions); continuous: −(action dimensions)."""
    max_grad_norm: float = setting(check=positive)
    """The gradient norms of the policy, of the Q-networks and of the temperature are each
    clipped to this."""


class QNetwork(nn.Module):
    """Q(s, ·) for every discrete action, or Q(s, a) for a continuous one (``action_dim``)."""

    def __init__(self, encoder: nn.Module, width: int, hidden: int, out_dim: int,
                 action_dim: int = 0) -> None:
        super().__init__()
        self.encoder, self.action_dim = encoder, action_dim
        self.head = nn.Sequential(nn.Linear(width + action_dim, hidden), nn.ReLU(),
                                  nn.Linear(hidden, out_dim))

    def forward(self, observation: torch.Tensor, action: torch.Tensor | None = None
                ) -> torch.Tensor:
        features = self.encoder(observation)
        if self.action_dim:
            features = torch.cat([features, action], dim=-1)
        return self.head(features)


class ReplayRing:
    """The last ``capacity`` transitions, sampled uniformly with the run's generator (so a
    resumed run samples what the uninterrupted one would)."""

    def __init__(self, capacity: int) -> None:
        self.capacity, self.cursor, self.size = capacity, 0, 0
        self.storage: TensorDictBase | None = None

    def add(self, transitions: TensorDictBase) -> None:
        if self.storage is None:
            self.storage = transitions[0].expand(self.capacity).clone()
        count = transitions.shape[0]
        where = (self.cursor + torch.arange(count)) % self.capacity
        self.storage[where] = transitions
        self.cursor = (self.cursor + count) % self.capacity
        self.size = min(self.size + count, self.capacity)

    def sample(self, count: int, generator: torch.Generator) -> TensorDictBase:
        return self.storage[torch.randint(self.size, (count,), generator=generator)]

    def state_dict(self) -> dict[str, Any]:
        kept = None if self.storage is None else tensordict_to_plain(self.storage[:self.size])
        return {"cursor": self.cursor, "size": self.size, "storage": kept}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.cursor, self.size, self.storage = state["cursor"], state["size"], None
        if state["storage"] is not None:
            kept = tensordict_from_plain(state["storage"])
            self.storage = kept[0].expand(self.capacity).clone()
            self.storage[:self.size] = kept


class SACLagrangian:
    """The policy, twin Q-networks with targets, the temperature, their optimiser and the
    replay buffer (see the module's docs)."""

    name: ClassVar[str] = "sac_lagrangian"
    LOSS_NAMES: ClassVar[tuple[str, ...]] = ("loss_actor", "loss_qvalue", "loss_alpha")

    def __init__(self, config: TrainConfig, settings: SACSettings, actor: nn.Module,
                 loss: SACLoss | DiscreteSACLoss, cost_names: list[str]) -> None:
        self.settings = settings
        self.actor, self.loss = actor, loss
        loss.make_value_estimator(ValueEstimators.TD0, gamma=settings.gamma)
        loss.set_keys(reward=PENALISED_REWARD)
        self.target = SoftUpdate(loss, tau=settings.tau)
        self.optimizer = torch.optim.Adam(loss.parameters(), lr=settings.lr)
        actor_ids = {id(p) for p in actor.parameters()}
        rest = [p for p in loss.parameters() if id(p) not in actor_ids]
        self._gradient_groups = [list(actor.parameters()),
                                 [p for p in rest if p is not loss.log_alpha],
                                 [loss.log_alpha]]
        self.combination = LagrangianAdvantage(
            cost_names, reward_key=("next", "reward"), out_key=("next", PENALISED_REWARD),
            cost_keys={c: ("next", cost_key(c)) for c in cost_names})
        self.buffer = ReplayRing(settings.buffer_frames)
        self.action_noise = ActionNoise.seeded(config.seed, config.num_envs)
        self._keys = sorted({*actor.in_keys, *loss.qvalue_network.in_keys} - {"action"})
        self._costs = [("next", cost_key(c)) for c in cost_names]
        self._carry = 0.0  # fractional gradient steps owed from earlier updates

    @classmethod
    def build(cls, config: TrainConfig, env: TrainingEnv) -> SACLagrangian:
        """Networks for ``env``'s state observations and actions.

        Raises:
            ConfigError: for ``obs=pixels``, or settings out of range.
        """
        settings = parse(SACSettings, config.algo.options, SOURCE, OPTIONS)
        if config.obs.name != "state":
            raise ConfigError(SOURCE, "obs", f"{cls.name} learns from state (obs=state): a "
                              "replay buffer of camera images would not fit a checkpoint")
        if config.model.policy_commands:
            raise ConfigError(SOURCE, "model.policy_commands", f"{cls.name}'s policy reads "
                              "the state alone; set model.policy_commands=false")
        frames = config.num_envs * config.rollout_steps
        if settings.buffer_frames < frames:
            raise ConfigError(SOURCE, "algo.options.buffer_frames", f"must hold one "
                              f"iteration's {frames} frames (num_envs × rollout_steps), got "
                              f"{settings.buffer_frames}")
        model, names = config.model, state_feature_names(env.config)
        shape = env.observation_spec["state"].shape[1:]
        actor = make_actor("state", shape, config.action.name, env.action_spec, model, names)
        encoder, width = make_encoder("state", shape, model, names)
        costs = [c.name for c in env.constraints]
        if config.action.name == "discrete":
            actions = len(DISCRETE_DUTIES)  # the env may take duties (the deployed policy)
            qvalue = TensorDictModule(QNetwork(encoder, width, model.hidden, actions),
                                      in_keys=["state"], out_keys=["action_value"])
            loss = DiscreteSACLoss(
                actor, qvalue, action_space="categorical", num_actions=actions,
                loss_function="l2", alpha_init=settings.alpha_init,
                target_entropy=settings.target_entropy_fraction * math.log(actions))
        else:
            dims = int(env.action_spec.shape[-1])
            qvalue = TensorDictModule(QNetwork(encoder, width, model.hidden, 1, dims),
                                      in_keys=["state", "action"],
                                      out_keys=["state_action_value"])
            loss = SACLoss(actor, qvalue, loss_function="l2", alpha_init=settings.alpha_init,
                           target_entropy=-float(dims))
        return cls(config, settings, actor, loss, costs)

    @property
    def diagnostic_names(self) -> list[str]:
        return [*self.LOSS_NAMES, "alpha", "entropy", "penalised_reward", "buffer_frames",
                "gradient_steps"]

    def prepare(self, frames: int, multipliers: Mapping[str, float]) -> None:
        self.combination.set_multipliers(multipliers)

    def needs_teacher(self, frames: int) -> bool:
        return False

    def update(self, batch: TensorDictBase, generator: torch.Generator) -> dict[str, float]:
        """Stores the batch, then ``updates_per_frame`` gradient steps per collected frame
        once the buffer holds ``warmup_frames``; the means of the losses, the temperature, the
        policy's entropy and the penalised reward of the sampled transitions (NaN before the
        first step)."""
        flat = batch.reshape(-1)
        keys = [*self._keys, "action", *(("next", k) for k in self._keys), ("next", "reward"),
                *self._costs, ("next", "done"), ("next", "terminated")]
        self.buffer.add(flat.select(*keys))
        sums = dict.fromkeys(self.diagnostic_names[:-2], 0.0)
        steps = 0
        if self.buffer.size >= max(self.settings.warmup_frames, self.settings.batch_size):
            self._carry += self.settings.updates_per_frame * flat.shape[0]
            steps, self._carry = int(self._carry), self._carry - int(self._carry)
        for _ in range(steps):
            sample = self.combination(self.buffer.sample(self.settings.batch_size, generator))
            out = self.loss(sample)
            total = sum(out[name] for name in self.LOSS_NAMES)
            self.optimizer.zero_grad(set_to_none=True)
            total.backward()
            for group in self._gradient_groups:  # each on its own: large Q errors do not
                torch.nn.utils.clip_grad_norm_(group, self.settings.max_grad_norm)  # shrink
            # the policy's step
            self.optimizer.step()
            self.target.step()
            for name in ("loss_actor", "loss_qvalue", "loss_alpha", "alpha", "entropy"):
                sums[name] += float(out[name].detach())
            sums["penalised_reward"] += float(sample["next", PENALISED_REWARD].mean())
        means = {k: (v / steps if steps else math.nan) for k, v in sums.items()}
        return {**means, "buffer_frames": float(self.buffer.size), "gradient_steps": float(steps)}

    def state_dict(self) -> dict[str, Any]:
        return {"actor": self.actor.state_dict(), "sac": dict(self.loss.state_dict()),
                "optimizer": self.optimizer.state_dict(), "replay": self.buffer.state_dict(),
                "step_carry": self._carry}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        self.loss.load_state_dict(state["sac"])
        self.actor.load_state_dict(state["actor"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.buffer.load_state_dict(state["replay"])
        self._carry = float(state["step_carry"])


LEARNER = SACLagrangian
