"""Throughput figures: raw physics and rendering, the dm-control environment, and the time a run
took to satisfy both constraints."""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

import crllk
from crllk.sim import constants as C
from crllk.sim.physics import close_renderer
from crllk.sim.scene import compile_scene
from crllk.tasks.config import load_task_config


def _rate(step: Callable[[], None], steps: int) -> float:
    """Calls per second of ``step`` over ``steps`` calls (after a short warm-up)."""
    for _ in range(min(50, steps)):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - start)


def raw_physics_rate(task: str, steps: int) -> float:
    """Control steps/s of bare ``mj_step`` (8 substeps) on the task's compiled scene."""
    config = load_task_config(task)
    model = compile_scene(config.map, config.motor)
    data = mujoco.MjData(model)
    substeps = round(config.control_timestep / model.opt.timestep)
    data.ctrl[:] = (0.2, 0.5)
    return _rate(lambda: mujoco.mj_step(model, data, substeps), steps)


def raw_render_rate(task: str, steps: int) -> float:
    """Control steps/s of bare ``mj_step`` plus one camera render at the policy's render size
    (observation size times supersampling) with a reused ``mujoco.Renderer``."""
    config = load_task_config(task)
    model = compile_scene(config.map, config.motor)
    data = mujoco.MjData(model)
    substeps = round(config.control_timestep / model.opt.timestep)
    cam = config.camera
    renderer = mujoco.Renderer(model, cam.height * cam.supersample, cam.width * cam.supersample)
    data.ctrl[:] = (0.2, 0.5)

    def step() -> None:
        mujoco.mj_step(model, data, substeps)
        renderer.update_scene(data, camera=C.CAMERA)
        renderer.render()

    rate = _rate(step, steps)
    close_renderer(renderer)
    return rate


def env_rate(task: str, observation: str, steps: int, seed: int = 0,
             overrides: dict[str, Any] | None = None) -> float:
    """Steps/s of ``crllk.load(task)`` (task settings ``overrides``) under uniformly random
    discrete actions."""
    env = crllk.load(task, observation=observation, action="discrete", seed=seed,
                     overrides=overrides)
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, 3, size=steps + 100)
    env.reset()
    counter = iter(range(10**9))

    def step() -> None:
        timestep = env.step(actions[next(counter) % len(actions)])
        if timestep.last():
            env.reset()

    rate = _rate(step, steps)
    env.physics.free_renderers()
    return rate


def time_to_constraints(run_dir: Path) -> tuple[float | None, int | None]:
    """Training time (s: wall time without the evaluations before it) and frames at the first
    evaluation in ``run_dir/eval.csv`` where both constraints held, or ``(None, None)``."""
    evaluating = 0.0
    with (run_dir / "eval.csv").open(newline="") as handle:
        for row in csv.DictReader(handle):
            if row["satisfied"] == "1":
                return float(row["time_s"]) - evaluating, int(row["frames"])
            evaluating += float(row.get("evaluation_s") or 0.0)
    return None, None


def print_row(name: str, rate: float, bound: float | None = None,
               target: float | None = None) -> None:
    if bound is None:
        print(f"{name:<48}{rate:>10.0f}")
        return
    if target is None:
        print(f"{name:<48}{rate:>10.0f}{bound:>10.0f}{rate / bound:>8.2f}")
        return
    ratio = rate / bound
    print(f"{name:<48}{rate:>10.0f}{bound:>10.0f}{ratio:>8.2f}{target:>8.2f}"
          f"  {'met' if ratio >= target else 'MISSED'}")
