"""How well a run's cost critic foresees its constraint's cost, over whole batches.

    python -m crllk.analysis.cost_critics RUN_DIR [--batches 12] [--constraint collision]

The trainer logs ``explained_variance_<cost>`` per minibatch of 512 transitions. For a rare
cost (a collision every few tens of thousands of frames) most minibatches hold none: their
targets are the critic's own bootstrapped values, their variance is tiny and the logged
figure swings far below zero whatever the critic knows. This command restores the run's last
checkpoint, collects ``batches`` training batches with its policy (one process, the run's
seed), computes the GAE targets as training does, and reports over all of them at once: how
many steps carried the cost, the explained variance, and the correlation of prediction and
target. The result goes to ``<run>/cost-critic-<constraint>.json``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from crllk.cli import Parser, positive_int, run
from crllk.errors import ConfigError
from crllk.files import atomic_write_text

SOURCE = "cost_critics"


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
        targets, values, costs = [], [], []
        with torch.no_grad():
            for _ in range(batches):
                batch, carry = collect_batch(env, learner.actor, carry, config.rollout_steps,
                                             learner.action_noise)
                shape_signals(batch, config, env.config)
                learner.advantages(batch)
                flat = batch.reshape(-1)
                learner.loss.evaluate_critics(flat)
                targets.append(flat.get(target_key).reshape(-1))
                values.append(flat.get(value_key).reshape(-1))
                costs.append(flat["next", cost_key].reshape(-1))
    finally:
        env.close()
    target, value, cost = torch.cat(targets), torch.cat(values), torch.cat(costs)
    both = torch.stack([target, value])
    return {"run_dir": str(run_dir), "constraint": constraint, "frames": int(target.numel()),
            "cost_steps": int((cost > 0).sum()),
            "explained_variance": float(explained_variance(value, target)),
            "correlation": float(torch.corrcoef(both)[0, 1]),
            "target_std": float(target.std()), "value_std": float(value.std())}


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
    return 0


if __name__ == "__main__":
    run(main)


__all__ = ["cost_critic_fit", "main"]
