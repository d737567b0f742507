"""The first command of the project: drive the scripted lane follower on every map, print what
it achieved, write pictures and standalone MJCF scenes.

    python -m crllk.demo [--out outputs/demo] [--steps 512]
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

from crllk.analysis.pictures import add_picture_arguments, picture_stem, write_pictures
from crllk.cli import Parser, run
from crllk.maps import load_map
from crllk.sim.scene import export_scene
from crllk.tasks.config import load_task_config


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    add_picture_arguments(parser, Path("outputs/demo"))
    args = parser.parse_args(argv)
    for task in args.maps:
        load_task_config(task)  # a bad task or map file ends here, before any picture
    print(f"{'map':<15}{'steps':>6}{'distance m':>12}{'lane cost dm':>14}{'collisions':>12}"
          f"  {'ended by':<10}{'steps/s':>8}")
    for task in args.maps:
        start = time.perf_counter()
        result = write_pictures(task, args.out, args.steps, args.seed)
        rate = result["steps"] / (time.perf_counter() - start)
        print(f"{picture_stem(task):<15}{result['steps']:>6}{result['distance']:>12.2f}"
              f"{result['lane_cost']:>14.3f}{result['collisions']:>12.0f}  "
              f"{result['termination'] or 'time limit':<10}{rate:>8.0f}")
        export_scene(load_map(task), args.out / "mjcf")
    print(f"pictures: {args.out}/*.png; scenes: python -m mujoco.viewer "
          f"--mjcf={args.out}/mjcf/<map>.xml")


if __name__ == "__main__":
    run(main)
