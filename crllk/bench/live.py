"""Frames/s cost of a training run's live view (``live=serve``), measured in one process.

    python -m crllk.bench.live [--iterations 4] [--repetitions 6] [--viewer] [OVERRIDE ...]

Blocks of ``iterations`` training iterations (collection, multipliers, PPO update, as in
:func:`crllk.training.loop.train`) alternate with the live view off and on (off on, on off, ...),
``repetitions`` times each, after a warm-up, so that drifts of the machine's load hit both
alike. With it on, every
iteration's row goes to the live view and one evaluation recording is forwarded per block (as
``record_every`` = ``iterations`` would; recording it is not counted, it happens either way).
``--viewer`` also connects a headless viewer to the stream, on the same machine.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import crllk  # noqa: F401  (headless GL before torchrl)
from crllk.bench.training import bench_config
from crllk.cli import Parser, positive_int, run
from crllk.config import TrainConfig
from crllk.envs.episodes import EpisodeAccumulator
from crllk.recording.live import LiveView, live_url, server_sink
from crllk.recording.recorder import record_episodes
from crllk.recording.viewer import free_port, start_viewer, stop_viewer
from crllk.training.batches import BatchSource
from crllk.training.build import Learner, build_env, build_run
from crllk.training.loop import episode_columns, learn

_TARGET = 0.05
"""The live view may cost at most this share of training frames/s."""


@dataclass(frozen=True)
class LiveCost:
    """Frames per second of wall time and of the process's CPU time (all its threads, rerun's
    included) of each block with the live view off and on."""

    off: tuple[float, ...]
    on: tuple[float, ...]
    cpu_off: tuple[float, ...]
    cpu_on: tuple[float, ...]

    @property
    def ratio(self) -> float:
        """Median frames/s on over median frames/s off."""
        return statistics.median(self.on) / statistics.median(self.off)

    @property
    def cpu_ratio(self) -> float:
        """The same per CPU second: less sensitive to other processes on the machine."""
        return statistics.median(self.cpu_on) / statistics.median(self.cpu_off)


def live_cost(config: TrainConfig, iterations: int, repetitions: int, viewer: bool = False
              ) -> LiveCost:
    """Alternating off/on blocks of ``iterations`` iterations, ``repetitions`` of each."""
    env, learner, multipliers, generator = build_run(config)
    episodes = EpisodeAccumulator(config.num_envs, env.constraints)
    batches = BatchSource.for_run(config, env, learner, env.reset())
    iteration, frames_per_batch = 0, config.frames_per_batch

    def block(live: LiveView | None, recording: Path) -> tuple[float, float]:
        nonlocal iteration
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(iterations):
            iteration += 1
            _, finished, losses = learn(config, env, learner, multipliers, generator,
                                        episodes, batches, iteration * frames_per_batch)
            if live is not None:
                live.log_iteration({"iteration": iteration,
                                    **episode_columns(finished, env.constraints),
                                    **{f"lambda_{n}": m.value for n, m in multipliers.items()},
                                    **losses, "frames_per_s": 0.0})
        if live is not None:
            live.add_recording(recording)
        frames = iterations * config.frames_per_batch
        return (frames / (time.perf_counter() - start),
                frames / (time.process_time() - cpu_start))

    with tempfile.TemporaryDirectory() as scratch:
        recording = _evaluation_recording(config, learner, Path(scratch) / "iteration.rrd")
        port = free_port()
        live = LiveView([server_sink(port)], "crllk-bench-live", env.constraints,
                        {c.name: 0.5 for c in env.constraints})
        process = start_viewer(free_port(), "--headless", "--connect", live_url(port)) \
            if viewer else None
        try:
            block(None, recording)  # warm-up
            rates: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
            for k in range(repetitions):  # off on, on off, ...: a drift hits both alike
                for on in (False, True) if k % 2 == 0 else (True, False):
                    rates[on].append(block(live if on else None, recording))
        finally:
            live.close()
            if process is not None:
                stop_viewer(process)
    env.close()
    (off, cpu_off), (with_live, cpu_on) = (tuple(zip(*rates[key], strict=True))
                                           for key in (False, True))
    return LiveCost(off, with_live, cpu_off, cpu_on)


def _evaluation_recording(config: TrainConfig, learner: Learner, path: Path) -> Path:
    env = build_env(config, num_envs=1, seed=config.eval.seed)
    record_episodes(env, learner.actor, 1, path, iteration=0)
    env.close()
    return path


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=positive_int, default=4, help="iterations per block")
    parser.add_argument("--repetitions", type=positive_int, default=6, help="blocks of each kind")
    parser.add_argument("--viewer", action="store_true",
                        help="connect a headless viewer to the live view")
    parser.add_argument("overrides", nargs="*", default=["obs=state"],
                        help="trainer overrides (default: obs=state)")
    args = parser.parse_args(argv)
    config = bench_config(args.overrides)
    result = live_cost(config, args.iterations, args.repetitions, args.viewer)
    print(f"frames/s, live view off: {' '.join(f'{r:.0f}' for r in result.off)}")
    print(f"frames/s, live view on:  {' '.join(f'{r:.0f}' for r in result.on)}")
    for name, ratio in (("wall time", result.ratio), ("CPU time", result.cpu_ratio)):
        print(f"frames/s per {name}, median on / off: {ratio:.3f} (cost "
              f"{100 * (1 - ratio):.1f} %; target at most {100 * _TARGET:.0f} %)")
    sys.stdout.flush()


if __name__ == "__main__":
    run(main)
