"""``python -m crllk.train task=<name>``: Lagrangian PPO (CRLLK) or fixed-weight PPO on a task.

Hydra composes the configuration (``crllk/conf``; every ``tasks/<name>.yaml`` is a choice of
the ``task`` group), :func:`resolve_config` checks it (a resumed run keeps its saved settings)
and :func:`crllk.training.loop.train` trains; bad input ends with one line and exit status 2.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

import hydra
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

import crllk  # noqa: F401  (chooses the headless GL backend before torchrl imports mujoco)
from crllk.errors import ConfigError
from crllk.files import read_yaml
from crllk.paths import task_file, task_names
from crllk.training.config import TrainConfig, upgrade, validate
from crllk.training.loop import train

RESUME_KEEPS = ("total_frames", "progress", "threads", "checkpoint_every", "record_every",
                "viewer", "live", "live_port")
"""Settings a resumed run takes from the command line; all others come from its config.yaml."""


def register_tasks(store: ConfigStore, names: Iterable[str] | None = None) -> None:
    """Makes every ``tasks/<name>.yaml`` a choice of the ``task`` group (``task=<name>``)."""
    for name in task_names() if names is None else names:
        data = read_yaml(task_file(name))
        node = dict(data) if isinstance(data, dict) else {}
        node.setdefault("name", name)
        store.store(group="task", name=name, node=node)


def resolve_config(cfg: DictConfig) -> TrainConfig:
    """The validated config; a resumed run keeps its saved settings except
    :data:`RESUME_KEEPS`."""
    config = validate(cfg)
    saved = config.resolved_run_dir() / "config.yaml"
    if config.resume and saved.exists():
        stored = upgrade(OmegaConf.load(saved))
        for key in RESUME_KEEPS:
            stored[key] = getattr(config, key)
        stored["resume"] = True
        stored["run_dir"] = str(config.resolved_run_dir())
        config = validate(stored)
    return config


register_tasks(ConfigStore.instance())


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> None:
    try:
        train(resolve_config(cfg))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(2) from None


def task_paths_as_task_file(argv: list[str]) -> list[str]:
    """``task=PATH`` (a ``.yaml`` task or Duckietown map file) becomes ``task_file=PATH``, so
    that ``task=`` takes a name or a path, as in the other commands."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        out.append(f"task_file={value}" if sep and key == "task"
                   and value.endswith((".yaml", ".yml")) else arg)
    return out


if __name__ == "__main__":
    sys.argv = [sys.argv[0], *task_paths_as_task_file(sys.argv[1:])]
    main()
