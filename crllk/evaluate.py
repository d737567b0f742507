"""Evaluate trained runs (or the scripted lane follower) with the paper's metrics.

    python -m crllk.evaluate run=runs/small_loop/crllk-discrete-state-seed0 episodes=100
    python -m crllk.evaluate 'runs=[runs/a,runs/b]' episodes=100 out=results/ab.json
    python -m crllk.evaluate follower=true task=small_loop episodes=100
    python -m crllk.evaluate teacher=true task=obstacle_loop episodes=100   # the swerving teacher
    python -m crllk.evaluate teacher=true task=obstacle_loop action=discrete   # ... in 3 turns
    python -m crllk.evaluate teacher=true task=obstacle_loop margin=0.06       # ... 6 cm clear
    python -m crllk.evaluate run=... episodes=100 record=true record_episodes=2 [viewer=spawn]
    python -m crllk.evaluate run=... fleet=4 episodes=25   # 4 robots, each driven by the policy

Each run's checkpoint plays ``episodes`` seeded episodes (episode k in sub-environment
k mod ``num_envs``, spawns from ``seed``, by default the run's evaluation seed, never a
training seed) with its policy as trained: actions are sampled, from a torch generator seeded
with the same seed, so the numbers are reproducible. ``deterministic=true`` plays the deployed
policy instead, the one ``crllk.export`` writes: a continuous policy's expected action
(:mod:`crllk.rl.expected_action`), and a discrete
policy's expected wheel duties (its three duty pairs weighted by their probabilities,
:mod:`crllk.rl.expected_duty`). The multipliers enforce the constraints on the sampled
policy, the one PPO trains; the most probable of three discrete actions would be another
policy, and a much worse one: a policy that steers by mixing turns and straight steps loses
the mix, which its expected duties keep. The result goes
to ``<run>/eval.json``: J_R (m), J_clane (dm), J_coll, episode length, the action histogram,
termination reasons and one row per episode. Several runs also print (and with ``out=`` write)
mean ± std across runs, the paper's way of reporting seeds. ``record=true`` also records
``record_episodes`` episodes of each run with rerun to ``<run>/recordings/eval.rrd``.

Every file is checked writable before the first episode. Each result is written under its own
lock (:mod:`crllk.training.run_dir`): a second evaluation into the same file of a run waits
for the first (saying so) instead of racing it; a run being trained can be evaluated.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from crllk.cli import one_line, run
from crllk.config import algo_thresholds
from crllk.errors import ConfigError
from crllk.files import WriteError, atomic_write_text, write_problem
from crllk.protocol import VALIDATION_SEED
from crllk.settings import (
    MAX_EPISODES,
    MAX_SIMULATIONS,
    at_least_one,
    at_most,
    file_stem,
    fleet_size,
    non_negative,
    one_of,
    parse_dotlist,
    setting,
    spawn_seed,
)
from crllk.tasks.actions import ACTIONS
from crllk.tasks.follower import FollowerGains
from crllk.training.run_dir import EVAL_FILE, EVAL_RECORDING, FLEET_FILE

SOURCE = "evaluate"
@dataclass
class EvaluateConfig:
    """Command-line settings (``key=value``)."""

    run: str | None = None
    """A run directory to evaluate."""
    runs: list[str] = field(default_factory=list)
    """Several run directories (``'runs=[a,b]'``), also summarised as mean ± std."""
    follower: bool = False
    """Evaluate the scripted lane follower on ``task``."""
    teacher: bool = False
    """Evaluate the privileged teacher (the follower, swerving around obstacles) on ``task``."""
    task: str = "small_loop"
    """The follower's and teacher's task: a name or the path of a task or map file."""
    action: str = setting("duty", check=one_of(*ACTIONS))
    """The action type the follower and teacher answer in: their wheel duties, or the nearest
    action of a policy's type (``discrete``: one of the three turns), as the teacher answers
    the policy in training."""
    margin: float = setting(FollowerGains.avoid_margin, check=non_negative)
    """The gap (m) the teacher keeps beside the obstacles it passes (a run's ``teacher.margin``)."""
    episodes: int = setting(100, check=at_most(MAX_EPISODES))
    deterministic: bool = False
    """The deployed policy instead of sampled actions: a discrete run's expected duties, a
    continuous run's expected action."""
    seed: int | None = setting(None, check=spawn_seed)
    """Spawn and sampling seed (default: the run's ``eval.seed``, a validation seed; the test
    seed is refused, :mod:`crllk.protocol`)."""
    num_envs: int = setting(10, check=at_most(MAX_SIMULATIONS))
    """Episode k runs in simulation k mod num_envs."""
    threads: int = setting(1, check=at_least_one)
    out: str | None = None
    """Also write every result (and the aggregate) to this JSON file."""
    record: bool = False
    """Record ``record_episodes`` episodes of each run to ``<run>/recordings/eval.rrd``."""
    record_episodes: int = setting(1, check=at_most(MAX_EPISODES))
    viewer: str = setting("none", check=one_of("none", "spawn", "serve"))
    overrides: dict[str, Any] = field(default_factory=dict)
    """Task settings changed for this evaluation, e.g. ``overrides.randomize=default`` or
    ``overrides.camera.robot_frames=true``, checked before any episode: of each run's task
    (named or a task file), its recording's, and the follower's and teacher's task; a run's
    result goes to ``<run>/<name>.json``."""
    name: str | None = setting(None, check=file_stem)
    """The result's file name in each run directory, without ``.json`` (default: ``eval``,
    or ``fleet`` with ``fleet``)."""
    fleet: int = setting(0, check=fleet_size)
    """Robots on the map, every one driven by the run's policy from its own observations (a
    pixel run's: its own camera), with ``episodes`` fleet episodes
    (:mod:`crllk.evaluation.fleet`); 0: the run's one robot."""
    thresholds: dict[str, float] = field(default_factory=algo_thresholds)
    """The follower's and teacher's constraint thresholds (``thresholds.lane=0.75``); a run
    is judged by its own ``algo.constraints``."""

    @property
    def result_name(self) -> str | None:
        """The result's file name without ``.json``: ``name``, ``fleet`` for a fleet, or None
        for the default ``eval.json``."""
        return FLEET_FILE if self.name is None and self.fleet else self.name

    def result_file(self, run_dir: Path) -> Path:
        """Where the result of ``run_dir`` goes."""
        name = self.result_name
        return run_dir / (EVAL_FILE if name is None else f"{name}.json")

    def run_dirs(self) -> list[Path]:
        return [Path(r) for r in ([self.run] if self.run else []) + list(self.runs)]

    def problems(self) -> Iterator[tuple[str, str]]:
        if not self.run_dirs() and not self.follower and not self.teacher:
            yield "run", "give run=<run_dir>, runs=[...], follower=true or teacher=true"
        if self.fleet and not self.run_dirs():
            yield "fleet", "a fleet is driven by a run's policy: give run=<run_dir>"
        if self.fleet and self.record:
            yield "record", "fleet evaluations are not recorded"
        for run_dir in self.run_dirs():
            if not run_dir.is_dir():
                yield "run", f"no such run directory: {run_dir}"
            elif problem := write_problem(self.result_file(run_dir)):
                yield "run", f"cannot write the result: {problem}"
            elif self.record and (problem := write_problem(run_dir / EVAL_RECORDING)):
                yield "record", f"cannot write the recording: {problem}"
        problem = write_problem(self.out) if self.out else None
        if problem:
            yield "out", problem


# ----- command line ------------------------------------------------------------------------
def parse(argv: Sequence[str]) -> EvaluateConfig:
    """``key=value`` arguments checked against :class:`EvaluateConfig`."""
    return parse_dotlist(EvaluateConfig, argv, SOURCE)


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if {"-h", "--help"} & set(argv):
        print(__doc__)
        return 0
    try:
        config = parse(argv)
        # torch and the simulator only once the arguments are known to be good: bad input is
        # reported in a second or two
        import torch

        from crllk.evaluation.fleet import evaluate_fleet, fleet_config
        from crllk.evaluation.report import aggregate, format_aggregate, format_summary
        from crllk.evaluation.runs import (
            check_task_overrides,
            evaluate_follower,
            evaluate_run,
            evaluation_config,
            record_run,
        )

        torch.set_num_threads(config.threads)
        for run_dir in config.run_dirs():  # every run's overrides checked before any work
            evaluation_config(run_dir, config.overrides)
            if config.fleet:
                fleet_config(run_dir, config.fleet, config.overrides)
        if config.overrides and (config.follower or config.teacher):
            check_task_overrides(config.task, config.overrides, config.overrides, SOURCE)
        documents = []
        for run_dir in config.run_dirs():
            if config.fleet:
                documents.append(evaluate_fleet(
                    run_dir, robots=config.fleet, episodes=config.episodes,
                    deterministic=config.deterministic, seed=config.seed,
                    overrides=config.overrides, name=config.result_name))
                print(format_summary(documents[-1]), flush=True)
                continue
            documents.append(evaluate_run(run_dir, episodes=config.episodes,
                                          deterministic=config.deterministic,
                                          seed=config.seed, num_envs=config.num_envs,
                                          overrides=config.overrides, name=config.result_name))
            print(format_summary(documents[-1]), flush=True)
            if config.record:
                record_run(run_dir, episodes=config.record_episodes, seed=config.seed,
                           deterministic=config.deterministic, viewer=config.viewer,
                           overrides=config.overrides)
        output: dict[str, Any] = {}
        if len(documents) > 1:
            output["aggregate"] = aggregate(documents)
            print(format_aggregate(output["aggregate"]), flush=True)
        for name in ("follower", "teacher"):
            if getattr(config, name):
                output[name] = evaluate_follower(
                    config.task, episodes=config.episodes, num_envs=config.num_envs,
                    seed=VALIDATION_SEED if config.seed is None else config.seed,
                    thresholds=config.thresholds, avoid_obstacles=name == "teacher",
                    action=config.action, margin=config.margin, overrides=config.overrides)
                print(format_summary(output[name]), flush=True)
        if config.out:
            output["runs"] = documents
            atomic_write_text(config.out, json.dumps(output, indent=1) + "\n")
    except (ConfigError, WriteError) as err:
        print(f"error: {one_line(err)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    run(main)
