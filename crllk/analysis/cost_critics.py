"""How well a run's cost critic foresees its constraint's cost, over whole batches.

    python -m crllk.analysis.cost_critics RUN_DIR [--batches 12] [--constraint collision]

The trainer logs ``explained_variance_<cost>`` per minibatch of 512 transitions. For a rare
cost (a collision every few tens of thousands of frames) most minibatches hold none: their
targets are the critic's own bootstrapped values, their variance is tiny and the logged
figure swings far below zero whatever the critic knows. This command restores the run's last
checkpoint, collects ``batches`` training batches with its policy (one process, the run's
seed), computes the GAE targets as training does, and reports over all of them at once: how
many steps carried the cost, the explained variance, and the correlation of prediction and
target. It also sets the critic's predictions against what followed: each step's discounted
cost-to-go over the collected steps (the cost discount of training, bootstrapped with the
critic only where an episode was cut by the horizon or the collection ended), averaged per bin
of the prediction (calibration) and per window of steps before each cost (lead: does the
critic see it coming?). The result goes to ``<run>/cost-critic-<constraint>.json``.
"""

from __future__ import annotations

import itertools
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crllk.cli import Parser, positive_int, run
from crllk.errors import ConfigError
from crllk.files import atomic_write_text

if TYPE_CHECKING:
    from torch import Tensor

SOURCE = "cost_critics"

PREDICTION_EDGES = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3)
"""Bin edges of the predicted discounted cost (collisions) for the calibration table."""
LEAD_WINDOWS = ((1, 10), (11, 30), (31, 60), (61, 90), (91, 150))
"""Windows of steps before a cost (1: the step that carried it) for the lead table."""


def discounted_costs_to_go(cost: Tensor, terminated: Tensor, truncated: Tensor,
                           next_value: Tensor, gamma: float) -> Tensor:
    """Per step of ``[envs, steps]`` series: c_t + γ·G_{t+1}, 0 after a termination, the
    critic's ``next_value`` after a truncation or the last step (the cost no step saw)."""
    import torch

    returns = torch.zeros_like(cost)
    following = next_value[:, -1]
    for t in range(cost.shape[1] - 1, -1, -1):
        following = torch.where(truncated[:, t], next_value[:, t], following)
        following = torch.where(terminated[:, t], torch.zeros_like(following), following)
        returns[:, t] = cost[:, t] + gamma * following
        following = returns[:, t]
    return returns


def calibration(predicted: Tensor, realised: Tensor,
                edges: Sequence[float] = PREDICTION_EDGES) -> list[dict[str, Any]]:
    """Per bin of the prediction (``edges`` between bins; None: unbounded): its steps and the
    mean predicted and realised discounted cost (None without steps)."""
    bounds = [None, *edges, None]
    rows = []
    for low, high in itertools.pairwise(bounds):
        inside = ((predicted >= (-math.inf if low is None else low))
                  & (predicted < (math.inf if high is None else high)))
        rows.append({"from": low, "to": high, **_means(inside, predicted, realised)})
    return rows


def _means(inside: Tensor, predicted: Tensor, realised: Tensor) -> dict[str, Any]:
    count = int(inside.sum())
    return {"steps": count,
            "predicted": float(predicted[inside].mean()) if count else None,
            "realised": float(realised[inside].mean()) if count else None}


def lead(predicted: Tensor, realised: Tensor, cost: Tensor, done: Tensor,
         windows: Sequence[tuple[int, int]] = LEAD_WINDOWS) -> list[dict[str, Any]]:
    """Per window ``(a, b)`` of steps before a step with the cost (1: that step) within its
    episode: the steps and the mean predicted and realised discounted cost there (None
    without steps)."""
    import torch

    before = []  # per step, the steps to the next cost in its episode (1-based), or -1
    for costs, ends in zip(cost.tolist(), done.tolist(), strict=True):
        distances, distance = [], -1
        for c, end in zip(reversed(costs), reversed(ends), strict=True):
            if c > 0:
                distance = 0
            elif end:
                distance = -1
            distance += distance >= 0
            distances.append(distance)
        before.append(distances[::-1])
    before = torch.tensor(before)
    rows = []
    for a, b in windows:
        inside = (before >= a) & (before <= b)
        rows.append({"from": a, "to": b, **_means(inside, predicted, realised)})
    return rows


