"""``python -m crllk.train task=<name>``: Lagrangian PPO (CRLLK) or fixed-weight PPO on a task.

Hydra composes the configuration (:mod:`crllk.training.compose`: the schema
:class:`~crllk.config.TrainConfig`, the groups in ``crllk/conf``, and every
``tasks/<name>.yaml`` as a choice of the ``task`` group), :func:`resolve_config` checks it
(a resumed run keeps its saved settings) and :func:`crllk.training.loop.train` trains; the
evaluation it makes at the end becomes the run's ``eval.json``, as ``python -m crllk.evaluate``
writes it. Bad input ends with one line and exit status 2.
"""

from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.cli import exit_status
from crllk.config import TrainConfig, validate
from crllk.errors import ConfigError
from crllk.network import keep_ray_launcher_local
from crllk.saved_config import read_run_config
from crllk.training.compose import (
    compose_config,
    launcher_problems,
    register,
    task_paths_as_task_file,
)

RESUME_KEEPS = ("total_frames", "progress", "threads", "workers", "collector", "ray_address",
                "checkpoint_every", "record_every", "viewer", "live", "live_port")
"""Settings a resumed run takes from the command line; all others come from its config.yaml."""


def resolve_config(cfg: DictConfig) -> TrainConfig:
    """The validated config; a resumed run keeps its saved settings except
    :data:`RESUME_KEEPS`."""
    config = validate(cfg)
    saved = config.resolved_run_dir() / "config.yaml"
    if config.resume and saved.exists():
        stored = read_run_config(saved)
        for key in RESUME_KEEPS:
            stored[key] = getattr(config, key)
        stored["resume"] = True
        stored["run_dir"] = str(config.resolved_run_dir())
        config = validate(stored, source=saved)
    return config


register()


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> None:
    status = exit_status(lambda: train_from(resolve_config(cfg)))
    if status:
        raise SystemExit(status)


def train_from(config: TrainConfig) -> None:
    """Trains a run with checked settings. The learner (torch, TorchRL) is imported only here,
    once the settings are known to be good, so bad input is reported in a second or two."""
    from crllk.evaluation.runs import write_final_evaluation
    from crllk.training.loop import train

    train(config, on_final_evaluation=write_final_evaluation)


def check_overrides(argv: list[str]) -> None:
    """Composes a plain command line (no ``--`` options) once before Hydra does, so that an
    unknown setting or choice ends with one line and exit status 2, not Hydra's report; a
    launcher whose plugin is not installed is named the same way, also in a multirun."""
    try:
        for problem in launcher_problems(argv):
            raise problem
        if not any(arg.startswith("-") for arg in argv):
            compose_config(argv)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(2) from None


if __name__ == "__main__":
    sys.argv = [sys.argv[0], *task_paths_as_task_file(sys.argv[1:])]
    check_overrides(sys.argv[1:])
    keep_ray_launcher_local(sys.argv[1:])
    main()
