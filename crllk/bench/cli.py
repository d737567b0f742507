"""Throughput benchmarks, each figure next to the bound it is measured against in the same run.

    python -m crllk.bench [--task small_loop] [--steps 3000] [--batched] [--training]
                          [--randomize-parts] [--traffic] [--workers 1 2 [--obs pixels state]]
                          [--runs RUN_DIR ...]

Bounds: a state-observation environment step should cost at most twice
the raw MuJoCo physics of one control step (ratio >= 0.5); a pixel environment step at most
1/0.6 of the raw physics-plus-render of the same scene (ratio >= 0.6) and the pixel environment
should reach 1,000 steps/s on 2 cores; with ``randomize=default`` pixel steps should keep 90 %
of their rate without, for one environment and for the batched one (each pair timed in turns,
in short chunks; each figure the median of its chunks', so that bursts of load from other
processes hardly count); ``--traffic`` times the batched pixel env of a task with traffic
against the same task without its movers (target: 80 % of its rate).
``--workers 1 2`` times collection (policy in this process, simulations
in that many worker processes) and whole training iterations for each worker count, each
against the first count's figure (no target: the ratio is the speed-up); with ``--overrides
collector=ray`` the simulations and the policy run in that many remote collectors of a private
Ray instance (or of the cluster at ``ray_address=host:port``).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crllk.bench.rates import (
    env_rate,
    env_stepper,
    interleaved_rates,
    paired_rates,
    print_row,
    raw_physics_rate,
    raw_render_rate,
    time_to_constraints,
)
from crllk.cli import Parser, fail, positive_int, run
from crllk.errors import ConfigError
from crllk.tasks.config import load_task_config
from crllk.tasks.randomization import PRESETS

if TYPE_CHECKING:
    from crllk.config import TrainConfig

RANDOMIZED = {"randomize": "default"}
"""Task settings of the randomised figures, each measured against the same env without."""
RANDOMIZED_TARGET = 0.9
"""Domain randomisation may slow pixel steps by at most 10 %."""
RANDOMIZED_PARTS = {
    "lighting": ("light_intensity", "light_tilt", "ambient", "headlight"),
    "colours": ("floor_color", "horizon_color", "object_color"),
    "camera pose": ("camera_height", "camera_pitch", "camera_fov", "camera_position_noise"),
    "JPEG compression": ("jpeg_quality",),
    "sensor noise": ("sensor_noise",),
    "dynamics": ("max_speed", "yaw_rate", "wheel_distance", "time_constants", "delay", "trim"),
}
"""The parts of ``randomize=default`` that ``--randomize-parts`` times one at a time."""
TRAFFIC_TARGET = 0.8
"""Moving agents may slow pixel steps by at most 20 %."""


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="small_loop")
    parser.add_argument("--steps", type=positive_int, default=3000,
                        help="control steps per figure")
    parser.add_argument("--num-envs", type=positive_int, default=32,
                        help="simulations of the batched environment figures")
    parser.add_argument("--batched", action="store_true",
                        help="add batched make_env figures (crllk.envs.batched)")
    parser.add_argument("--training", action="store_true",
                        help="add training frames/s next to environment-only frames/s")
    parser.add_argument("--iterations", type=positive_int, default=5,
                        help="training iterations per training figure")
    parser.add_argument("--overrides", nargs="*", default=[],
                        help="trainer overrides for the training figures (e.g. num_envs=4)")
    parser.add_argument("--workers", nargs="+", type=positive_int, default=[],
                        help="worker-process counts whose collection and training frames/s to "
                             "compare (the trainer's workers setting), e.g. 1 2")
    parser.add_argument("--obs", nargs="+", choices=("pixels", "state"),
                        default=["pixels", "state"], help="observations of the --workers figures")
    parser.add_argument("--randomize-parts", action="store_true",
                        help="time each part of randomize=default alone against the pixel env "
                             "without randomisation (where the randomisation cost goes)")
    parser.add_argument("--traffic", action="store_true",
                        help="time the batched pixel env of --task (one with traffic) against the "
                             "same task without its movers, in turns")
    parser.add_argument("--runs", nargs="*", type=Path, default=[],
                        help="run directories whose eval.csv gives the time to satisfy both "
                             "constraints")
    args = parser.parse_args(argv)
    for run_dir in args.runs:
        if not (run_dir / "eval.csv").is_file():
            fail(f"{run_dir}: --runs: no eval.csv (not a run directory, or no evaluation yet)")
    try:
        config = load_task_config(args.task)
        if args.traffic and config.traffic is None:
            raise ConfigError(args.task, "traffic", "--traffic needs a task with traffic "
                              "(e.g. tasks/traffic_loop.yaml)")
        worker_configs = worker_bench_configs(args.task, args.workers, args.obs, args.overrides)
        training_configs = (training_bench_configs(args.task, args.overrides)
                            if args.training else [])
    except ConfigError as err:
        fail(err)
    raw = raw_physics_rate(args.task, args.steps)
    render = raw_render_rate(args.task, args.steps)
    print(f"task {args.task}, {args.steps} steps per figure")
    print(f"{'figure':<48}{'steps/s':>10}{'bound':>10}{'ratio':>8}{'target':>8}")
    print_row("raw MuJoCo physics (8 substeps)", raw)
    print_row("raw physics + camera render", render)
    print_row("env, state observations", env_rate(args.task, "state", args.steps), raw, 0.5)
    pixels, randomized = paired_rates(functools.partial(env_stepper, args.task, "pixels"),
                                      args.steps, RANDOMIZED)
    print_row("env, pixel observations", pixels, render, 0.6)
    print_row("env, pixels, randomize=default", randomized, pixels, RANDOMIZED_TARGET)
    if args.randomize_parts:
        print_randomization_parts(args.task, args.steps)
    if args.batched:
        print_batched_figures(args.task, args.num_envs, args.steps, raw, render)
    if args.traffic:
        print_traffic_figures(args.task, args.num_envs, args.steps)
    if training_configs:
        from crllk.bench.training import training_rates

        for config in training_configs:
            observation = config.obs.name
            ahead = ", collect_ahead" if config.collect_ahead else ""
            rates = training_rates(config, iterations=args.iterations)
            print_row(f"env only, {observation}{ahead}, num_envs={config.num_envs}",
                      rates.environment)
            print_row(f"training, {observation}{ahead} (frames/s)", rates.training,
                       rates.environment, 0.5)
    if worker_configs:
        print_worker_figures(worker_configs, args.iterations)
    for run_dir in args.runs:
        seconds, frames = time_to_constraints(run_dir)
        verdict = ("never" if seconds is None
                   else f"{seconds:.0f} s ({seconds / 60:.1f} min) at {frames} frames")
        print(f"time to satisfy both constraints, {run_dir}: {verdict}")


def training_bench_configs(task: str, overrides: Sequence[str]) -> list[TrainConfig]:
    """The trainer configurations of the ``--training`` figures, state, state collecting
    ahead (``collect_ahead=true``, unless the overrides decide it) and
    pixels (checked before anything is measured).

    Raises:
        ConfigError: if an override is bad, or asks for remote collectors (these figures step
            the training env in this process too).
    """
    from crllk.bench.training import bench_config

    state = bench_config([f"task={task}", "obs=state", *overrides])
    if state.collector != "local":
        raise ConfigError("--overrides", "collector", "--training times local collection; time "
                          "collector=ray with --workers")
    settings = [["obs=pixels"]]
    decided = any(o.split("=", 1)[0].lstrip("+") == "collect_ahead" for o in overrides)
    if not decided:
        settings.insert(0, ["obs=state", "collect_ahead=true"])
    return [state, *(bench_config([f"task={task}", *setting, *overrides])
                     for setting in settings)]


def randomization_part(part: str) -> dict[str, Any]:
    """The ``randomize`` setting of one part of the ``default`` preset (:data:`RANDOMIZED_PARTS`),
    the other parts off."""
    preset = PRESETS["default"]
    return {name: list(value) if isinstance(value, tuple) else value
            for name in RANDOMIZED_PARTS[part] for value in [getattr(preset, name)]}


def print_randomization_parts(task: str, steps: int) -> None:
    """The pixel env with each part of ``randomize=default`` alone, and with all of it, each
    against the env without randomisation, all timed in turns in one run."""
    settings = {"none": None, **{part: {"randomize": randomization_part(part)}
                                 for part in RANDOMIZED_PARTS}, "all (default)": RANDOMIZED}
    steppers = {name: env_stepper(task, "pixels", overrides=overrides)
                for name, overrides in settings.items()}
    rates = dict(zip(steppers, interleaved_rates([s[0] for s in steppers.values()], steps),
                     strict=True))
    for _, close in steppers.values():
        close()
    for name, rate in rates.items():
        if name != "none":
            print_row(f"env, pixels, randomize: {name}", rate, rates["none"])


def print_batched_figures(task: str, num_envs: int, steps: int, raw: float,
                          render: float) -> None:
    """The batched env's frames/s with state and pixel observations against their raw bounds,
    and with ``randomize=default`` against the pixel figure timed in turns with it."""
    from crllk.bench.envs import batched_env_rate, batched_stepper

    batched_steps = max(1, steps // num_envs)
    state = batched_env_rate(task, "state", num_envs, batched_steps)
    print_row(f"make_env state, num_envs={num_envs}", state, raw, 0.5)
    pixels, randomized = paired_rates(
        functools.partial(batched_stepper, task, "pixels", num_envs), batched_steps, RANDOMIZED)
    pixels, randomized = pixels * num_envs, randomized * num_envs
    print_row(f"make_env pixels, num_envs={num_envs}", pixels, render, 0.6)
    print_row(f"make_env pixels, randomize=default, num_envs={num_envs}", randomized, pixels,
              RANDOMIZED_TARGET)


def without_traffic(task: str) -> dict[str, Any]:
    """Task settings that take a task's movers away, and the constraints that need them."""
    config = load_task_config(task)
    return {"traffic": None, "constraints": [c.name for c in config.constraints
                                             if c.signal != "headway"]}


