"""Bad map and task files: each gives one clear error naming the file, the field and the problem.

Design section 8: a malformed task or map file, an unknown tile or object kind, a road that does
not connect or an object off the map gives one message ``<file>: <field>: <problem>``.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from crllk.errors import ConfigError, MapError
from crllk.maps import load_map
from crllk.tasks.config import load_task_config

DATA = Path(__file__).parent / "data"
S = 0.585
QUARTER = math.pi / 2

LOOP = ["[curve_left/W, straight/W, curve_left/N]",
        "[straight/S,   asphalt,    straight/N]",
        "[curve_left/S, straight/E, curve_left/E]"]
"""small_loop's rows, as YAML flow lists."""


def _map_text(rows: list[str] = LOOP, tile_size: str | None = "0.585", extra: str = "",
              indent: str = "") -> str:
    lines = [] if tile_size is None else [f"tile_size: {tile_size}"]
    lines += ["tiles:", *(f"  - {row}" for row in rows)]
    return "".join(f"{indent}{line}\n" for line in lines) + extra


def _task_text(settings: str) -> str:
    return "map:\n" + _map_text(indent="  ") + settings


def _replace(row: int, old: str, new: str) -> list[str]:
    rows = list(LOOP)
    rows[row] = rows[row].replace(old, new, 1)
    return rows


# (case id, file text, field named, words of the problem)
MAP_CASES = [
    ("unknown_tile_kind", _map_text(_replace(0, "straight/W", "bridge/W")),
     "tiles[0][1]", ["unknown tile kind", "bridge"]),
    ("bad_orientation", _map_text(_replace(0, "straight/W", "straight/Q")),
     "tiles[0][1]", ["bad orientation", "straight/Q"]),
    ("curve_without_orientation", _map_text(_replace(2, "curve_left/E", "curve_left")),
     "tiles[2][2]", ["bad orientation"]),
    ("ragged_rows", _map_text(_replace(1, "asphalt,", "")),
     "tiles[1]", ["ragged", "2 tiles", "row 0 has 3"]),
    # Top-right corner replaced by asphalt: the top straight (row 0, column 1) opens east onto it.
    ("road_onto_asphalt", _map_text(_replace(0, "curve_left/N", "asphalt")),
     "tiles[0][1]", ["opens to the E onto 'asphalt'", "does not connect"]),
    # One row of two east-west straights: the west one opens off the west edge of the map.
    ("road_off_the_map", _map_text(["[straight/E, straight/E]"]),
     "tiles[0][0]", ["opens to the W off the edge of the map", "does not connect"]),
    ("road_onto_road_not_opening_back", _map_text(_replace(2, "straight/E", "straight/N")),
     "tiles[2][0]", ["onto 'straight/N'", "does not open back"]),
    ("no_road_at_all", _map_text(["[asphalt, floor]", "[grass, empty]"]),
     "tiles", ["no drivable tile"]),
    ("object_off_the_map", _map_text(extra="objects:\n  - {kind: duckie, pos: [3.5, 1.0]}\n"),
     "objects[0].pos", ["off the map", "[3.5, 1.0]"]),
    ("object_negative_pos", _map_text(extra="objects:\n  - {kind: cone, pos: [1.5, -0.2]}\n"),
     "objects[0].pos", ["off the map"]),
    ("unknown_object_kind", _map_text(extra="objects:\n  - {kind: dragon, pos: [1.5, 1.5]}\n"),
     "objects[0].kind", ["unknown object kind", "dragon"]),
    ("object_kind_not_a_string",
     _map_text(extra="objects:\n  - {kind: [duckie], pos: [1.5, 1.5]}\n"),
     "objects[0].kind", ["unknown object kind"]),
    ("object_without_pos", _map_text(extra="objects:\n  - {kind: duckie}\n"),
     "objects[0].pos", ["expected [x, z]"]),
    ("object_rotate_infinite",
     _map_text(extra="objects:\n  - {kind: cone, pos: [1.5, 1.5], rotate: .inf}\n"),
     "objects[0].rotate", ["expected degrees"]),
    ("missing_tile_size", _map_text(tile_size=None), "tile_size", ["missing"]),
    ("zero_tile_size", _map_text(tile_size="0"), "tile_size", ["positive", "got 0"]),
    ("negative_tile_size", _map_text(tile_size="-0.585"), "tile_size", ["positive"]),
    ("text_tile_size", _map_text(tile_size="big"), "tile_size", ["expected a number"]),
    ("missing_tiles", "tile_size: 0.585\n", "tiles", ["missing"]),
    ("unknown_map_key", _map_text(extra="tile_colour: red\n"), "tile_colour", ["unknown key"]),
    ("unknown_keys_of_mixed_types", _map_text(extra="tile_colour: red\n7: seven\n"),
     "7", ["unknown key"]),
    ("yaml_syntax", _map_text(extra="objects: [{kind: duckie, pos: [1.5, 1.5]\n"),
     "line", ["not valid YAML"]),
    ("not_a_mapping", "- just\n- a list\n", "<top>", ["expected a mapping"]),
]


