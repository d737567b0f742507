"""Real Duckietown map files (``tests/data/real_maps``, see its README): every one loads, a task on
it steps and renders, and its lanes lie where the file's tiles say. Both object formats (a list,
a mapping of named objects), intersections, signs, traffic lights and open roads.

Tile geometry is worked out here from the raw YAML, independently of the map reader: a tile's
centre, the edges it opens to, and its lanes 0.117 m right of the road centre line.
"""

from __future__ import annotations

import functools
import itertools
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

import crllk
from crllk.analysis.pictures import topdown
from crllk.errors import MapError, MapWarning
from crllk.maps import load_map
from crllk.sim.texture import ROAD_RGB
from crllk.tasks.follower import LaneFollower

REAL = Path(__file__).parent / "data" / "real_maps"
FILES = sorted(str(p.relative_to(REAL)) for p in REAL.glob("*/*.yaml"))
NO_ROAD = ("duckietown-world/calibration_map_int.yaml", "duckietown-world/field1.yaml")
LOADABLE = [name for name in FILES if name not in NO_ROAD]
OFFSET = 0.117
"""Lane centre right of the road centre line (m)."""
STRAIGHT = 2
"""The discrete action that drives straight ahead."""

HEADING = {"N": math.pi / 2, "E": 0.0, "S": -math.pi / 2, "W": math.pi}
UNIT = {"N": (0, 1), "E": (1, 0), "S": (0, -1), "W": (-1, 0)}
OPPOSITE = {"N": "S", "S": "N", "E": "W", "W": "E"}
LEFT = {"N": "W", "W": "S", "S": "E", "E": "N"}
RIGHT = {v: k for k, v in LEFT.items()}


@functools.cache
def _raw(name: str) -> dict:
    """The file's YAML (shared: do not modify)."""
    return yaml.safe_load((REAL / name).read_text())


def _road_tiles(name: str) -> list[tuple[int, int, str, str]]:
    """(column, row, kind, orientation) of every road tile, read from the raw YAML; a tile
    without an orientation faces east, as the Duckietown simulator reads it."""
    out = []
    for row, tiles in enumerate(_raw(name)["tiles"]):
        for column, label in enumerate(tiles):
            kind, _, orientation = label.strip().partition("/")
            if kind.strip() in ("straight", "curve_left", "curve_right", "3way_left",
                                "3way_right", "4way"):
                out.append((column, row, kind.strip(), orientation.strip() or "E"))
    return out


def _openings(kind: str, d: str) -> set[str]:
    """Edges an intersection tile opens to: a 3-way is a road along d with a branch."""
    if kind == "4way":
        return {"N", "E", "S", "W"}
    return {d, OPPOSITE[d], (LEFT if kind == "3way_left" else RIGHT)[d]}


def _lane_point(name: str, column: int, row: int, heading: str, ahead: float,
                from_edge: bool = False) -> tuple[float, float, float]:
    """World (x, y, yaw) on the lane of ``heading`` through the tile's centre line,
    ``ahead`` m past the tile centre (or past the entry edge with ``from_edge``)."""
    raw = _raw(name)
    s, rows = raw["tile_size"], len(raw["tiles"])
    hx, hy = UNIT[heading]
    cx, cy = (column + 0.5) * s, (rows - 1 - row + 0.5) * s
    along = ahead - s / 2 if from_edge else ahead
    return (cx + hx * along + hy * OFFSET, cy + hy * along - hx * OFFSET, HEADING[heading])


@pytest.fixture(scope="module")
def maps():
    """Every loadable map, read once."""
    return {name: load_map(REAL / name) for name in LOADABLE}


# ----- loading ----------------------------------------------------------------------------

