"""The trainer's Hydra configuration: the schema and the task group, composed from overrides.

:func:`register` stores :class:`~crllk.config.TrainConfig` as the schema of
``crllk/conf/train.yaml`` and every ``tasks/<name>.yaml`` as a choice of the ``task`` group.
:func:`compose_config` composes like ``python -m crllk.train`` and turns Hydra's own error text
into one :class:`~crllk.errors.ConfigError` line naming the field and, for a group, its choices.
"""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Iterable, Sequence

from hydra import compose, initialize_config_module
from hydra.core.config_store import ConfigStore
from hydra.errors import HydraException
from omegaconf import DictConfig
from omegaconf.errors import OmegaConfBaseException

from crllk.config import CLUSTER_EXTRA, SOURCE, register_schema
from crllk.errors import ConfigError
from crllk.paths import task_file, task_names
from crllk.yaml_files import read_yaml

CONFIG_MODULE = "crllk.conf"
CONFIG_NAME = "train"
GROUPS = {"task": "tasks/*.yaml", "algo": "crllk/conf/algo", "action": "crllk/conf/action",
          "obs": "crllk/conf/obs", "agent": "crllk/conf/agent"}
"""The trainer's config groups and where their choices live."""


def register(store: ConfigStore | None = None, names: Iterable[str] | None = None) -> None:
    """Stores the schema and makes every ``tasks/<name>.yaml`` a choice of ``task``."""
    store = ConfigStore.instance() if store is None else store
    register_schema(store)
    for name in task_names() if names is None else names:
        data = read_yaml(task_file(name))
        node = dict(data) if isinstance(data, dict) else {}
        node.setdefault("name", name)
        store.store(group="task", name=name, node=node)


def compose_config(overrides: Sequence[str] = ()) -> DictConfig:
    """The trainer's configuration with Hydra-style ``overrides``, not yet checked.

    Raises:
        ConfigError: one line for an unknown setting, group choice or unparsable override.
    """
    register()
    overrides = task_paths_as_task_file(overrides)
    for problem in task_file_problems(overrides):
        raise problem
    try:
        with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
            return compose(config_name=CONFIG_NAME, overrides=overrides)
    except (HydraException, OmegaConfBaseException) as err:
        raise composition_error(err, overrides) from None


def task_paths_as_task_file(overrides: Iterable[str]) -> list[str]:
    """``task=PATH`` (a ``.yaml`` task or Duckietown map file) becomes ``task_file=PATH``, so
    that ``task=`` takes a name or a path, as in the other commands."""
    out = []
    for override in overrides:
        key, sep, value = override.partition("=")
        out.append(f"task_file={value}" if sep and key == "task"
                   and value.endswith((".yaml", ".yml")) else override)
    return out


def task_file_problems(overrides: Iterable[str]) -> list[ConfigError]:
    """A one-line error for each ``task.<key>=...`` given with a task file: the file holds its
    task's settings (the composed ``task`` is the default task's, which the run never reads),
    so the change would be dropped without a word."""
    overrides = list(overrides)
    if not any(o.partition("=")[0].lstrip("+~") == "task_file" for o in overrides):
        return []
    return [ConfigError(SOURCE, key, "a task file's settings are set in the file; task.* "
                        "changes apply to named tasks (edit a copy of the file)")
            for key in (o.partition("=")[0].lstrip("+~") for o in overrides)
            if key.startswith("task.")]


LAUNCHER_PLUGINS = {
    "joblib": ("hydra_plugins.hydra_joblib_launcher", "hydra-joblib-launcher (a dependency)"),
    "submitit": ("hydra_plugins.hydra_submitit_launcher", CLUSTER_EXTRA),
    "ray": ("hydra_plugins.hydra_ray_launcher", CLUSTER_EXTRA),
}
"""Hydra launcher families (``hydra/launcher=<family>_<variant>``): the plugin module each
needs and what installs it."""


def launcher_problems(overrides: Iterable[str]) -> list[ConfigError]:
    """A one-line error for each ``hydra/launcher=NAME`` whose Hydra plugin is not installed
    (Hydra's own report names a missing config file several lines deep)."""
    problems = []
    for override in overrides:
        key, sep, name = override.partition("=")
        if not sep or key.removeprefix("override ").strip() != "hydra/launcher":
            continue
        plugin = LAUNCHER_PLUGINS.get(name.partition("_")[0])
        if plugin and importlib.util.find_spec(plugin[0]) is None:
            problems.append(ConfigError(SOURCE, "hydra/launcher",
                                        f"{name!r} needs {plugin[0]}, from {plugin[1]}"))
    return problems


def composition_error(err: Exception, overrides: Sequence[str]) -> ConfigError:
    """Hydra's multi-line composition error as one line: ``override: <field>: <problem>``."""
    text = str(err)
    group = re.search(r"Could not (?:find|load) '([\w/]+)/([^']*)'", text)
    if group and group.group(1) in GROUPS:
        name = group.group(1)
        choices = re.findall(r"^\t(\S+)$", text, flags=re.MULTILINE)
        listed = f" (choices: {', '.join(choices)})" if choices else ""
        return ConfigError(SOURCE, name, f"unknown choice {group.group(2)!r}{listed}")
    missing_key = re.search(r"Key '([^']+)' is not in struct", text)
    could_not = re.search(r"Could not (?:override|append to) '([^']+)'", text)
    if missing_key or could_not:
        key = could_not.group(1) if could_not else missing_key.group(1)
        return ConfigError(SOURCE, key, "no such setting (python -m crllk.train --cfg job "
                           "lists them all)")
    parse = re.search(r"Error parsing override '([^']*)'", text)
    if parse:
        return ConfigError(SOURCE, parse.group(1), "cannot parse this override "
                           "(expected key=value)")
    cause = err.__cause__ if isinstance(err.__cause__, OmegaConfBaseException) else err
    key = getattr(cause, "full_key", None) or _first_key(overrides)
    lines = [line.strip() for line in str(cause).splitlines() if line.strip()]
    return ConfigError(SOURCE, str(key), lines[0] if lines else type(err).__name__)


def _first_key(overrides: Sequence[str]) -> str:
    return overrides[0].partition("=")[0] if overrides else "<overrides>"


__all__ = ["LAUNCHER_PLUGINS", "compose_config", "composition_error", "launcher_problems",
           "register", "task_file_problems", "task_paths_as_task_file"]
