"""The first command of the project: drive the scripted lane follower on every map, print what
it achieved, write pictures and standalone MJCF scenes.

    python -m crllk.demo [--out outputs/demo] [--steps 512]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path

from crllk.analysis.pictures import DEFAULT_MAPS, write_pictures
from crllk.maps import load_map
from crllk.sim.scene import export_scene


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    parser.add_argument("--maps", nargs="+", default=list(DEFAULT_MAPS))
    parser.add_argument("--steps", type=int, default=512)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(f"{'map':<15}{'steps':>6}{'distance m':>12}{'lane cost dm':>14}{'collisions':>12}"
          f"  {'ended by':<10}{'steps/s':>8}")
    for task in args.maps:
        start = time.perf_counter()
        run = write_pictures(task, args.out, args.steps, args.seed)
        rate = run["steps"] / (time.perf_counter() - start)
        print(f"{task:<15}{run['steps']:>6}{run['distance']:>12.2f}{run['lane_cost']:>14.3f}"
              f"{run['collisions']:>12.0f}  {run['termination'] or 'time limit':<10}{rate:>8.0f}")
        export_scene(load_map(task), args.out / "mjcf")
    print(f"pictures: {args.out}/*.png; scenes: python -m mujoco.viewer "
          f"--mjcf={args.out}/mjcf/<map>.xml")


if __name__ == "__main__":
    main()
