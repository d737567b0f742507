"""Pixel training with and without collecting ahead, in turns in one process.

    python scripts/collect_ahead_pixels.py [--rounds 2] [--iterations 10]

Each round times ``small_loop`` pixel training (:func:`crllk.bench.training.training_rates`)
sequentially (``collect_ahead=false``), collecting ahead with the update on the default two
threads, and collecting ahead with it on one, and prints a line per figure: the round, the
overrides, training frames/s and environment-only frames/s. The output of one run is
``results/bench/collect-ahead-pixels.txt`` (quoted in ``docs/benchmarks.md``).
"""

from __future__ import annotations

import argparse

from crllk.bench.training import bench_config, training_rates

SETTINGS = (["collect_ahead=false"], ["collect_ahead=true"], ["collect_ahead=true", "threads=1"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--iterations", type=int, default=10)
    args = parser.parse_args()
    for round_ in range(args.rounds):
        for overrides in SETTINGS:
            config = bench_config(["obs=pixels", "task=small_loop", *overrides])
            rates = training_rates(config, iterations=args.iterations)
            print(round_, overrides, round(rates.training), round(rates.environment), flush=True)


if __name__ == "__main__":  # the workers are spawned: they import this file
    main()
