"""Lane geometry probes: lane poses, lap lengths, the world frame and right-hand traffic.

Numbers from the design (section 4) and ``reference/duckietown.md``: tile size s = 0.585 m, lane
centres 0.117 m right of the road centre line, left-turn arcs of radius s/2 + 0.117 = 0.4095 m and
right-turn arcs of radius s/2 - 0.117 = 0.1755 m about the tile corner.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from crllk.maps import DuckietownMap, Lane, load_map

S = 0.585
OFFSET = 0.117
R_LEFT = S / 2 + OFFSET  # 0.4095 m
R_RIGHT = S / 2 - OFFSET  # 0.1755 m
QUARTER = math.pi / 2
MAPS = ("small_loop", "zigzag", "obstacle_loop")
FRACTIONS = (0.05, 0.25, 0.5, 0.75, 0.95)
"""Positions along each lane as fractions of its length (clear of the tile edges)."""


@pytest.fixture(scope="module", params=MAPS)
def dmap(request) -> DuckietownMap:
    return load_map(request.param)


@pytest.fixture(scope="module")
def small_loop() -> DuckietownMap:
    return load_map("small_loop")


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _lane(dmap: DuckietownMap, column: int, row: int, heading: float) -> Lane:
    """The lane of a straight tile travelling along ``heading`` (rad)."""
    (lane,) = [ln for ln in dmap.tile_lanes(column, row)
               if abs(_wrap(ln.start_heading - heading)) < 1e-9]
    return lane


# ----- lane poses on every lane --------------------------------------------------------------

def test_lane_centre_reads_zero_offset_and_heading_error(dmap):
    """Every lane centre point reads lateral 0 and heading error 0 against that very lane."""
    assert dmap.lanes
    for lane in dmap.lanes:
        for f in FRACTIONS:
            x, y, heading = lane.point_at(f * lane.length)
            pose = dmap.lane_pose(x, y, heading)
            assert pose.on_road
            assert pose.lane == lane
            assert abs(pose.lateral) < 1e-9
            assert abs(pose.heading_error) < 1e-9
            assert pose.along == pytest.approx(f * lane.length, abs=1e-9)


def test_projection_inverts_point_at_on_every_lane(dmap):
    """A point ``lateral`` (up to 15 cm, inside the tightest arc's radius) right of the centre
    ``along`` a lane projects back to (lateral, along, the lane's heading there), on straights
    and arcs; ``offsets`` and ``along_within`` give the same numbers, the latter None outside
    its band."""
    rng = np.random.default_rng(3)
    for lane in dmap.lanes:
        for along, lateral in zip(rng.uniform(0.0, lane.length, 20), rng.uniform(-0.15, 0.15, 20),
                                  strict=True):
            x, y, heading = lane.point_at(float(along), float(lateral))
            projection = lane.project(x, y)
            assert projection.lateral == pytest.approx(lateral, abs=1e-9)
            assert projection.along == pytest.approx(along, abs=1e-9)
            assert abs(_wrap(projection.heading - heading)) < 1e-9
            assert lane.offsets(x, y) == (projection.lateral, projection.along)
            assert lane.along_within(x, y, abs(lateral) + 1e-6) == projection.along
            assert lane.along_within(x, y, abs(lateral) - 1e-6) is None


def test_offsets_right_positive_left_negative(dmap):
    """0.05 m right of a lane centre reads +0.05, 0.05 m left reads -0.05."""
    for lane in dmap.lanes:
        for f in FRACTIONS:
            for offset in (0.05, -0.05):
                x, y, heading = lane.point_at(f * lane.length, offset)
                pose = dmap.lane_pose(x, y, heading)
                assert pose.lane == lane
                assert pose.lateral == pytest.approx(offset, abs=1e-9)
                assert abs(pose.heading_error) < 1e-9


def test_lanes_join_seamlessly(dmap):
    """Each lane ends where the next begins, with the same heading (no kinks, no gaps)."""
    for lane in dmap.lanes:
        nxt = dmap.next_lane(lane)
        assert nxt is not None, f"lane {lane.entry}->{lane.exit} of {lane.column, lane.row}"
        x0, y0, h0 = lane.point_at(lane.length)
        x1, y1, h1 = nxt.point_at(0.0)
        assert math.hypot(x1 - x0, y1 - y0) < 1e-9
        assert abs(_wrap(h1 - h0)) < 1e-9


def test_curves_are_quarter_circles_about_a_tile_corner(dmap):
    """Arcs through three of their points: radius 0.4095 (left) or 0.1755 (right), centred
    on a corner of their tile, turning the heading by +-90 degrees."""
    arcs = [ln for ln in dmap.lanes if ln.turn != 0]
    assert arcs
    for lane in arcs:
        p = np.array([lane.point_at(f * lane.length)[:2] for f in (0.0, 0.5, 1.0)])
        centre = _circumcentre(*p)
        radius = float(np.linalg.norm(p[0] - centre))
        expected = R_LEFT if lane.turn == 1 else R_RIGHT
        assert radius == pytest.approx(expected, abs=1e-9)
        assert lane.length == pytest.approx(QUARTER * expected, abs=1e-12)
        corners = {((lane.column + a) * S, (dmap.rows - 1 - lane.row + b) * S)
                   for a in (0, 1) for b in (0, 1)}
        assert min(math.dist(centre, c) for c in corners) < 1e-9
        turned = _wrap(lane.point_at(lane.length)[2] - lane.point_at(0.0)[2])
        assert turned == pytest.approx(lane.turn * QUARTER, abs=1e-9)
        # Curvature sign: positive for left turns.
        assert lane.curvature == pytest.approx(lane.turn / expected)


def _circumcentre(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Centre of the circle through three points (solves |p - a|^2 = |p - b|^2 = |p - c|^2)."""
    m = 2 * np.array([b - a, c - a])
    rhs = np.array([b @ b - a @ a, c @ c - a @ a])
    return np.linalg.solve(m, rhs)


# ----- lap lengths ---------------------------------------------------------------------------

def test_small_loop_lap_lengths(small_loop):
    """CCW (intended): 4 straights + 4 left arcs; CW: 4 straights + 4 right arcs."""
    # 4 * 0.585 + 4 * (pi/2) * 0.4095 = 2.34 + 2.5730 = 4.9130 m
    assert small_loop.lap_length("intended") == pytest.approx(4 * S + 4 * QUARTER * R_LEFT,
                                                              rel=1e-3)
    # 4 * 0.585 + 4 * (pi/2) * 0.1755 = 2.34 + 1.1027 = 3.4427 m
    assert small_loop.lap_length("reverse") == pytest.approx(4 * S + 4 * QUARTER * R_RIGHT,
                                                             rel=1e-3)
    assert small_loop.lap_length() == small_loop.lap_length("intended")


def test_obstacle_loop_lap_lengths():
    """Intended (CCW): five left turns and the right turn at curve_right/N (4, 4)."""
    dmap = load_map("obstacle_loop")
    # 12 * 0.585 + (pi/2) * (5 * 0.4095 + 0.1755) = 7.02 + 3.4919 = 10.5119 m
    assert dmap.lap_length("intended") == pytest.approx(
        12 * S + 5 * QUARTER * R_LEFT + QUARTER * R_RIGHT, rel=1e-3)
    # Reverse: the five left curves become right turns and vice versa.
    assert dmap.lap_length("reverse") == pytest.approx(
        12 * S + 5 * QUARTER * R_RIGHT + QUARTER * R_LEFT, rel=1e-3)


def test_zigzag_lap_drives_every_curve_as_named():
    """zigzag: 12 straights, 9 curve_left and 5 curve_right tiles. In the intended direction
    every curve is driven through the turn its orientation names, so the 9 curve_left tiles are
    left arcs (0.4095 m) and the 5 curve_right tiles right arcs (0.1755 m)."""
    dmap = load_map("zigzag")
    kinds = [t.kind for t in dmap.road_tiles]
    assert (kinds.count("straight"), kinds.count("curve_left"), kinds.count("curve_right")) == (
        12, 9, 5)
    # 12 * 0.585 + (pi/2) * (9 * 0.4095 + 5 * 0.1755) = 7.02 + 7.1675 = 14.1875 m
    intended = 12 * S + QUARTER * (9 * R_LEFT + 5 * R_RIGHT)
    assert dmap.lap_length("intended") == pytest.approx(intended, rel=1e-3)
    # 12 * 0.585 + (pi/2) * (5 * 0.4095 + 9 * 0.1755) = 7.02 + 5.6973 = 12.7173 m
    assert dmap.lap_length("reverse") == pytest.approx(
        12 * S + QUARTER * (5 * R_LEFT + 9 * R_RIGHT), rel=1e-3)
    # Follow the loop from the named turn of the first curve_left tile: one lane per road tile,
    # each curve turning the way its kind says.
    first = next(t for t in dmap.road_tiles if t.kind == "curve_left")
    start = next(ln for ln in dmap.tile_lanes(first.column, first.row) if ln.turn == 1)
    loop = dmap.loop(start)
    assert sorted((ln.column, ln.row) for ln in loop) == sorted(
        (t.column, t.row) for t in dmap.road_tiles)
    for lane in loop:
        kind = dmap.tile(lane.column, lane.row).kind
        assert lane.turn == {"straight": 0, "curve_left": 1, "curve_right": -1}[kind]
    assert sum(ln.length for ln in loop) == pytest.approx(intended, rel=1e-9)


def test_lap_length_rejects_unknown_direction(small_loop):
    with pytest.raises(ValueError, match="direction"):
        small_loop.lap_length("sideways")


# ----- world frame ---------------------------------------------------------------------------

def test_tile_index_at_tile_centres_and_corners(dmap):
    """Tile (i, j) covers x in [i*s, (i+1)*s], y in [(R-1-j)*s, (R-j)*s]."""
    R = dmap.rows
    for row in dmap.spec.tiles:
        for t in row:
            i, j = t.column, t.row
            centre = ((i + 0.5) * S, (R - 1 - j + 0.5) * S)
            assert dmap.tile_index(*centre) == (i, j)
            assert dmap.is_road(*centre) == t.drivable
            assert dmap.tile_index(i * S + 1e-6, (R - 1 - j) * S + 1e-6) == (i, j)
            assert dmap.tile_index((i + 1) * S - 1e-6, (R - j) * S - 1e-6) == (i, j)
    assert dmap.tile_index(-1e-6, S / 2) is None
    assert dmap.tile_index(S / 2, R * S + 1e-6) is None
    assert not dmap.is_road(-0.3, -0.3)


def test_known_tiles_in_world_frame(small_loop):
    """Row 0 is the north edge: small_loop's curve_left/W is the north-west corner tile."""
    # 3 rows: tile (0, 0) covers x in [0, 0.585], y in [1.17, 1.755].
    assert small_loop.tile_index(0.29, 1.46) == (0, 0)
    assert small_loop.tile(0, 0).label == "curve_left/W"
    assert small_loop.tile_index(1.46, 0.29) == (2, 2)
    assert small_loop.tile(2, 2).label == "curve_left/E"
    # The centre tile (asphalt) is not road; the straight north of it is.
    assert small_loop.tile(1, 1).kind == "asphalt"
    assert not small_loop.is_road(1.5 * S, 1.5 * S)
    assert small_loop.is_road(1.5 * S, 2.5 * S)
    obstacle = load_map("obstacle_loop")
    # 7 rows: curve_right/N at (4, 4) covers x in [2.34, 2.925], y in [1.17, 1.755].
    assert obstacle.tile_index(2.6, 1.5) == (4, 4)
    assert obstacle.tile(4, 4).label == "curve_right/N"
    assert not obstacle.is_road(0.29, 0.29)  # floor border


def test_objects_in_world_frame():
    """Object pos [x, z] in tile units from the north-west corner: x*s east, (R - z)*s north."""
    dmap = load_map("obstacle_loop")
    duckie, cone = dmap.objects[0], dmap.objects[1]
    # duckie at [3.5, 1.2]: x = 3.5 * 0.585 = 2.0475, y = (7 - 1.2) * 0.585 = 3.393
    assert (duckie.x, duckie.y) == pytest.approx((2.0475, 3.393))
    assert duckie.yaw == pytest.approx(math.radians(10))
    # It stands in the west-bound lane of the top row, 3.393 - (3.2175 + 0.117) = 0.0585 m
    # north of its centre, i.e. to the right when heading west.
    pose = dmap.lane_pose(duckie.x, duckie.y, math.pi)
    assert pose.on_road and pose.tile == (3, 1)
    assert pose.lateral == pytest.approx(0.0585, abs=1e-9)
    # cone at [6.8, 2.5]: in the north-bound lane of the right column, 0.0585 m east (right).
    pose = dmap.lane_pose(cone.x, cone.y, math.pi / 2)
    assert pose.on_road and pose.tile == (6, 2)
    assert pose.lateral == pytest.approx(0.0585, abs=1e-9)


# ----- right-hand traffic, signs, lane choice ------------------------------------------------

def test_right_hand_traffic_on_small_loop_top_row(small_loop):
    """Top row, tile (1, 0): centre (0.8775, 1.4625). West-bound lane 0.117 m north of the
    centre line (right of travel), east-bound 0.117 m south; the CCW lap drives west here."""
    cx, cy = 1.5 * S, 2.5 * S
    west = _lane(small_loop, 1, 0, math.pi)
    east = _lane(small_loop, 1, 0, 0.0)
    assert west.point_at(S / 2)[:2] == pytest.approx((cx, cy + OFFSET), abs=1e-12)
    assert east.point_at(S / 2)[:2] == pytest.approx((cx, cy - OFFSET), abs=1e-12)
    pose = small_loop.lane_pose(cx, cy + OFFSET, math.pi)
    assert pose.lane == west
    assert abs(pose.lateral) < 1e-9 and abs(pose.heading_error) < 1e-9
    assert sum(ln.length for ln in small_loop.loop(west)) == pytest.approx(
        small_loop.lap_length("intended"))
    assert sum(ln.length for ln in small_loop.loop(east)) == pytest.approx(
        small_loop.lap_length("reverse"))


def test_small_loop_turn_radii(small_loop):
    """Each corner has a left-turn lane of 0.4095 m and a right-turn lane of 0.1755 m; the
    intended (CCW) direction drives all four as left turns."""
    for column, row in ((0, 0), (2, 0), (0, 2), (2, 2)):
        lanes = small_loop.tile_lanes(column, row)
        radii = {ln.turn: ln.radius for ln in lanes}
        assert radii == pytest.approx({1: R_LEFT, -1: R_RIGHT})
        curvature = {ln.turn: ln.curvature for ln in lanes}
        assert curvature[1] == pytest.approx(1 / R_LEFT) and curvature[1] > 0
        assert curvature[-1] == pytest.approx(-1 / R_RIGHT)


def test_heading_error_sign(small_loop):
    """yaw = lane heading + 0.1 reads +0.1; - 0.1 reads -0.1; wraps across +-pi."""
    x, y = 1.5 * S, 2.5 * S + OFFSET  # west-bound lane centre, heading pi
    assert small_loop.lane_pose(x, y, math.pi + 0.1).heading_error == pytest.approx(0.1)
    assert small_loop.lane_pose(x, y, math.pi - 0.1).heading_error == pytest.approx(-0.1)
    assert small_loop.lane_pose(x, y, -math.pi + 0.1).heading_error == pytest.approx(0.1)


def test_reversed_yaw_picks_the_opposite_lane(small_loop):
    """On the west-bound lane centre but heading east, the pose is measured against the
    east-bound lane 0.234 m to the south, i.e. 0.234 m left of it: lateral -0.234."""
    x, y = 1.5 * S, 2.5 * S + OFFSET
    pose = small_loop.lane_pose(x, y, 0.0)
    assert pose.lane == _lane(small_loop, 1, 0, 0.0)
    assert pose.lateral == pytest.approx(-2 * OFFSET, abs=1e-9)
    assert abs(pose.heading_error) < 1e-9
    # On the east-bound lane centre heading west: the west-bound lane is 0.234 m north, and
    # north is right when heading west, so the robot is 0.234 m left of it. Right-hand traffic:
    # the oncoming lane always lies to the left.
    pose = small_loop.lane_pose(x, 2.5 * S - OFFSET, math.pi)
    assert pose.lane == _lane(small_loop, 1, 0, math.pi)
    assert pose.lateral == pytest.approx(-2 * OFFSET, abs=1e-9)


def test_reversed_yaw_on_a_curve(small_loop):
    """On the left-turn lane of the north-west corner, the opposite direction is a right turn
    whose centre is 0.4095 - 0.1755 = 0.234 m nearer the corner; lateral reads -0.234 (left)."""
    left = next(ln for ln in small_loop.tile_lanes(0, 0) if ln.turn == 1)
    x, y, heading = left.point_at(left.length / 2)
    pose = small_loop.lane_pose(x, y, heading + math.pi)
    assert pose.lane.turn == -1
    assert pose.lateral == pytest.approx(-(R_LEFT - R_RIGHT), abs=1e-9)
    assert abs(pose.heading_error) < 1e-9


def test_off_road_points(dmap):
    """Off the road (decor tiles and outside the grid): on_road False, finite values."""
    R = dmap.rows
    decor = [t for row in dmap.spec.tiles for t in row if not t.drivable]
    points = [((t.column + 0.5) * S, (R - 1 - t.row + 0.5) * S) for t in decor]
    points += [(-0.3, -0.3), (dmap.width + 1.0, dmap.height / 2), (dmap.width / 2, -2.0)]
    for x, y in points:
        for yaw in (0.0, 2.0, -2.5):
            pose = dmap.lane_pose(x, y, yaw)
            assert not pose.on_road
            assert math.isfinite(pose.lateral) and math.isfinite(pose.heading_error)
            assert -math.pi <= pose.heading_error < math.pi


# ----- curvature ahead and lane following ----------------------------------------------------

def test_curvature_ahead_on_small_loop(small_loop):
    """From the middle of the top straight heading west (along = 0.2925):
    0.1 m ahead is still straight (0.3925 < 0.585), 0.5 m ahead is 0.2075 m into the
    north-west left curve (arc 0.643 m), 1.5 m ahead is on the west straight
    (1.7925 - 0.585 - 0.6432 = 0.5643 < 0.585)."""
    pose = small_loop.lane_pose(1.5 * S, 2.5 * S + OFFSET, math.pi)
    assert pose.along == pytest.approx(S / 2)
    assert small_loop.curvature_ahead(pose, (0.1, 0.5, 1.5)) == pytest.approx(
        [0.0, 1 / R_LEFT, 0.0])
    # Heading east, the next corner is driven as a right turn.
    pose = small_loop.lane_pose(1.5 * S, 2.5 * S - OFFSET, 0.0)
    assert small_loop.curvature_ahead(pose, (0.1, 0.5)) == pytest.approx([0.0, -1 / R_RIGHT])


def test_next_lane_goes_round_the_loop(small_loop):
    """Following next_lane from any lane returns to it after 8 tiles, visiting each once."""
    for lane in small_loop.lanes:
        seen, current = [], lane
        for _ in range(8):
            seen.append((current.column, current.row))
            current = small_loop.next_lane(current)
        assert current == lane
        assert len(set(seen)) == 8
