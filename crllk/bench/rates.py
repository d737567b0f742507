"""Throughput figures: raw physics and rendering, the dm-control environment, and the time a run
took to satisfy both constraints."""

from __future__ import annotations

import csv
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

import crllk
from crllk.sim import constants as C
from crllk.sim.physics import close_renderer
from crllk.sim.scene import compile_scene
from crllk.tasks.config import load_task_config

ACTION_CYCLE = 1000
"""Random actions drawn once and cycled through by the environment figures."""
WARMUP_CALLS = 50
"""Calls made before timing a figure (first renders, caches)."""
ROUNDS = 50
"""Chunks in which figures measured together are timed in turns."""


def rate_of(step: Callable[[], None], steps: int, warmup: int = WARMUP_CALLS) -> float:
    """Calls per second of ``step`` over ``steps`` calls, after ``warmup`` calls."""
    for _ in range(min(warmup, steps)):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - start)


def interleaved_rates(steps_of: Sequence[Callable[[], None]], steps: int,
                      rounds: int = ROUNDS, warmup: int = WARMUP_CALLS) -> list[float]:
    """Calls per second of each of ``steps_of`` over ``steps`` calls each, timed in ``rounds``
    chunks taken in turns (the order reversed every other round): the median of its chunks'
    rates, so that a burst of load from other processes falls on few chunks and on all
    figures alike. After ``warmup`` calls of each."""
    for step in steps_of:
        for _ in range(min(warmup, steps)):
            step()
    rounds = max(1, min(rounds, steps))
    rates: list[list[float]] = [[] for _ in steps_of]
    order = list(range(len(steps_of)))
    for turn in range(rounds):
        calls = steps * (turn + 1) // rounds - steps * turn // rounds
        for k in order if turn % 2 == 0 else order[::-1]:
            start = time.perf_counter()
            for _ in range(calls):
                steps_of[k]()
            rates[k].append(calls / (time.perf_counter() - start))
    return [float(np.median(chunks)) for chunks in rates]


def raw_physics_rate(task: str, steps: int) -> float:
    """Control steps/s of bare ``mj_step`` (8 substeps) on the task's compiled scene."""
    config = load_task_config(task)
    model = compile_scene(config.map, config.motor)
    data = mujoco.MjData(model)
    substeps = round(config.control_timestep / model.opt.timestep)
    data.ctrl[:] = (0.2, 0.5)
    return rate_of(lambda: mujoco.mj_step(model, data, substeps), steps)


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

    rate = rate_of(step, steps)
    close_renderer(renderer)
    return rate


def env_rate(task: str, observation: str, steps: int, seed: int = 0,
             overrides: dict[str, Any] | None = None) -> float:
    """Steps/s of ``crllk.load(task)`` (task settings ``overrides``) under uniformly random
    discrete actions."""
    step, close = env_stepper(task, observation, seed, overrides)
    rate = rate_of(step, steps)
    close()
    return rate


def env_stepper(task: str, observation: str, seed: int = 0,
                overrides: dict[str, Any] | None = None) -> tuple[Callable[[], None],
                                                                  Callable[[], None]]:
    """A function that steps ``crllk.load(task)`` (task settings ``overrides``) once under a
    uniformly random discrete action, resetting at episode ends, and one that frees its
    renderers."""
    env = crllk.load(task, observation=observation, action="discrete", seed=seed,
                     overrides=overrides)
    actions = np.random.default_rng(seed).integers(0, 3, size=ACTION_CYCLE).tolist()
    env.reset()
    count = 0

    def step() -> None:
        nonlocal count
        timestep = env.step(actions[count % ACTION_CYCLE])
        count += 1
        if timestep.last():
            env.reset()

    return step, env.physics.free_renderers


def paired_rates(make: Callable[..., tuple[Callable[[], None], Callable[[], None]]],
                 steps: int, overrides: dict[str, Any]) -> tuple[float, float]:
    """Calls/s of the stepper ``make()`` builds and of the one ``make(overrides=overrides)``
    builds, timed in turns (:func:`interleaved_rates`)."""
    plain, changed = make(), make(overrides=overrides)
    rates = interleaved_rates([plain[0], changed[0]], steps)
    plain[1]()
    changed[1]()
    return rates[0], rates[1]


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
