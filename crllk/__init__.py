"""crllk: constrained reinforcement learning for Duckiebot lane keeping in MuJoCo.

``crllk.load(task, observation=..., action=..., seed=...)`` returns a dm-control environment;
``crllk.make_env(task, num_envs=N, ...)`` returns one batched TorchRL environment;
``crllk.maps.load_map(name_or_path)`` returns a map with its exact lane geometry.
"""

from __future__ import annotations

import os

# Headless rendering must be chosen before mujoco or dm_control is imported.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
# Mesa's software rasteriser draws on the calling thread: the robot camera's small frames are
# a few of its tiles, and its helper threads only add hand-offs (and compete with the other
# simulation process for the second core). Also as fast at 640x480.
os.environ.setdefault("LP_NUM_THREADS", "0")

from crllk.errors import show_map_warnings_on_one_line

show_map_warnings_on_one_line()

__all__ = ["load", "make_env", "maps"]


def __getattr__(name: str):
    """``crllk.load``, ``crllk.make_env`` and ``crllk.maps`` import MuJoCo, dm-control and
    TorchRL only when first used, so that parts which need none of them (the pilot on a
    robot) import without them."""
    if name == "load":
        from crllk.tasks.lane_keeping import load

        return load
    if name == "make_env":
        from crllk.envs.batched import make_env

        return make_env
    if name == "maps":
        import crllk.maps

        return crllk.maps
    raise AttributeError(f"module 'crllk' has no attribute {name!r}")
__version__ = "0.1.0"
