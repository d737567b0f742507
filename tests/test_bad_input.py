"""Bad map and task files: each gives one clear error naming the file, the field and the problem.

Design section 8: a malformed task or map file, an unknown tile or object kind, a road that does
not connect, an object off the map or a map beyond the size limits gives one message
``<file>: <field>: <problem>``.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from crllk.errors import ConfigError, MapError, MapWarning
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
    ("too_many_tiles", _map_text([str(["asphalt"] * 40)] * 40), "tiles",
     ["40 x 40 (rows x columns), 1600 tiles", "more than the 1024"]),
    ("too_long_a_side", _map_text([str(["straight/E"] * 65)]), "tiles",
     ["1 x 65 (rows x columns)", "at most 64 rows and 64 columns"]),
    ("too_many_objects", _map_text(extra="objects:\n" + "  - {kind: duckie, pos: [1, 1]}\n" * 1001),
     "objects", ["1001 objects", "more than the 1000"]),
    ("objects_neither_list_nor_mapping", _map_text(extra="objects: 7\n"), "objects",
     ["expected a list of objects or a mapping of named objects"]),
    ("named_object_unknown_kind", _map_text(extra="objects:\n  d1: {kind: dragon, pos: [1, 1]}\n"),
     "objects.d1.kind", ["unknown object kind", "dragon"]),
    ("place_tile_off_the_map",
     _map_text(extra="objects:\n  b: {kind: bus, place: {tile: [3, 0], relative: {}}}\n"),
     "objects.b.place.tile", ["[3, 0] is off the map"]),
    ("attach_bad_slot",
     _map_text(extra="objects:\n  s: {kind: sign_stop, attach: {tile: [1, 1], slot: 8}}\n"),
     "objects.s.attach.slot", ["expected a slot number 0 to 7, got 8"]),
    ("pose_off_the_map",
     _map_text(extra="objects:\n  t: {kind: tree, pose: {~SE2Transform: {p: [-1, 0]}}}\n"),
     "objects.t", ["off the map"]),
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
        "curve_right, 3way_left, 3way_right, 4way, asphalt, floor, grass, calibration_tile, "
        "empty)"]


def test_unknown_map_keys_are_ignored_with_one_warning(tmp_path):
    """Unknown top-level keys load with one single-line warning naming them; the Duckietown
    keys start_tile, start_pose and version load without one."""
    path = tmp_path / "extra_keys.yaml"
    path.write_text(_map_text(extra="tile_colour: red\n7: seven\nversion: 2\n"
                                    "start_tile: [0, 1]\nstart_pose: [[0.48, 0, 0.29], 0]\n"))
    with pytest.warns(MapWarning) as record:
        dmap = load_map(path)
    assert len(dmap.road_tiles) == 8
    assert [str(w.message) for w in record] == [
        f"{path}: tile_colour, 7: unknown map keys, ignored"]


def test_file_too_large_is_refused_before_parsing(tmp_path):
    """A file over the size limit is refused without reading its YAML."""
    path = tmp_path / "huge.yaml"
    path.write_text(_map_text() + "objects:\n" + "  - {kind: duckie, pos: [1, 1]}\n" * 20000)
    with pytest.raises(MapError, match=r"huge\.yaml: <file>: \d+ bytes, more than the 524288"):
        load_map(path)


def test_dead_ends_load(tmp_path):
    """A road that opens off the map or onto a tile that is not road is a dead end: the map
    loads and lists it (the robot leaves the road there)."""
    off_the_map = tmp_path / "two_straights.yaml"
    off_the_map.write_text(_map_text(["[straight/E, straight/E]"]))
    assert load_map(off_the_map).dead_ends == ((0, 0, "W"), (1, 0, "E"))
    onto_asphalt = tmp_path / "onto_asphalt.yaml"
    onto_asphalt.write_text(_map_text(_replace(0, "curve_left/N", "asphalt")))
    assert load_map(onto_asphalt).dead_ends == ((1, 0, "E"), (2, 1, "N"))


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
    ("name_climbs_out", "name: ../../x\n", "name", ["not a task name", "'../../x'"]),
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


@pytest.mark.parametrize("name", ["../../x", "a/b", ".hidden"])
def test_a_task_name_never_leaves_the_tasks_folder(name):
    """A name (from the command line or a shared run's ``config.yaml``) is never joined into
    a path: it becomes a file and folder name, so only plain names are taken."""
    with pytest.raises(ConfigError, match="not a task name") as info:
        load_task_config(name)
    assert str(info.value).startswith(f"{name}: task: ")
    with pytest.raises(ConfigError, match="not a task name"):
        load_map(name)


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
