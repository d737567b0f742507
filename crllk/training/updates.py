"""Between collection and the learner's update: shaping the signals, the multipliers' ascent."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from tensordict import TensorDictBase

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.config import TrainConfig
from crllk.envs.episodes import EpisodeStats
from crllk.rl.lagrange import Multiplier
from crllk.tasks.config import TaskConfig


def shape_signals(batch: TensorDictBase, config: TrainConfig, task: TaskConfig) -> None:
    """The signals the learner sees, in place: the reward scaled by ``reward_scale``, and, with
    ``absorbing_off_road``, the lane-deviation cost of every later step of a terminated
    episode folded into its last step: the robot stays off the road at the task's
    ``off_road_lane_cost`` (dm) per step for ever, γ·c_off / (1 − γ) in discounted sum (γ
    the PPO learner's cost discount, ``ppo.cost_gamma`` or else ``ppo.gamma``).
    Otherwise ending an episode early would cut its lane cost short and a large λ_lane would
    make leaving the road look cheap."""
    nxt = batch["next"]
    nxt["reward"] = nxt["reward"] * config.reward_scale
    if config.absorbing_off_road:
        gamma = config.ppo.discount_of_costs()
        tail = task.off_road_lane_cost * gamma / (1.0 - gamma) if gamma < 1.0 else 0.0
        for constraint in task.constraints:
            if constraint.signal == "lane_deviation":
                key = constraint.cost_key
                nxt[key] = nxt[key] + tail * nxt["terminated"].to(torch.float32)


def update_multipliers(multipliers: dict[str, Multiplier],
                       episodes: Sequence[EpisodeStats]) -> None:
    """Dual ascent from the finished episodes of the task's own spawn distribution (episodes
    started in front of an obstacle are left out): each multiplier from its constraint's
    episode values (the mean lane cost in dm, the number of collisions, ...)."""
    episodes = [e for e in episodes if not e.encounter]
    for name, multiplier in multipliers.items():
        multiplier.update([e.costs[name] for e in episodes])
