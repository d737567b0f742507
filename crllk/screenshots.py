"""Screenshots of the real rerun viewer, taken headless: a recording, or a training run's live
view.

    python -m crllk.screenshots REC.rrd --out DIR --times 3 9 [--timeline sim_time] [--view NAME]
    python -m crllk.screenshots --out DIR --train task=obstacle_loop obs=state record_every=5 ...

The viewer runs with ``--headless`` (software Vulkan: Debian's ``mesa-vulkan-drivers`` and
``libvulkan1``, installed by ``scripts/install-egl.sh``) on a free port of 127.0.0.1 and is
driven with ``rerun.experimental.ViewerClient`` (:mod:`crllk.recording.headless`): open the
file, wait until it has loaded, move the time cursor, wait until two consecutive frames agree,
save the picture. With ``--train`` the
viewer connects to the live view of a training run (``live=serve``, :mod:`crllk.recording.live`)
that runs meanwhile, and the picture shows the run's end. The viewer is always stopped, whatever
fails. Every view's warnings and errors are printed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from rerun.experimental import ViewerClient

from crllk.cli import Parser, run
from crllk.errors import ConfigError
from crllk.recording.headless import (
    POLL,
    START_TIMEOUT,
    WINDOW_SIZE,
    ScreenshotError,
    ViewProblem,
    headless_viewer,
    seek,
    settled_png,
    view_id,
    view_problems,
    wait_loaded,
)
from crllk.recording.viewer import VIEWER_HOST, free_port, viewer_listening

_TRAIN_TIMEOUT = 1800.0
"""Longest training run of ``--train`` (s)."""
_NOTICE_SECONDS = 20.0
"""How long the viewer's notice that a finished run's server went away stays on screen (s)."""
_MAGIC = b"RRF2"
"""First bytes of a rerun 0.41 ``.rrd`` file."""


# ----- what to take -----------------------------------------------------------------------
def screenshot_recording(path: Path, out_dir: Path, times: Sequence[float], *,
                         timeline: str = "sim_time", view: str | None = None,
                         prefix: str | None = None, size: tuple[int, int] = WINDOW_SIZE
                         ) -> tuple[list[Path], list[ViewProblem]]:
    """Pictures of the recording at ``path`` at each of ``times`` on ``timeline``, written to
    ``out_dir/<prefix>_<time>.png`` (``prefix``: the file's stem); the whole viewer, or only
    the view named ``view``. Returns the pictures and the views' problems.

    Raises:
        ScreenshotError: for a file that is not a recording, a timeline or view that does not
            exist, or a viewer that does not start or load.
    """
    path = check_recording(path)
    out_dir = check_out_dir(out_dir)
    written = []
    with headless_viewer(size) as client:
        client.open(str(path))
        wait_loaded(client, timeline)
        target = view_id(client, view) if view else None
        for value in times:
            seek(client, timeline, value)
            out = out_dir / f"{prefix or path.stem}_{value:g}.png"
            out.write_bytes(settled_png(client, target))
            written.append(out)
        problems = view_problems(client)
    return written, problems


def screenshot_training(overrides: Sequence[str], out_dir: Path, *, prefix: str = "live_view",
                        size: tuple[int, int] = WINDOW_SIZE
                        ) -> tuple[list[Path], list[ViewProblem]]:
    """Run ``python -m crllk.train live=serve <overrides>`` (in a temporary run directory
    unless ``run_dir=`` is among them) with a headless viewer connected to its live view, and
    take the viewer's picture at the end of the run, once the viewer's notice that the run's
server went away has gone: ``out_dir/<prefix>.png``.

    Raises:
        ScreenshotError: when training fails, or the viewer does not start or receive the run.
    """
    out_dir = check_out_dir(out_dir)
    port = free_port()
    with tempfile.TemporaryDirectory() as scratch, headless_viewer(size) as client:
        run_dir = [] if any(o.startswith("run_dir=") for o in overrides) else [
            f"run_dir={scratch}/run"]
        command = [sys.executable, "-m", "crllk.train", "live=serve", f"live_port={port}",
                   "progress=false", *run_dir, *overrides]
        with tempfile.TemporaryFile() as log:
            training = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
            try:
                _connect_to_run(client, training, port)
                training.wait(timeout=_TRAIN_TIMEOUT)
            finally:
                if training.poll() is None:
                    training.kill()
                    training.wait()
            log.seek(0)
            output = log.read().decode(errors="replace")
        if training.returncode != 0:
            last = (output.strip().splitlines() or ["no output"])[-1]
            raise ScreenshotError(f"training failed (exit {training.returncode}): {last}")
        wait_loaded(client, "iteration")
        client.set_time("iteration", play_state="following")
        time.sleep(_NOTICE_SECONDS)
        out = out_dir / f"{prefix}.png"
        out.write_bytes(settled_png(client))
        return [out], view_problems(client)


def _connect_to_run(client: ViewerClient, training: subprocess.Popen, port: int) -> None:
    """Open the training run's live view in the viewer once its server listens."""
    deadline = time.monotonic() + START_TIMEOUT
    while not viewer_listening(port):
        if training.poll() is not None or time.monotonic() > deadline:
            raise ScreenshotError(f"the training run did not serve its live view on "
                                  f"{VIEWER_HOST}:{port}")
        time.sleep(POLL)
    client.open(f"rerun+http://{VIEWER_HOST}:{port}/proxy")


# ----- input checks -----------------------------------------------------------------------
def check_recording(path: Path) -> Path:
    """The absolute path of a readable rerun recording.

    Raises:
        ConfigError: if ``path`` is missing, unreadable or not an ``.rrd`` file.
    """
    path = Path(path).expanduser().resolve()
    try:
        with path.open("rb") as handle:
            magic = handle.read(len(_MAGIC))
    except OSError as err:
        raise ConfigError(path, "recording", f"cannot read: {err.strerror or err}") from None
    if magic != _MAGIC:
        raise ConfigError(path, "recording", "not a rerun recording (.rrd)")
    return path


def check_out_dir(out_dir: Path) -> Path:
    """``out_dir``, created; absolute (the viewer process writes nothing, this one does).

    Raises:
        ConfigError: if it cannot be created or written.
    """
    out_dir = Path(out_dir).expanduser().resolve()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out_dir):
            pass
    except OSError as err:
        raise ConfigError(out_dir, "--out", f"cannot write pictures here: "
                          f"{err.strerror or err}") from None
    return out_dir


