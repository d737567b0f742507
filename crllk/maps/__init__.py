"""Duckietown maps: the map format, exact lane geometry and lane poses."""

from __future__ import annotations

from pathlib import Path

from crllk.errors import MapError, MapWarning
from crllk.maps.format import MapSpec, Tile, parse_map
from crllk.maps.lanes import Lane
from crllk.maps.objects import MapObject
from crllk.maps.road import DuckietownMap, LanePose
from crllk.paths import task_file, task_names
from crllk.yaml_files import read_yaml

__all__ = ["DuckietownMap", "Lane", "LanePose", "MapError", "MapObject", "MapSpec", "MapWarning",
           "Tile", "load_map"]


def load_map(name_or_path: str | Path) -> DuckietownMap:
    """Load a map by task name (``small_loop``, ``zigzag``, ``obstacle_loop``, ...) or from a
    Duckietown map file or task file given by path.

    Unknown map keys are ignored with a :class:`MapWarning` naming them.

    Raises:
        MapError: naming the file and field when the map cannot be built.
    """
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        if not task_file(str(name_or_path)).exists():
            raise MapError(name_or_path, "<name>",
                           f"no such map or task (known: {', '.join(task_names())}; "
                           "or give the path of a map file)")
        path = task_file(str(name_or_path))
    elif not path.exists():
        raise MapError(path, "<file>", "no such file")
    data = read_yaml(path)
    prefix = ""
    if isinstance(data, dict) and "map" in data:
        data, prefix = data["map"], "map."
    return DuckietownMap(parse_map(data, name=path.stem, source=path, field_prefix=prefix))
