"""Read a recording (``.rrd``, as :func:`crllk.recording.recorder.record_episodes` writes it)
back and draw it as one picture: the map from above with the driven trail, camera frames and the
costs.

    python -m crllk.recording_picture REC.rrd --out docs/images/recording.png

Everything drawn comes from the file (``rerun.chunk.RrdReader``): the static map geometry, the
``world/robot`` poses, the camera images and the scalar series.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow as pa
from matplotlib.patches import Polygon

from crllk.cli import Parser, run
from crllk.errors import ConfigError
from crllk.files import write_problem
from crllk.recording import entities as R
from crllk.recording.sinks import read_recording

_FRAMES = 4
"""Camera frames shown, evenly spread over the recording."""
_NS = 1e9
"""Nanoseconds per second (rerun stores durations in ns)."""
_FIGURE_SIZE = (13.0, 6.5)
"""Picture size (inches at 100 dpi)."""
_TRAIL_COLOURS = ("#29abff", "#911eb4", "#3cb44b", "#f032e6", "#000075")


@dataclass(frozen=True)
class Series:
    """One entity's temporal rows of one component, in step order."""

    steps: np.ndarray
    """The ``step`` timeline: control steps since the recording began."""
    times: np.ndarray
    """The ``sim_time`` timeline (s)."""
    episodes: np.ndarray
    """The ``episode`` timeline."""
    values: list


def _time_column(batch: pa.RecordBatch, name: str) -> list[int]:
    column = batch.column(name)
    return (column.cast(pa.int64()) if pa.types.is_temporal(column.type) else column).to_pylist()


def series(batches: Sequence[pa.RecordBatch], component: str) -> Series:
    """The temporal rows that hold ``component`` (e.g. ``"Scalars:scalars"``), sorted by
    step; static rows are left out."""
    rows: list[tuple[int, int, int, object]] = []
    for batch in batches:
        names = batch.schema.names
        if component not in names or "step" not in names:
            continue
        columns = [_time_column(batch, t) for t in ("step", "sim_time", "episode")]
        rows += [row for row in zip(*columns, batch.column(component).to_pylist(), strict=True)
                 if row[-1] is not None]
    rows.sort(key=lambda row: row[0])
    steps, times, episodes = (np.asarray([row[k] for row in rows], np.int64) for k in range(3))
    return Series(steps, times / _NS, episodes, [row[3] for row in rows])


def static_value(batches: Sequence[pa.RecordBatch], component: str) -> list:
    """The (last) static value of ``component``: a list with one entry per instance."""
    found: list = []
    for batch in batches:
        if component in batch.schema.names and "step" not in batch.schema.names:
            found = batch.column(component).to_pylist()[-1]
    return found


def _with_values(data: Series, values: list) -> Series:
    return Series(data.steps, data.times, data.episodes, values)


def scalars(chunks: dict[str, list[pa.RecordBatch]], path: str) -> Series:
    """A scalar series (one float per row)."""
    data = series(chunks.get(path, []), "Scalars:scalars")
    return _with_values(data, [v[0] for v in data.values])


def positions(chunks: dict[str, list[pa.RecordBatch]]) -> Series:
    """The robot's (x, y) (m) per logged step, from ``world/robot``'s translations."""
    data = series(chunks[R.ROBOT], "Transform3D:translation")
    return _with_values(data, [tuple(v[0][:2]) for v in data.values])


def images(chunks: dict[str, list[pa.RecordBatch]]) -> Series:
    """The camera images (uint8 H x W x 3) per logged step."""
    buffers = series(chunks[R.IMAGE], "Image:buffer")
    formats = series(chunks[R.IMAGE], "Image:format")
    frames = [np.asarray(b[0], np.uint8).reshape(f[0]["height"], f[0]["width"], 3)
              for b, f in zip(buffers.values, formats.values, strict=True)]
    return _with_values(buffers, frames)


# ----- drawing ----------------------------------------------------------------------------
def _rgb(packed: int) -> tuple[float, float, float]:
    """A rerun colour (0xRRGGBBAA) as matplotlib RGB in [0, 1]."""
    return ((packed >> 24) & 255) / 255, ((packed >> 16) & 255) / 255, ((packed >> 8) & 255) / 255