@pytest.mark.parametrize("name", LOADABLE)
def test_every_real_map_loads(name):
    """Each file loads without a warning, with the file's grid and every road tile."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", MapWarning)
        dmap = load_map(REAL / name)
    raw = _raw(name)
    assert (dmap.rows, dmap.columns) == (len(raw["tiles"]), len(raw["tiles"][0]))
    assert dmap.tile_size == raw["tile_size"]
    road = {(c, r) for c, r, _, _ in _road_tiles(name)}
    assert {(t.column, t.row) for t in dmap.road_tiles} == road
    assert dmap.lanes


@pytest.mark.parametrize("name", NO_ROAD)
def test_maps_without_road_are_refused(name):
    """A map with no road tile is refused, naming the file."""
    path = REAL / name
    with pytest.raises(MapError, match="no drivable tile") as info:
        load_map(path)
    assert str(info.value).startswith(f"{path}: tiles: ")


def test_the_corpus_covers_both_object_formats():
    """Files list their objects as a list and as a mapping of named objects."""
    formats = {type(_raw(name).get("objects")).__name__ for name in LOADABLE}
    assert {"list", "dict"} <= formats


# ----- tasks ------------------------------------------------------------------------------

@pytest.mark.parametrize("name", LOADABLE)
def test_a_task_on_every_real_map_steps_and_renders(name):
    """crllk.load(path) builds a task that resets, steps 30 times driving straight (resetting
    past the end of an open road) and renders a small top-down picture of its road."""
    env = crllk.load(REAL / name, observation="pixels", action="discrete", seed=0,
                     overrides={"horizon": 40})
    try:
        ts = env.reset()
        for _ in range(30):
            ts = env.reset() if ts.last() else env.step(STRAIGHT)
            assert ts.observation["pixels"].shape == (30, 40, 3)
            assert all(np.isfinite(ts.observation[key]) for key in ("cost_lane",
                                                                    "cost_collision"))
        picture = np.asarray(topdown(env.physics, env.task.map, size=(48, 64)))
        assert picture.shape == (48, 64, 3)
        road = np.all(np.abs(picture.astype(int) - ROAD_RGB) < 40, axis=-1)
        assert road.mean() > 0.01
    finally:
        env.physics.free_renderers()


def test_spawns_on_open_roads_and_single_tiles():
    """Every reset finds a start on a map whose roads end: a one-row road, a road that ends at
    both map edges, a lone 4-way tile and a one-tile road."""
    for name in ("gym-duckietown/straight_road.yaml", "duckietown-world/straight_road_down.yaml",
                 "gym-duckietown/regress_4way_drivable.yaml",
                 "duckietown-world/calibration_map_ext.yaml"):
        env = crllk.load(REAL / name, observation="state", action="discrete", seed=3)
        for _ in range(5):
            env.reset()
            x, y, _ = env.physics.pose()
            assert env.task.map.is_road(x, y)
            assert env.task.lane_pose.on_road


def test_a_dead_end_is_a_road_departure():
    """Driving straight east along straight_road's last tile leaves the road at its dead end:
    the episode terminates as off the road."""
    name = "gym-duckietown/straight_road.yaml"
    env = crllk.load(REAL / name, observation="state", action="discrete", seed=0)
    assert env.task.map.dead_ends == ((0, 0, "W"), (35, 0, "E"))
    env.reset()
    env.physics.set_pose(*_lane_point(name, 35, 0, "E", 0.15))  # 0.14 m before the end
    env.physics.forward()
    ts = env.step(STRAIGHT)
    for _ in range(60):
        if ts.last():
            break
        ts = env.step(STRAIGHT)
    assert ts.last() and ts.discount == 0.0
    assert env.task.outcome.termination == "off_road"
    assert ts.observation["cost_collision"] == 1.0
    assert env.physics.pose()[0] > 36 * 0.585 - 0.1


# ----- lanes where the file says ------------------------------------------------------------

@pytest.mark.parametrize("name", LOADABLE)
def test_straight_tiles_have_a_lane_each_way(name, maps):
    """At the centre of every straight tile, 0.117 m right of the centre line in either
    direction along the tile's axis, the lane pose reads 0 offset and 0 heading error
    against a straight lane of that tile."""
    dmap = maps[name]
    for column, row, kind, d in _road_tiles(name):
        if kind != "straight":
            continue
        for heading in (d, OPPOSITE[d]):
            x, y, yaw = _lane_point(name, column, row, heading, 0.0)
            pose = dmap.lane_pose(x, y, yaw)
            assert pose.on_road and pose.tile == (column, row)
            assert abs(pose.lateral) < 1e-9 and abs(pose.heading_error) < 1e-9
            assert pose.lane.turn == 0


INTERSECTION_MAPS = [name for name in LOADABLE
                     if any(kind in ("3way_left", "3way_right", "4way")
                            for _, _, kind, _ in _road_tiles(name))]


@pytest.mark.parametrize("name", INTERSECTION_MAPS)
def test_intersections_have_lanes_through_every_opening(name, maps):
    """On every 3-way and 4-way tile: just past each opening, the incoming lane reads 0 offset
    and heading along the lane; where the road goes straight through, the lane across the tile
    centre is the straight one (0 offset, 0 heading error, no curvature), also 15 cm before and
    after the centre and when the robot is 5 cm off it to either side."""
    dmap = maps[name]
    for column, row, kind, d in _road_tiles(name):
        if kind not in ("3way_left", "3way_right", "4way"):
            continue
        edges = _openings(kind, d)
        assert {e for ln in dmap.tile_lanes(column, row) for e in (ln.entry, ln.exit)} == edges
        for entry in edges:
            heading = OPPOSITE[entry]
            x, y, yaw = _lane_point(name, column, row, heading, 0.01, from_edge=True)
            pose = dmap.lane_pose(x, y, yaw)
            assert pose.on_road and pose.tile == (column, row) and pose.lane.entry == entry
            assert abs(pose.lateral) < 1e-3 and abs(pose.heading_error) < 0.05
            if heading not in edges:
                continue
            for ahead, off in itertools.product((-0.15, 0.0, 0.15), (0.0, -0.05, 0.05)):
                x, y, yaw = _lane_point(name, column, row, heading, ahead)
                hx, hy = UNIT[heading]
                pose = dmap.lane_pose(x + hy * off, y - hx * off, yaw)
                assert (pose.lane.entry, pose.lane.exit, pose.curvature) == (entry, heading, 0)
                assert pose.lateral == pytest.approx(off, abs=1e-9)
                assert abs(pose.heading_error) < 1e-9


@pytest.mark.parametrize("name", LOADABLE)
def test_lanes_join_or_end_at_a_dead_end(name, maps):
    """Each lane continues into a lane of the next tile where it ends, with the same position
    and heading, or ends at one of the map's dead ends."""
    dmap = maps[name]
    for lane in dmap.lanes:
        following = dmap.next_lane(lane)
        if following is None:
            assert (lane.column, lane.row, lane.exit) in dmap.dead_ends
            continue
        x0, y0, h0 = lane.point_at(lane.length)
        x1, y1, h1 = following.point_at(0.0)
        assert math.hypot(x1 - x0, y1 - y0) < 1e-9
        assert abs(math.remainder(h1 - h0, 2 * math.pi)) < 1e-9


