"""``python -m crllk.deploy --policy F.onnx --frames DIR|VIDEO``: the commands a robot would get.

    python -m crllk.deploy --policy F.onnx --parity small_loop zigzag   # camera frames vs sim

Runs the pilot (:class:`Pilot`, from :mod:`crllk.deployment.pilot`) on every frame of a folder
of images (JPEG files reach it as the camera's messages do) or of a video, writes one row per
frame to ``--out`` (frame, vel_left, vel_right, latency in ms: preparing the frame and running
the policy) and prints the latency's median and 95th percentile on this machine, and how many
frames gave a stop instead (a policy output that is not finite). A frame that cannot be read
(no image, too large an image) ends it with one line naming the file.

In Python: ``Pilot.from_onnx("policy.onnx").step(jpeg_bytes)`` gives a :class:`WheelCommand`.
"""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from crllk.cli import Parser, fail, positive_int, run
from crllk.deployment.frames import read_frames
from crllk.deployment.pilot import Pilot, WheelCommand
from crllk.files import atomic_write_text, write_problem


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, required=True, help="an exported policy (.onnx)")
    parser.add_argument("--frames", type=Path, help="a folder of images (.jpg, .png) or a video")
    parser.add_argument("--parity", nargs="+", default=[], metavar="TASK",
                        help="instead: how often the pilot on JPEG camera frames of these tasks "
                             "acts as the policy on the simulator's own images")
    parser.add_argument("--parity-frames", type=positive_int, default=900)
    parser.add_argument("--out", type=Path, default=Path("commands.csv"),
                        help="the commands, one row per frame (CSV)")
    parser.add_argument("--threads", type=positive_int, default=1,
                        help="CPU threads of ONNX Runtime")
    args = parser.parse_args(argv)
    if args.parity:
        return print_parity(Pilot.from_onnx(args.policy, threads=args.threads), args.parity,
                            args.parity_frames)
    if args.frames is None:
        parser.error("give --frames DIR|VIDEO (or --parity TASK ...)")
    problem = write_problem(args.out)
    if problem:
        fail(f"{args.out}: --out: {problem}")
    pilot = Pilot.from_onnx(args.policy, threads=args.threads)
    rows, latencies = [], []
    for name, frame in read_frames(args.frames):
        start = time.perf_counter()
        command = pilot.step(frame, frame_source(args.frames, name))
        latencies.append(1000.0 * (time.perf_counter() - start))
        rows.append((name, command, latencies[-1]))
    atomic_write_text(args.out, commands_csv(rows))
    median, p95 = np.percentile(latencies, [50, 95])
    print(f"{len(rows)} frames -> {args.out}; latency per frame (prepare + policy): median "
          f"{median:.2f} ms, 95th percentile {p95:.2f} ms, {args.threads} thread(s)")
    if pilot.faults.total:
        kinds = ", ".join(f"{kind} {count}" for kind, count in pilot.faults.counts.items())
        print(f"{pilot.faults.total} of {len(rows)} frames gave a stop ({kinds})")
    return 0


def frame_source(frames: Path, name: str) -> str:
    """What a frame's errors name: the image file, or ``<video>#<index>``."""
    return str(frames / name if frames.is_dir() else frames.with_name(name))


def print_parity(pilot: Pilot, tasks: Sequence[str], frames: int) -> int:
    """Prints :func:`crllk.deployment.parity.pilot_parity` per task. (The simulator is
    imported here: on a robot, the frames path needs only the pilot's own libraries.)"""
    from crllk.deployment.parity import pilot_parity
    from crllk.tasks.config import load_task_config

    for task in tasks:
        load_task_config(task)  # a bad task ends here
    rendered = (f" (simulator images supersampled {pilot.supersample}x, as in training)"
                if pilot.supersample else "")
    for task in tasks:
        parity = pilot_parity(pilot, task, frames)
        print(f"{task}: the same command on {parity.same} of {parity.frames} frames "
              f"({100 * parity.agreement:.1f} %); mean image difference "
              f"{parity.mean_pixel_difference:.2f} of 255{rendered}", flush=True)
    return 0


def commands_csv(rows: Sequence[tuple[str, WheelCommand, float]]) -> str:
    """``frame,vel_left,vel_right,latency_ms`` rows."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["frame", "vel_left", "vel_right", "latency_ms"])
    for name, command, latency in rows:
        writer.writerow([name, f"{command.vel_left:.6f}", f"{command.vel_right:.6f}",
                         f"{latency:.3f}"])
    return buffer.getvalue()


__all__ = ["Pilot", "WheelCommand", "main"]


if __name__ == "__main__":
    run(main)
