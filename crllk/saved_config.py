"""A run's saved ``config.yaml``: read as safely as a task file, and brought to the current
layout of the settings (:class:`crllk.config.TrainConfig` validates it then)."""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from crllk.errors import ConfigError
from crllk.yaml_files import read_yaml


def read_run_config(path: str | Path) -> DictConfig:
    """A run's saved ``config.yaml`` in the current layout (:func:`upgrade`), read
    as task files are (:func:`crllk.yaml_files.read_yaml`: size-limited, duplicate keys and
    alias bombs refused) before OmegaConf sees it.

    Raises:
        ConfigError: naming the file and what is wrong with it.
    """
    path = Path(path)
    content = read_yaml(path)
    if not isinstance(content, dict):
        raise ConfigError(path, "<file>", "not a run configuration (expected a mapping)")
    try:
        return upgrade(OmegaConf.create(content))
    except (OmegaConfBaseException, ValueError) as err:
        raise ConfigError(path, "<file>", f"unreadable: {' '.join(str(err).split())}") from None


def upgrade(stored: DictConfig) -> DictConfig:
    """A run's saved ``config.yaml`` in the current layout: multipliers that an older version
    kept at ``algo.lane`` and ``algo.collision`` move to ``algo.constraints.<name>``."""
    algo = stored.get("algo")
    if algo is not None and "constraints" not in algo:
        moved = {name: algo.pop(name) for name in ("lane", "collision") if name in algo}
        algo["constraints"] = moved
    return stored


__all__ = ["read_run_config", "upgrade"]