def _box_corners(centre: Sequence[float], half: Sequence[float], yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([(-1, -1), (1, -1), (1, 1), (-1, 1)]) * np.asarray(half[:2])
    return local @ np.array([[c, s], [-s, c]]) + np.asarray(centre[:2])


def _draw_boxes(ax, batches: Sequence[pa.RecordBatch], edge: str | None = None) -> None:
    centres = static_value(batches, "Boxes3D:centers")
    halves = static_value(batches, "Boxes3D:half_sizes")
    colours = static_value(batches, "Boxes3D:colors")
    angles = static_value(batches, "Boxes3D:rotation_axis_angles") or [None] * len(centres)
    for k, (centre, half) in enumerate(zip(centres, halves, strict=True)):
        yaw = angles[k]["angle"] if angles[k] else 0.0
        colour = _rgb(colours[k if len(colours) > 1 else 0])
        ax.add_patch(Polygon(_box_corners(centre, half, yaw), closed=True, facecolor=colour,
                             edgecolor=edge or colour, linewidth=0.5))


def _draw_strips(ax, batches: Sequence[pa.RecordBatch], width: float, **kwargs) -> None:
    colour = _rgb(static_value(batches, "LineStrips3D:colors")[0])
    for strip in static_value(batches, "LineStrips3D:strips"):
        points = np.asarray(strip)
        ax.plot(points[:, 0], points[:, 1], color=colour, linewidth=width,
                solid_capstyle="butt", **kwargs)


def draw_topdown(ax, chunks: dict[str, list[pa.RecordBatch]]) -> None:
    """The logged map (tiles, markings, lane centres, objects) and each episode's trail,
    ending in a cross where the episode collided or left the road."""
    _draw_boxes(ax, chunks[R.TILES])
    _draw_strips(ax, chunks[R.WHITE_MARKINGS], 1.6)
    _draw_strips(ax, chunks[R.YELLOW_MARKINGS], 1.0)
    _draw_strips(ax, chunks[R.LANES], 0.5, alpha=0.5, linestyle=":")
    _draw_boxes(ax, chunks[R.OBJECTS], edge="black")
    trail = positions(chunks)
    collisions = scalars(chunks, R.episode_path("collision"))
    crashed = {int(e) for e, c in zip(collisions.episodes, collisions.values, strict=True) if c}
    points = np.asarray(trail.values)
    for k, episode in enumerate(np.unique(trail.episodes)):
        xy = points[trail.episodes == episode]
        colour = _TRAIL_COLOURS[k % len(_TRAIL_COLOURS)]
        ax.plot(xy[:, 0], xy[:, 1], color=colour, linewidth=2.2, label=f"episode {episode}")
        ax.plot(*xy[0], "o", color="white", markeredgecolor=colour, markersize=6)
        ax.plot(*xy[-1], "X" if episode in crashed else "s", color=colour,
                markeredgecolor="black", markersize=10 if episode in crashed else 6)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("map and trails (o start, X collision or off road)", fontsize=10)
    ax.legend(loc="lower right", fontsize=8)


def draw_series(ax, chunks: dict[str, list[pa.RecordBatch]]) -> None:
    """Lane cost, collision cost and lateral offset over simulated time, one segment per
    episode."""
    for path, label, colour, scale in (
            (R.cost_path("lane"), "lane cost (dm)", "#e6194b", 1.0),
            (R.cost_path("collision"), "collision cost", "#800000", 1.0),
            (R.LATERAL, "lateral offset (dm, + right)", "#0082c8", 10.0)):
        data = scalars(chunks, path)
        values = np.asarray(data.values) * scale
        for k, episode in enumerate(np.unique(data.episodes)):
            rows = data.episodes == episode
            ax.plot(data.times[rows], values[rows], color=colour, linewidth=1.2,
                    label=label if k == 0 else None)
            if k:
                ax.axvline(data.times[rows][0], color="grey", linewidth=0.6, linestyle="--")
    ax.axhline(0.0, color="grey", linewidth=0.5)
    ax.set_xlabel("simulated time (s); dashed: episode starts")
    ax.legend(loc="upper right", fontsize=8)


def draw_frames(axes: Sequence, frames: Series) -> None:
    """Camera frames evenly spread over the recording."""
    picks = np.linspace(0, len(frames.values) - 1, len(axes)).round().astype(int)
    for ax, k in zip(axes, picks, strict=True):
        ax.imshow(frames.values[k], interpolation="nearest")
        ax.set_title(f"episode {frames.episodes[k]}, t = {frames.times[k]:.1f} s", fontsize=8)
        ax.axis("off")


def draw_recording(path: str | Path, out: str | Path, title: str | None = None) -> Path:
    """Write a picture of the recording at ``path`` to ``out`` (PNG)."""
    chunks = read_recording(path)
    figure = plt.figure(figsize=_FIGURE_SIZE, dpi=100)
    outer = figure.add_gridspec(1, 2, width_ratios=[1.05, 1], left=0.05, right=0.99,
                                top=0.9, bottom=0.09, wspace=0.12)
    draw_topdown(figure.add_subplot(outer[0]), chunks)
    right = outer[1].subgridspec(2, _FRAMES, height_ratios=[1, 1.6], hspace=0.3, wspace=0.05)
    draw_frames([figure.add_subplot(right[0, k]) for k in range(_FRAMES)], images(chunks))
    draw_series(figure.add_subplot(right[1, :]), chunks)
    figure.suptitle(title or f"{Path(path).name}: map, trails, robot camera (30×40) and costs, "
                    "all read back from the rerun recording")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out)
    plt.close(figure)
    return out


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description="Draw a picture of a crllk rerun recording.")
    parser.add_argument("recording", type=Path)
    parser.add_argument("--out", type=Path, default=Path("docs/images/recording.png"))
    parser.add_argument("--title", default=None)
    args = parser.parse_args(argv)
    if not args.recording.is_file():
        raise ConfigError(args.recording, "recording", "no such file")
    problem = write_problem(args.out)
    if problem:
        raise ConfigError(args.out, "--out", problem)
    print(draw_recording(args.recording, args.out, args.title))


__all__ = ["Series", "draw_recording", "images", "positions", "scalars", "series",
           "static_value"]


if __name__ == "__main__":
    run(main)