def _window_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if not (200 <= width <= 8192 and 200 <= height <= 8192):
        raise argparse.ArgumentTypeError(f"width and height must lie in [200, 8192], got {text}")
    return width, height


def _time(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be finite and >= 0, got {text}")
    return value


# ----- command line -----------------------------------------------------------------------
def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = Parser(
        prog="python -m crllk.screenshots",
        description="Screenshots of the real rerun viewer, taken headless.")
    parser.add_argument("recording", nargs="?", type=Path, help="a .rrd file")
    parser.add_argument("--out", type=Path, required=True, help="folder of the pictures")
    parser.add_argument("--times", nargs="+", type=_time, default=[0.0],
                        help="where to put the time cursor (s on sim_time; numbers on "
                             "sequence timelines)")
    parser.add_argument("--timeline", default="sim_time")
    parser.add_argument("--view", default=None, help="only this view (e.g. 'robot camera')")
    parser.add_argument("--prefix", default=None,
                        help="file names <prefix>_<time>.png (default: the recording's stem; "
                             "with --train <prefix>.png, default live_view)")
    parser.add_argument("--size", type=_window_size, default=WINDOW_SIZE,
                        help="window size WIDTHxHEIGHT (px)")
    parser.add_argument("--train", nargs="+", metavar="OVERRIDE", default=None,
                        help="instead of a recording: train with these overrides and take "
                             "the live view at the end (put it last)")
    args = parser.parse_args(argv)
    if (args.recording is None) == (args.train is None):
        parser.error("give either a recording or --train OVERRIDES")
    return args


def main(argv: Sequence[str] | None = None) -> None:
    args = parse_args(argv)
    try:
        if args.train is not None:
            written, problems = screenshot_training(args.train, args.out,
                                                    prefix=args.prefix or "live_view",
                                                    size=args.size)
        else:
            written, problems = screenshot_recording(
                args.recording, args.out, args.times, timeline=args.timeline, view=args.view,
                prefix=args.prefix, size=args.size)
    except ScreenshotError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(1) from None
    for problem in problems:
        print(f"{problem.severity}: view {problem.view!r}: {problem.summary}", file=sys.stderr)
    for path in written:
        print(path)


__all__ = ["WINDOW_SIZE", "ScreenshotError", "ViewProblem", "check_out_dir", "check_recording",
           "headless_viewer", "screenshot_recording", "screenshot_training", "seek",
           "settled_png", "view_id", "view_problems", "wait_loaded"]


if __name__ == "__main__":
    run(main)
