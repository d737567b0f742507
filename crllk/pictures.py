"""``python -m crllk.pictures``: pictures of the simulator (:mod:`crllk.analysis.pictures`).

    python -m crllk.pictures --out docs/images [--maps small_loop zigzag obstacle_loop]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from crllk.analysis.pictures import DEFAULT_MAPS, write_pictures


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/pictures"))
    parser.add_argument("--maps", nargs="+", default=list(DEFAULT_MAPS))
    parser.add_argument("--steps", type=int, default=512)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    for task in args.maps:
        run = write_pictures(task, args.out, args.steps, args.seed)
        print(f"{task}: {run['steps']} steps, {run['distance']:.2f} m, "
              f"lane cost {run['lane_cost']:.3f} dm -> {args.out}/{task}_*.png")


if __name__ == "__main__":
    main()
