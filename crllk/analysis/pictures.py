"""Pictures of the simulator: a top-down view of each map with a driven trajectory, the robot's
camera at policy resolution and at full resolution, and a chase view."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import crllk
from crllk.cli import non_negative_int, positive_int
from crllk.maps import DuckietownMap
from crllk.sim import constants as C
from crllk.sim.physics import Physics
from crllk.tasks.follower import LaneFollower

DEFAULT_MAPS = ("small_loop", "zigzag", "obstacle_loop")


def add_picture_arguments(parser: argparse.ArgumentParser, out: Path) -> None:
    """The options of the commands that draw the maps: ``--out`` (default ``out``),
    ``--maps``, ``--steps`` and ``--seed``."""
    parser.add_argument("--out", type=Path, default=out)
    parser.add_argument("--maps", nargs="+", default=list(DEFAULT_MAPS),
                        help="task names or paths of task or map files")
    parser.add_argument("--steps", type=positive_int, default=512)
    parser.add_argument("--seed", type=non_negative_int, default=0)


_TOPDOWN_SIZE = (600, 800)
"""(height, width) of top-down pictures (px)."""


def overhead_pixel(dmap: DuckietownMap, x: float, y: float, height: int,
                   width: int) -> tuple[float, float]:
    """(column, row) in the overhead camera's image of the world point (x, y).

    The overhead camera is orthographic, centred on the map, with a vertical extent of
    max(map height, map width * 3/4) metres.
    """
    extent = max(dmap.height, dmap.width * 3 / 4)
    metres_per_pixel = extent / height
    return (width / 2 + (x - dmap.width / 2) / metres_per_pixel,
            height / 2 - (y - dmap.height / 2) / metres_per_pixel)


def topdown(physics: Physics, dmap: DuckietownMap, trail: Sequence[tuple[float, float]] = (),
            size: tuple[int, int] = _TOPDOWN_SIZE) -> Image.Image:
    """The overhead view with ``trail`` (world x, y points) drawn on it."""
    height, width = size
    image = Image.fromarray(physics.render_camera(height, width, camera=C.OVERHEAD_CAMERA))
    if len(trail) > 1:
        points = [overhead_pixel(dmap, x, y, height, width) for x, y in trail]
        ImageDraw.Draw(image).line(points, fill=(230, 40, 200), width=3)
    return image


def camera_strip(frames: Sequence[np.ndarray], scale: int = 6) -> Image.Image:
    """Camera frames side by side, enlarged ``scale`` times with nearest-neighbour pixels."""
    gap = 4
    h, w = frames[0].shape[:2]
    strip = Image.new("RGB", (len(frames) * (w * scale + gap) - gap, h * scale), (255, 255, 255))
    for k, frame in enumerate(frames):
        big = Image.fromarray(frame).resize((w * scale, h * scale), Image.Resampling.NEAREST)
        strip.paste(big, (k * (w * scale + gap), 0))
    return strip


def drive(task: str, steps: int, seed: int = 0, snapshots: int = 4) -> dict:
    """Drive the scripted follower on ``task``; return its trail, camera frames and metrics."""
    env = crllk.load(task, observation="pixels", action="duty", seed=seed,
                     overrides={"horizon": steps})
    follower = LaneFollower(env.task.map, env.task.config.motor)
    timestep = env.reset()
    trail, frames, full_frames = [env.physics.pose()[:2]], [], []
    snap_at = set(np.linspace(0, steps - 1, snapshots).astype(int).tolist())
    distance, lane_costs, collisions, step = 0.0, [], 0.0, 0
    while not timestep.last():
        if step in snap_at:
            frames.append(timestep.observation["pixels"])
            full_frames.append(env.physics.render_camera(240, 320, camera=C.CAMERA))
        timestep = env.step(follower.duty(env.physics))
        step += 1
        trail.append(env.physics.pose()[:2])
        distance += timestep.reward
        lane_costs.append(float(timestep.observation["cost_lane"]))
        collisions += float(timestep.observation["cost_collision"])
    return {"env": env, "trail": trail, "frames": frames, "full_frames": full_frames,
            "steps": step, "distance": distance, "lane_cost": float(np.mean(lane_costs)),
            "collisions": collisions, "termination": env.task.outcome.termination}


def picture_stem(task: str) -> str:
    """How a task's pictures are named: the task's name, or the stem of its file."""
    return Path(task).stem if task.endswith((".yaml", ".yml")) else task


def write_pictures(task: str, out: Path, steps: int = 512, seed: int = 0) -> dict:
    """Drive ``task`` (a name or the path of a task or map file) and write
    ``<stem>_topdown.png``, ``<stem>_camera.png`` (policy resolution), ``<stem>_camera_full.png``
    and ``<stem>_chase.png`` into ``out`` (:func:`picture_stem`)."""
    out.mkdir(parents=True, exist_ok=True)
    run = drive(task, steps, seed)
    env = run["env"]
    stem = picture_stem(task)
    topdown(env.physics, env.task.map, run["trail"]).save(out / f"{stem}_topdown.png")
    camera_strip(run["frames"]).save(out / f"{stem}_camera.png")
    camera_strip(run["full_frames"], scale=1).save(out / f"{stem}_camera_full.png")
    Image.fromarray(env.physics.render_camera(360, 480, camera=C.CHASE_CAMERA)).save(
        out / f"{stem}_chase.png")
    env.physics.free_renderers()
    return run