def _follow(name: str, start: tuple[float, float, float], steps: int):
    """The scripted lane follower from ``start``: (tiles visited in order, largest lane cost,
    termination)."""
    env = crllk.load(REAL / name, observation="state", action="duty", seed=0,
                     overrides={"horizon": steps})
    dmap = env.task.map
    follower = LaneFollower(dmap, env.task.config.motor)
    env.reset()
    env.physics.set_pose(*start)
    env.physics.forward()
    ts, tiles, worst = None, [], 0.0
    while ts is None or not ts.last():
        ts = env.step(follower.duty(env.physics))
        worst = max(worst, float(ts.observation["cost_lane"]))
        tile = dmap.tile_index(*env.physics.pose()[:2])
        if not tiles or tiles[-1] != tile:
            tiles.append(tile)
    return tiles, worst, env.task.outcome.termination


def test_the_follower_drives_straight_through_intersections():
    """From udem1's top row heading west, the lane follower goes straight through the 3-way
    tile (3, 1), round the corner and straight through the 3-way tile (1, 3), within 5 cm of
    its lane throughout."""
    name = "duckietown-world/udem1.yaml"
    tiles, worst, termination = _follow(name, _lane_point(name, 4, 1, "W", 0.0), 360)
    assert termination is None
    assert tiles[:6] == [(4, 1), (3, 1), (2, 1), (1, 1), (1, 2), (1, 3)]
    assert worst < 0.5  # dm


def test_the_follower_completes_a_turn_begun_on_an_intersection():
    """Started a third of the way along the left turn of udem1's 3-way tile (3, 1) (entering
    from the east, leaving south), the follower keeps to that turn and drives on south."""
    name = "duckietown-world/udem1.yaml"
    dmap = load_map(REAL / name)
    (turn,) = [ln for ln in dmap.tile_lanes(3, 1) if (ln.entry, ln.exit) == ("E", "S")]
    tiles, worst, termination = _follow(name, turn.point_at(turn.length / 3), 200)
    assert termination is None
    assert tiles[:3] == [(3, 1), (3, 2), (3, 3)]
    assert worst < 0.5  # dm


# ----- objects ------------------------------------------------------------------------------

def test_both_object_formats_read_the_same_objects():
    """The two udem1 files (a list and named objects) give the same map; the named-object
    loop_obstacles gives the obstacle_loop task's objects."""
    listed = load_map(REAL / "gym-duckietown/udem1.yaml")
    named = load_map(REAL / "duckietown-world/udem1.yaml")
    assert listed.objects == named.objects and len(named.objects) == 14
    assert load_map(REAL / "duckietown-world/loop_obstacles.yaml").objects == \
        load_map("obstacle_loop").objects


def test_signs_attached_to_tile_corners():
    """robotarium1's 34 signs stand 2 to 5 cm from a tile corner, have the sign post's size,
    and are obstacles; its 59 floor tags are left out."""
    dmap = load_map(REAL / "duckietown-world/robotarium1.yaml")
    s = dmap.tile_size
    assert len(_raw("duckietown-world/robotarium1.yaml")["objects"]) == 93
    assert len(dmap.objects) == 34
    for obj in dmap.objects:
        assert obj.kind.startswith("sign_")
        gaps = sorted(abs(v / s - round(v / s)) * s for v in (obj.x, obj.y))
        assert gaps == pytest.approx([0.035 * s, 0.09 * s])
        assert (obj.length, obj.width, obj.height) == pytest.approx((0.040, 0.051, 0.180))
        assert obj.collidable


def test_a_traffic_light_is_drawn_but_not_an_obstacle():
    """4way's traffic light sits where ``place`` puts it (0.18 m south-west of the centre of
    the middle tile, facing 135 degrees); the scene draws it without a collision box, and it is
    no obstacle ahead."""
    env = crllk.load(REAL / "duckietown-world/4way.yaml", observation="state", seed=0)
    (light,) = env.task.map.objects
    s = env.task.map.tile_size
    assert (light.kind, light.collidable) == ("trafficlight", False)
    assert (light.x, light.y) == pytest.approx((2.5 * s - 0.18, 2.5 * s - 0.18))
    assert light.yaw == pytest.approx(math.radians(135))
    assert len(env.physics._obstacle_geoms) == 0
    assert env.task.obstacles.on_road == ()
