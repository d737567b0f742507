"""Evaluate trained runs (or the scripted lane follower) with the paper's metrics.

    python -m crllk.evaluate run=runs/small_loop/crllk-discrete-state-seed0 episodes=100
    python -m crllk.evaluate 'runs=[runs/a,runs/b]' episodes=100 out=results/ab.json
    python -m crllk.evaluate follower=true task=small_loop episodes=100
    python -m crllk.evaluate teacher=true task=obstacle_loop episodes=100   # the swerving teacher
    python -m crllk.evaluate run=... episodes=100 record=true record_episodes=2 [viewer=spawn]

Each run's checkpoint plays ``episodes`` seeded episodes (episode k in sub-environment
k mod ``num_envs``, spawns from ``seed``, by default the run's evaluation seed, never a
training seed) with its policy as trained: actions are sampled, from a torch generator seeded
with the same seed, so the numbers are reproducible (``deterministic=true`` takes the policy's
mode instead). The multipliers enforce the constraints on the sampled policy, the one PPO
trains; its mode is another policy, and with three discrete actions a much worse one: a policy
that steers by mixing turns and straight steps loses the mix. The result goes
to ``<run>/eval.json``: J_R (m), J_clane (dm), J_coll, episode length, the action histogram,
termination reasons and one row per episode. Several runs also print (and with ``out=`` write)
mean ± std across runs, the paper's way of reporting seeds. ``record=true`` also records
``record_episodes`` episodes of each run with rerun to ``<run>/recordings/eval.rrd``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from crllk.errors import ConfigError
from crllk.evaluation.report import DEFAULT_SEED, aggregate, format_aggregate, format_summary
from crllk.evaluation.runs import evaluate_follower, evaluate_run, record_run
from crllk.files import atomic_write_text

SOURCE = "evaluate"
@dataclass
class EvaluateConfig:
    """Command-line settings (``key=value``)."""

    run: str | None = None
    runs: list[str] = field(default_factory=list)
    follower: bool = False
    teacher: bool = False
    task: str = "small_loop"
    episodes: int = 100
    deterministic: bool = False
    seed: int | None = None
    num_envs: int = 10
    threads: int = 1
    out: str | None = None
    record: bool = False
    record_episodes: int = 1
    viewer: str = "none"
    lane_threshold: float = 0.5
    collision_threshold: float = 0.02

    def run_dirs(self) -> list[Path]:
        return [Path(r) for r in ([self.run] if self.run else []) + list(self.runs)]


# ----- one evaluation ----------------------------------------------------------------------
# ----- several runs ------------------------------------------------------------------------
# ----- command line ------------------------------------------------------------------------
def parse(argv: Sequence[str]) -> EvaluateConfig:
    """``key=value`` arguments checked against :class:`EvaluateConfig`."""
    schema = OmegaConf.structured(EvaluateConfig)
    try:
        merged = OmegaConf.merge(schema, OmegaConf.from_dotlist(list(argv)))
        config: EvaluateConfig = OmegaConf.to_object(merged)  # type: ignore[assignment]
    except OmegaConfBaseException as err:
        key = getattr(err, "full_key", None) or "<arguments>"
        raise ConfigError(SOURCE, str(key), str(err).splitlines()[0]) from None
    if config.viewer not in ("none", "spawn", "serve"):
        raise ConfigError(SOURCE, "viewer", f"must be one of none, spawn, serve, got "
                          f"{config.viewer!r}")
    for key in ("episodes", "num_envs", "threads", "record_episodes"):
        if getattr(config, key) < 1:
            raise ConfigError(SOURCE, key, f"must be >= 1, got {getattr(config, key)}")
    if not config.run_dirs() and not config.follower and not config.teacher:
        raise ConfigError(SOURCE, "run", "give run=<run_dir>, runs=[...], follower=true or "
                          "teacher=true")
    for run_dir in config.run_dirs():
        if not run_dir.is_dir():
            raise ConfigError(SOURCE, "run", f"no such run directory: {run_dir}")
    return config


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    try:
        config = parse(argv)
        torch.set_num_threads(config.threads)
        documents = []
        for run_dir in config.run_dirs():
            documents.append(evaluate_run(run_dir, episodes=config.episodes,
                                          deterministic=config.deterministic,
                                          seed=config.seed, num_envs=config.num_envs))
            print(format_summary(documents[-1]), flush=True)
            if config.record:
                record_run(run_dir, episodes=config.record_episodes, seed=config.seed,
                           deterministic=config.deterministic, viewer=config.viewer)
        output: dict[str, Any] = {}
        if len(documents) > 1:
            output["aggregate"] = aggregate(documents)
            print(format_aggregate(output["aggregate"]), flush=True)
        thresholds = {"lane": config.lane_threshold, "collision": config.collision_threshold}
        for name in ("follower", "teacher"):
            if getattr(config, name):
                output[name] = evaluate_follower(
                    config.task, episodes=config.episodes, num_envs=config.num_envs,
                    seed=DEFAULT_SEED if config.seed is None else config.seed,
                    thresholds=thresholds, avoid_obstacles=name == "teacher")
                print(format_summary(output[name]), flush=True)
        if config.out:
            output["runs"] = documents
            Path(config.out).parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(config.out, json.dumps(output, indent=1) + "\n")
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
