"""``python -m crllk.record``: record episodes of the scripted lane follower with rerun
(a trained run's episodes: ``python -m crllk.evaluate run=DIR record=true``).
The file is written beside ``--out`` and renamed over it at the end, under its lock
(:func:`crllk.files.output_lock`).

    python -m crllk.record --task obstacle_loop --episodes 1 --out rec.rrd [--viewer spawn]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from crllk.cli import Parser, fail, positive_int, run
from crllk.errors import ConfigError
from crllk.files import output_lock, write_problem
from crllk.recording.recorder import RecordingReport, record_episodes
from crllk.recording.sinks import VIEWERS
from crllk.tasks.follower import FollowerPolicy


@contextmanager
def _follower_env(args: argparse.Namespace) -> Iterator:
    """A one-simulation env of the command line's task for the scripted follower."""
    from crllk.envs.batched import make_env

    overrides = {"horizon": args.horizon} if args.horizon is not None else None
    env = make_env(args.task, observation=args.obs, action="duty", seed=args.seed,
                   overrides=overrides)
    try:
        yield env
    finally:
        env.close()


def _unrecorded_seconds(args: argparse.Namespace) -> float:
    """Wall time of the same episodes played without recording (a fresh, equal env)."""
    from crllk.rl.rollout import run_episodes

    with _follower_env(args) as env:
        start = time.perf_counter()
        run_episodes(env, FollowerPolicy(env), args.episodes)
        return time.perf_counter() - start


def _print_report(report: RecordingReport, wall: float) -> None:
    for message in report.warnings:
        print(f"warning: {message}", file=sys.stderr, flush=True)
    for stats in report.episode_stats:
        costs = ", ".join(f"{name} {value:.3g}" for name, value in stats.costs.items())
        print(f"episode: {stats.length} steps, {stats.distance:.2f} m, {costs}")
    per_step = 1e3 / max(report.steps, 1)
    print(f"{report.steps} steps -> {report.path}: {wall:.2f} s wall, "
          f"{report.logging_seconds:.2f} s in rerun ({report.logging_seconds * per_step:.3f} "
          f"ms/step), {report.render_seconds:.2f} s rendering the camera "
          f"({report.render_seconds * per_step:.3f} ms/step)")


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description="Record the scripted lane follower to a rerun .rrd file.")
    parser.add_argument("--task", default="obstacle_loop")
    parser.add_argument("--episodes", type=positive_int, default=1)
    parser.add_argument("--out", type=Path, default=Path("outputs/recordings/follower.rrd"))
    parser.add_argument("--obs", choices=("state", "pixels"), default="pixels")
    parser.add_argument("--horizon", type=positive_int, default=None, help="steps per episode")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--viewer", choices=VIEWERS, default="none")
    parser.add_argument("--compare", action="store_true",
                        help="also time the same episodes unrecorded")
    args = parser.parse_args(argv)
    problem = write_problem(args.out)
    if problem:
        fail(f"{args.out}: --out: {problem}")
    try:
        with output_lock(args.out), _follower_env(args) as env:
            start = time.perf_counter()
            report = record_episodes(env, FollowerPolicy(env), args.episodes, args.out,
                                     viewer=args.viewer)
            wall = time.perf_counter() - start
    except ConfigError as err:  # an unknown task, a bad task file, an unwritable path
        fail(err)
    _print_report(report, wall)
    if args.compare:
        print(f"unrecorded: {_unrecorded_seconds(args):.2f} s wall")


if __name__ == "__main__":
    run(main)
