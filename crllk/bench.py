"""Throughput benchmarks, each figure next to the bound it is measured against in the same run.

    python -m crllk.bench [--task small_loop] [--steps 3000]

Bounds (DESIGN.md section 7): a state-observation environment step should cost at most twice
the raw MuJoCo physics of one control step (ratio >= 0.5); a pixel environment step at most
1/0.6 of the raw physics-plus-render of the same scene (ratio >= 0.6) and the pixel environment
should reach 1,000 steps/s on 2 cores.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence

import mujoco
import numpy as np

import crllk
from crllk.sim import constants as C
from crllk.sim.scene import compile_scene
from crllk.task_config import load_task_config


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
    renderer.close()
    return rate


def env_rate(task: str, observation: str, steps: int, seed: int = 0) -> float:
    """Steps/s of ``crllk.load(task)`` under uniformly random discrete actions."""
    env = crllk.load(task, observation=observation, action="discrete", seed=seed)
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


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="small_loop")
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args(argv)
    raw = raw_physics_rate(args.task, args.steps)
    render = raw_render_rate(args.task, args.steps)
    state = env_rate(args.task, "state", args.steps)
    pixels = env_rate(args.task, "pixels", args.steps)
    print(f"task {args.task}, {args.steps} steps per figure, single process")
    print(f"{'figure':<44}{'steps/s':>10}{'bound':>10}{'ratio':>8}{'target':>8}")
    rows = [("raw MuJoCo physics (8 substeps)", raw, None, None),
            ("raw physics + camera render", render, None, None),
            ("env, state observations", state, raw, 0.5),
            ("env, pixel observations", pixels, render, 0.6)]
    for name, rate, bound, target in rows:
        if bound is None:
            print(f"{name:<44}{rate:>10.0f}")
        else:
            ratio = rate / bound
            print(f"{name:<44}{rate:>10.0f}{bound:>10.0f}{ratio:>8.2f}{target:>8.2f}"
                  f"  {'met' if ratio >= target else 'MISSED'}")


if __name__ == "__main__":
    main()