def cost_critic_fit(run_dir: Path, batches: int, constraint: str) -> dict[str, Any]:
    """The fit of ``constraint``'s cost critic over ``batches`` freshly collected batches."""
    import torch

    from crllk.algos.ppo_lagrangian import PPOLagrangian
    from crllk.envs.episodes import EpisodeAccumulator
    from crllk.rl.loss import explained_variance
    from crllk.training.batches import collect_batch, first_carry
    from crllk.training.build import build_run
    from crllk.training.checkpoints import load_checkpoint, restore
    from crllk.training.runs import CHECKPOINT_FILE, load_run_config
    from crllk.training.updates import shape_signals

    config = load_run_config(run_dir)
    config.workers, config.threads = 1, 1
    checkpoint = run_dir / CHECKPOINT_FILE
    if not checkpoint.is_file():
        raise ConfigError(SOURCE, "run", f"no checkpoint in {run_dir} ({CHECKPOINT_FILE})")
    env, learner, multipliers, generator = build_run(config)
    try:
        names = [c.name for c in env.constraints]
        if constraint not in names:
            raise ConfigError(SOURCE, "--constraint",
                              f"{constraint!r} is not a constraint of the run ({names})")
        if not isinstance(learner, PPOLagrangian):
            raise ConfigError(SOURCE, "run", f"the run's learner {learner.name!r} has no GAE "
                              "cost critics to analyse")
        restore(load_checkpoint(checkpoint, resuming=True), learner, multipliers,
                EpisodeAccumulator(config.num_envs, env.constraints), env, generator)
        cost_key = env.constraints[names.index(constraint)].cost_key
        target_key, value_key = learner.loss.cost_keys(constraint)
        carry = first_carry(env)
        series: dict[str, list[torch.Tensor]] = {k: [] for k in (
            "target", "value", "cost", "next_value", "terminated", "truncated")}
        with torch.no_grad():
            for _ in range(batches):
                batch, carry = collect_batch(env, learner.actor, carry, config.rollout_steps,
                                             learner.action_noise)
                shape_signals(batch, config, env.config)
                learner.advantages(batch)
                flat = batch.reshape(-1)
                learner.loss.evaluate_critics(flat)
                shape = batch.shape
                nxt = batch["next"]
                for name, values in (
                        ("target", flat.get(target_key)), ("value", flat.get(value_key)),
                        ("cost", nxt[cost_key]), ("next_value", nxt[value_key]),
                        ("terminated", nxt["terminated"]), ("truncated", nxt["truncated"])):
                    series[name].append(values.reshape(shape))
    finally:
        env.close()
    s = {name: torch.cat(parts, dim=1) for name, parts in series.items()}
    target, value, cost = s["target"].reshape(-1), s["value"].reshape(-1), s["cost"].reshape(-1)
    realised = discounted_costs_to_go(s["cost"], s["terminated"], s["truncated"],
                                      s["next_value"], config.ppo.discount_of_costs())
    both = torch.stack([target, value])
    return {"run_dir": str(run_dir), "constraint": constraint, "frames": int(target.numel()),
            "cost_steps": int((cost > 0).sum()),
            "explained_variance": float(explained_variance(value, target)),
            "correlation": float(torch.corrcoef(both)[0, 1]),
            "target_std": float(target.std()), "value_std": float(value.std()),
            "cost_gamma": config.ppo.discount_of_costs(),
            "realised_correlation": float(torch.corrcoef(
                torch.stack([realised.reshape(-1), value]))[0, 1]),
            "calibration": calibration(s["value"], realised),
            "lead": lead(s["value"], realised, s["cost"],
                         s["terminated"] | s["truncated"])}


def table_text(result: dict[str, Any]) -> str:
    """The calibration and lead tables as text (predicted against realised cost-to-go)."""
    lines = [f"discounted {result['constraint']} cost-to-go (γ {result['cost_gamma']}), "
             "predicted → realised:"]
    for row in result["calibration"]:
        if row["steps"]:
            low = "-inf" if row["from"] is None else f"{row['from']:g}"
            high = "inf" if row["to"] is None else f"{row['to']:g}"
            lines.append(f"  predicted in [{low}, {high}): {row['steps']} "
                         f"steps, {row['predicted']:.4f} → {row['realised']:.4f}")
    for row in result["lead"]:
        if row["steps"]:
            lines.append(f"  {row['from']}–{row['to']} steps before the cost: {row['steps']} "
                         f"steps, {row['predicted']:.4f} → {row['realised']:.4f}")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="python -m crllk.analysis.cost_critics",
                    description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--batches", type=positive_int, default=12)
    parser.add_argument("--constraint", default="collision")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if not args.run_dir.is_dir():
        raise ConfigError(SOURCE, "run", f"no such run directory: {args.run_dir}")
    result = cost_critic_fit(args.run_dir, args.batches, args.constraint)
    out = args.run_dir / f"cost-critic-{args.constraint}.json"
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    print(f"{out}: {result['frames']} frames, {result['cost_steps']} with the cost; explained "
          f"variance {result['explained_variance']:.3f}, correlation {result['correlation']:.3f}")
    print(table_text(result))
    return 0


if __name__ == "__main__":
    run(main)


__all__ = ["calibration", "cost_critic_fit", "discounted_costs_to_go", "lead", "main",
           "table_text"]
