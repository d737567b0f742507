"""``python -m crllk.pictures``: pictures of the simulator (:mod:`crllk.analysis.pictures`).

    python -m crllk.pictures --out docs/images [--maps small_loop zigzag obstacle_loop]
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from crllk.analysis.pictures import add_picture_arguments, picture_stem, write_pictures
from crllk.cli import Parser, fail, run
from crllk.files import write_problem
from crllk.tasks.config import load_task_config


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    add_picture_arguments(parser, Path("outputs/pictures"))
    args = parser.parse_args(argv)
    problem = write_problem(args.out / "probe.png")
    if problem:
        fail(f"--out: {problem}")
    for task in args.maps:
        load_task_config(task)  # a bad task or map file ends here, before any picture
    for task in args.maps:
        result = write_pictures(task, args.out, args.steps, args.seed)
        print(f"{task}: {result['steps']} steps, {result['distance']:.2f} m, lane cost "
              f"{result['lane_cost']:.3f} dm -> {args.out}/{picture_stem(task)}_*.png")


if __name__ == "__main__":
    run(main)