def print_traffic_figures(task: str, num_envs: int, steps: int) -> None:
    """The batched pixel env of ``task`` with its traffic against the same task without its
    movers, timed in turns."""
    from crllk.bench.envs import batched_stepper

    traffic, plain = paired_rates(functools.partial(batched_stepper, task, "pixels", num_envs),
                                  max(1, steps // num_envs), without_traffic(task))
    print_row(f"make_env pixels without movers, num_envs={num_envs}", plain * num_envs)
    print_row(f"make_env pixels with traffic, num_envs={num_envs}", traffic * num_envs,
              plain * num_envs, TRAFFIC_TARGET)


def worker_bench_configs(task: str, workers: Sequence[int], observations: Sequence[str],
                         overrides: Sequence[str]) -> dict[str, list[TrainConfig]]:
    """The trainer configurations of the ``--workers`` figures, by observation (checked before
    anything is measured).

    Raises:
        ConfigError: if a worker count does not divide num_envs, or an override is bad.
    """
    if not workers:
        return {}
    from crllk.bench.training import bench_config

    return {observation: [bench_config([f"task={task}", f"obs={observation}", *overrides,
                                        f"workers={count}"]) for count in workers]
            for observation in observations}


def print_worker_figures(configs: dict[str, list[TrainConfig]], iterations: int) -> None:
    """Collection and training frames/s with each number of workers, each against the first
    number's (bound column: that figure; ratio: the speed-up), then the main process's policy
    forward pass and update time."""
    from crllk.bench.training import collection_rates

    for observation, observation_configs in configs.items():
        measured = [collection_rates(config, iterations=iterations)
                    for config in observation_configs]
        base, config = measured[0], observation_configs[0]
        for kind in ("collection", "training"):
            for rates in measured:
                where = "" if rates.collector == "local" else f" collector={rates.collector}"
                print_row(f"{kind}, {observation},{where} workers={rates.workers} (frames/s)",
                          getattr(rates, kind), getattr(base, kind))
        print(f"main process, {observation}: policy forward on {config.num_envs} observations "
              f"{base.policy_ms:.1f} ms; update {base.update_s:.2f} s per iteration of "
              f"{config.frames_per_batch} frames (workers={base.workers})")


if __name__ == "__main__":
    run(main)