@pytest.mark.parametrize("text, field, words", [c[1:] for c in MAP_CASES],
                         ids=[c[0] for c in MAP_CASES])
def test_bad_map_file(tmp_path, text, field, words):
    """load_map raises one single-line MapError: '<file>: <field>: <problem>'."""
    path = tmp_path / "bad_map.yaml"
    path.write_text(text)
    with pytest.raises(MapError) as info:
        load_map(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {field}")
    assert info.value.source == str(path)
    for word in words:
        assert word in message
    assert "\n" not in message


def test_unknown_tile_kind_message_is_one_line(tmp_path):
    """The whole message, with the list of known kinds, fits on one line."""
    path = tmp_path / "bridge.yaml"
    path.write_text(_map_text(_replace(1, "asphalt", "bridge")))
    with pytest.raises(MapError) as info:
        load_map(path)
    assert str(info.value).splitlines() == [
        f"{path}: tiles[1][1]: unknown tile kind 'bridge' (known: straight, curve_left, "
        "curve_right, 3way_left, 3way_right, 4way, asphalt, floor, grass, empty)"]


TASK_CASES = [
    ("unknown_setting", "horizn: 100\n", "horizn", ["unknown setting"]),
    ("unknown_section_key", "motor:\n  top_speed: 2.0\n", "motor.top_speed",
     ["unknown setting"]),
    ("horizon_not_a_number", 'horizon: "ten"\n', "horizon", ["expected a whole number", "ten"]),
    ("horizon_fractional", "horizon: 10.5\n", "horizon", ["expected a whole number"]),
    ("horizon_zero", "horizon: 0\n", "horizon", ["must be positive"]),
    ("control_rate_text", "control_rate: fast\n", "control_rate", ["expected a number"]),
    ("spawn_low_above_high", "spawn:\n  lateral_offset: [0.05, -0.05]\n",
     "spawn.lateral_offset", ["low 0.05 is above high -0.05"]),
    ("spawn_range_not_a_pair", "spawn:\n  heading_error: 0.25\n", "spawn.heading_error",
     ["expected [low, high]"]),
    ("negative_delay", "motor:\n  delay: -0.1\n", "motor.delay", ["non-negative"]),
    ("section_not_a_mapping", "camera: 40\n", "camera", ["expected a mapping"]),
    ("yaml_syntax", "horizon: [512\n", "line", ["not valid YAML"]),
]


@pytest.mark.parametrize("settings, field, words", [c[1:] for c in TASK_CASES],
                         ids=[c[0] for c in TASK_CASES])
def test_bad_task_file(tmp_path, settings, field, words):
    """load_task_config raises one single-line ConfigError naming the file and the field."""
    path = tmp_path / "bad_task.yaml"
    path.write_text(_task_text(settings))
    with pytest.raises(ConfigError) as info:
        load_task_config(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {field}")
    for word in words:
        assert word in message
    assert "\n" not in message


def test_bad_map_inside_a_task_file(tmp_path):
    """A task file's broken map is a MapError naming the task file and the map's field."""
    path = tmp_path / "task_with_bad_map.yaml"
    path.write_text("map:\n" + _map_text(_replace(0, "straight/W", "straight/Q"), indent="  ")
                    + "horizon: 64\n")
    with pytest.raises(MapError, match="bad orientation") as info:
        load_task_config(path)
    assert str(info.value).startswith(f"{path}: map.tiles[0][1]")


def test_unknown_task_name():
    """An unknown task name is a ConfigError that names it and lists the known tasks."""
    with pytest.raises(ConfigError) as info:
        load_task_config("no_such_task")
    message = str(info.value)
    assert message.startswith("no_such_task: ")
    assert "unknown task" in message and "small_loop" in message
    with pytest.raises(MapError, match="no such map or task"):
        load_map("no_such_task")


def test_missing_file(tmp_path):
    """A path that does not exist is named as such."""
    path = tmp_path / "absent.yaml"
    with pytest.raises(MapError, match="no such file") as info:
        load_map(path)
    assert str(path) in str(info.value)
    with pytest.raises(ConfigError, match="no such file"):
        load_task_config(path)


# ----- valid custom files ----------------------------------------------------------------------

def test_custom_clockwise_loop_loads_by_path():
    """small_loop_cw: every corner is curve_right, so the intended direction is clockwise and
    drives each corner as a right turn on the inner lane: 4 * 0.585 + 4 * (pi/2) * 0.1755
    = 3.4427 m; the reverse (counter-clockwise) lap takes the outer 0.4095 m arcs: 4.9130 m."""
    dmap = load_map(DATA / "small_loop_cw.yaml")
    assert dmap.name == "small_loop_cw"
    assert (dmap.rows, dmap.columns, len(dmap.road_tiles)) == (3, 3, 8)
    assert dmap.lap_length("intended") == pytest.approx(4 * S + 4 * QUARTER * 0.1755, rel=1e-3)
    assert dmap.lap_length("reverse") == pytest.approx(4 * S + 4 * QUARTER * 0.4095, rel=1e-3)
    # Clockwise on the top row means heading east; right-hand traffic puts that lane 0.117 m
    # south of the centre line (y = 2.5 * 0.585 - 0.117 = 1.3455).
    pose = dmap.lane_pose(1.5 * S, 2.5 * S - 0.117, 0.0)
    assert pose.on_road and abs(pose.lateral) < 1e-9
    assert sum(ln.length for ln in dmap.loop(pose.lane)) == pytest.approx(
        dmap.lap_length("intended"))


def test_bare_map_file_is_a_task_with_defaults():
    """A map file given to load_task_config is a task named after the file, default settings."""
    config = load_task_config(DATA / "small_loop_cw.yaml")
    assert config.name == "small_loop_cw"
    assert config.horizon == 512 and config.control_rate == 30.0
    assert config.map.lap_length() == pytest.approx(4 * S + 4 * QUARTER * 0.1755, rel=1e-3)


def test_valid_task_file_with_settings(tmp_path):
    """A custom task file's settings are read and checked, unset ones keep their defaults."""
    path = tmp_path / "my_task.yaml"
    path.write_text(_task_text("horizon: 64\nspawn:\n  lateral_offset: [-0.02, 0.03]\n"
                               "motor:\n  delay: 0.0\n"))
    config = load_task_config(path)
    assert config.name == "my_task"
    assert config.horizon == 64
    assert config.spawn.lateral_offset == (-0.02, 0.03)
    assert config.spawn.heading_error == (-0.25, 0.25)
    assert config.motor.delay == 0.0 and config.motor.max_speed == 0.6


def test_control_rate_must_divide_the_physics_rate():
    """A control rate that is no whole fraction of 240 Hz is refused naming the field."""
    from crllk.errors import ConfigError
    from crllk.tasks.config import load_task_config

    with pytest.raises(ConfigError, match=r"small_loop\.yaml: control_rate: 7 Hz does not divide"):
        load_task_config("small_loop", {"control_rate": 7})
    assert load_task_config("small_loop", {"control_rate": 15}).control_rate == 15
