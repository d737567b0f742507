"""Whether a finished run was trained as an experiment would train it now.

An experiment reuses its finished runs. When a default changes (a setting adopted on
validation episodes), the runs trained before it no longer are the configuration the tables
name. :func:`stale_settings` composes the trainer configuration a run's command would get now
and compares it with the run's ``config.yaml``, setting by setting:

- settings that do not change what is learned (where files go, threads, progress bars, the
  trainer's own evaluations) are not compared (:data:`NOT_COMPARED`);
- a setting a run's file does not hold was added after the run: it trained as that setting's
  default did then, which is the default now, except for those in :data:`FORMER_DEFAULTS`;
- the encounter settings are compared only where encounter spawns happen: a map with objects
  and ``encounters`` above 0.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from omegaconf import OmegaConf

from crllk.tasks.config import load_task_config
from crllk.yaml_files import read_yaml

NOT_COMPARED = frozenset({
    "run_dir", "resume", "progress", "threads", "workers", "collector", "ray_address",
    "checkpoint_every", "record_every", "viewer", "live", "live_port", "task_file", "eval",
    "total_frames"})
"""Top-level settings that decide where and how a run is watched, not what it learns (the
task itself is compared through ``task.*``), and its budget: a run trained for fewer frames
than an experiment asks for is resumed to them (a longer run keeps its own schedules)."""
FORMER_DEFAULTS: Mapping[str, Any] = {"encounter_curve_weight": 1.0}
"""Settings added since with a value that changed what runs learn: a run without the setting
in its ``config.yaml`` trained as this value."""
ENCOUNTER_SETTINGS = frozenset({"encounter_curve_weight", "encounter_horizon"})
"""Settings without effect where no episode starts before an obstacle."""


def flatten(node: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a.b": value}`` of a nested mapping (lists stay values)."""
    out: dict[str, Any] = {}
    for key, value in node.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, name + "."))
        else:
            out[name] = value
    return out


def meets_obstacles(settings: Mapping[str, Any]) -> bool:
    """Whether a run with these (flat) settings starts episodes before obstacles."""
    return bool(settings.get("task.map.objects")) and float(settings.get("encounters", 0)) > 0


def stale_settings(run_dir: Path, overrides: Sequence[str],
                   task_file: str | None = None) -> list[tuple[str, Any, Any]]:
    """``(setting, as trained, as it would be trained now)`` for each setting in which the
    run in ``run_dir`` differs from a run trained now with ``overrides``. With ``task_file``
    the run's map comes from that file: the composed ``task.*`` (the default task's) is not
    compared, and the file's objects decide whether encounters happen."""
    from crllk.training.compose import compose_config  # Hydra only when checking

    wanted = flatten(OmegaConf.to_container(compose_config(overrides), resolve=True))
    trained = flatten(read_yaml(run_dir / "config.yaml") or {})
    if task_file:
        objects = list(load_task_config(task_file).map.objects)
        trained = {k: v for k, v in trained.items() if not k.startswith("task.")}
        wanted = {k: v for k, v in wanted.items() if not k.startswith("task.")}
        trained["task.map.objects"] = wanted["task.map.objects"] = objects
    return list(_differences(trained, wanted))


def _differences(trained: Mapping[str, Any],
                 wanted: Mapping[str, Any]) -> Iterator[tuple[str, Any, Any]]:
    encounters = meets_obstacles(trained) or meets_obstacles(wanted)
    for name, value in wanted.items():
        if name.split(".", 1)[0] in NOT_COMPARED:
            continue
        if name in ENCOUNTER_SETTINGS and not encounters:
            continue
        if name in trained:
            had = trained[name]
        elif name in FORMER_DEFAULTS:
            had = FORMER_DEFAULTS[name]
        else:
            continue
        if had != value:
            yield name, had, value


def describe(run_dir: Path, differences: Sequence[tuple[str, Any, Any]]) -> str:
    """One line: the run and how its settings differ."""
    return f"{run_dir}: " + ", ".join(f"{name} {had} (now {value})"
                                      for name, had, value in differences)


__all__ = ["FORMER_DEFAULTS", "NOT_COMPARED", "describe", "flatten", "meets_obstacles",
           "stale_settings"]
