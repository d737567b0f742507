"""Throughput of the batched TorchRL environment, next to the raw MuJoCo bounds.

    python -m crllk.bench.envs [--task small_loop] [--steps 300] [--num-envs 1 8 32]
                               [--observations state pixels]

Frames are environment steps of one sub-environment: a batched step of N sub-environments is
N frames. The raw bounds (:func:`crllk.bench.rates.raw_physics_rate`, ``raw_render_rate``) are
single-simulation control steps/s, so the ratio frames/s / bound is comparable to the budgets
of the targets (state >= 0.5, pixels >= 0.6).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from crllk.bench.rates import ACTION_CYCLE, rate_of, raw_physics_rate, raw_render_rate
from crllk.cli import Parser, positive_int, run
from crllk.envs.batched import make_env

WARMUP_STEPS = 10
"""Batched steps made before timing a batched figure."""


def batched_env_rate(task: str, observation: str, num_envs: int, steps: int,
                     seed: int = 0, overrides: dict[str, Any] | None = None) -> float:
    """Frames/s (``steps * num_envs`` over the time) of ``make_env(task, num_envs=...)``
    (task settings ``overrides``) stepped with uniformly random discrete actions and TorchRL
    auto-reset."""
    step, close = batched_stepper(task, observation, num_envs, seed, overrides)
    rate = rate_of(step, steps, WARMUP_STEPS)
    close()
    return rate * num_envs


def batched_stepper(task: str, observation: str, num_envs: int, seed: int = 0,
                    overrides: dict[str, Any] | None = None) -> tuple[Callable[[], None],
                                                                      Callable[[], None]]:
    """A function that steps ``make_env(task, num_envs=...)`` (task settings ``overrides``)
    once with uniformly random discrete actions and TorchRL auto-reset, and one that closes
    the env."""
    env = make_env(task, num_envs=num_envs, observation=observation, action="discrete",
                   seed=seed, overrides=overrides)
    generator = torch.Generator().manual_seed(seed)
    actions = torch.randint(0, 3, (ACTION_CYCLE, num_envs), generator=generator)
    tensordict, count = env.reset(), 0

    def step() -> None:
        nonlocal tensordict, count
        tensordict["action"] = actions[count % ACTION_CYCLE]
        _, tensordict = env.step_and_maybe_reset(tensordict)
        count += 1

    return step, env.close


def main(argv: Sequence[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="small_loop")
    parser.add_argument("--steps", type=positive_int, default=300, help="batched steps per figure")
    parser.add_argument("--num-envs", type=positive_int, nargs="+", default=[1, 8, 32])
    parser.add_argument("--observations", nargs="+", default=["state", "pixels"],
                        choices=["state", "pixels"])
    args = parser.parse_args(argv)
    raw_steps = 3000
    rates = {"state": raw_physics_rate, "pixels": raw_render_rate}
    targets = {"state": 0.5, "pixels": 0.6}
    bounds = {obs: (rates[obs](args.task, raw_steps), targets[obs]) for obs in args.observations}
    print(f"task {args.task}, {args.steps} batched steps per figure, single process")
    print(f"{'figure':<36}{'frames/s':>10}{'bound':>10}{'ratio':>8}{'target':>8}")
    for observation, (bound, target) in bounds.items():
        for num_envs in args.num_envs:
            rate = batched_env_rate(args.task, observation, num_envs, args.steps)
            ratio = rate / bound
            name = f"make_env {observation}, num_envs={num_envs}"
            print(f"{name:<36}{rate:>10.0f}{bound:>10.0f}{ratio:>8.2f}{target:>8.2f}"
                  f"  {'met' if ratio >= target else 'MISSED'}")


if __name__ == "__main__":
    run(main)
