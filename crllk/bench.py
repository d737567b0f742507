"""Throughput benchmarks, each figure next to the bound it is measured against in the same run.

    python -m crllk.bench [--task small_loop] [--steps 3000] [--batched] [--training]
                          [--runs RUN_DIR ...]

Bounds (DESIGN.md section 7): a state-observation environment step should cost at most twice
the raw MuJoCo physics of one control step (ratio >= 0.5); a pixel environment step at most
1/0.6 of the raw physics-plus-render of the same scene (ratio >= 0.6) and the pixel environment
should reach 1,000 steps/s on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import time
from collections.abc import Callable, Sequence
from pathlib import Path

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


def _print_row(name: str, rate: float, bound: float | None = None,
               target: float | None = None) -> None:
    if bound is None or target is None:
        print(f"{name:<48}{rate:>10.0f}")
        return
    ratio = rate / bound
    print(f"{name:<48}{rate:>10.0f}{bound:>10.0f}{ratio:>8.2f}{target:>8.2f}"
          f"  {'met' if ratio >= target else 'MISSED'}")


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="small_loop")
    parser.add_argument("--steps", type=int, default=3000, help="control steps per figure")
    parser.add_argument("--num-envs", type=int, default=32,
                        help="simulations of the batched environment figures")
    parser.add_argument("--batched", action="store_true",
                        help="add batched make_env figures (crllk.envs)")
    parser.add_argument("--training", action="store_true",
                        help="add training frames/s next to environment-only frames/s")
    parser.add_argument("--iterations", type=int, default=5,
                        help="training iterations per training figure")
    parser.add_argument("--overrides", nargs="*", default=[],
                        help="trainer overrides for the training figures (e.g. num_envs=4)")
    parser.add_argument("--runs", nargs="*", type=Path, default=[],
                        help="run directories whose eval.csv gives the time to satisfy both "
                             "constraints")
    args = parser.parse_args(argv)
    raw = raw_physics_rate(args.task, args.steps)
    render = raw_render_rate(args.task, args.steps)
    print(f"task {args.task}, {args.steps} steps per figure")
    print(f"{'figure':<48}{'steps/s':>10}{'bound':>10}{'ratio':>8}{'target':>8}")
    _print_row("raw MuJoCo physics (8 substeps)", raw)
    _print_row("raw physics + camera render", render)
    _print_row("env, state observations", env_rate(args.task, "state", args.steps), raw, 0.5)
    _print_row("env, pixel observations", env_rate(args.task, "pixels", args.steps), render, 0.6)
    if args.batched:
        from crllk.bench_envs import batched_env_rate

        steps = max(1, args.steps // args.num_envs)
        for observation, bound, target in (("state", raw, 0.5), ("pixels", render, 0.6)):
            rate = batched_env_rate(args.task, observation, args.num_envs, steps)
            _print_row(f"make_env {observation}, num_envs={args.num_envs}", rate, bound, target)
    if args.training:
        from crllk.bench_training import bench_config, training_rates

        for observation in ("state", "pixels"):
            config = bench_config([f"task={args.task}", f"obs={observation}", *args.overrides])
            rates = training_rates(config, iterations=args.iterations)
            _print_row(f"env only, {observation}, num_envs={config.num_envs}", rates.environment)
            _print_row(f"training, {observation} (frames/s)", rates.training,
                       rates.environment, 0.5)
    for run_dir in args.runs:
        seconds, frames = time_to_constraints(run_dir)
        verdict = ("never" if seconds is None
                   else f"{seconds:.0f} s ({seconds / 60:.1f} min) at {frames} frames")
        print(f"time to satisfy both constraints, {run_dir}: {verdict}")


if __name__ == "__main__":
    main()
