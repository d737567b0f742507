"""Probes that the drawn, rendered and collidable geometry sits where the spec says.

Appearance numbers from ``reference/duckietown.md``: white edge tape 4.8 cm wide, 1.5-6.3 cm from
the tile edge (centre 0.039 m from it); yellow centre tape 2.4 cm wide in 5 cm dashes with 2.5 cm
gaps; colours road (75, 72, 69), white (238, 238, 238), yellow (238, 225, 77), asphalt
(62, 58, 51), floor (149, 154, 82), grass (93, 129, 44). The robot's collision footprint is
0.18 m long and 0.15 m wide, centred 0.024 m behind the axle.
"""

from __future__ import annotations

import colorsys
import itertools
import math

import numpy as np
import pytest

from crllk.maps import DuckietownMap, Lane, load_map
from crllk.sim.physics import Physics
from crllk.sim.scene import compile_scene, export_scene
from crllk.sim.texture import render_texture, world_to_texel

S = 0.585
ROAD, WHITE, YELLOW = (75, 72, 69), (238, 238, 238), (238, 225, 77)
DECOR = {"asphalt": (62, 58, 51), "floor": (149, 154, 82), "grass": (93, 129, 44)}
# Offsets right of a lane centre (m). The lane centre is 0.2925 - 0.117 = 0.1755 m from the
# tile edge on its right, so the white tape centre (0.039 m from the edge) is 0.1365 m right of
# it and the yellow centre line 0.117 m left of it. Probes keep 6 mm or more from the band edges
# (one texel is 4.6 mm): white at 0.021, 0.039 and 0.057 m from the edge (tape 0.015-0.063),
# grey at 0.0075 m (the bare strip outside the tape) and 0.071 m (inside the lane); grey 0.02 m
# either side of the centre line (tape half width 0.012).
LANE_TO_EDGE = 0.1755
WHITE_TAPE = LANE_TO_EDGE - 0.039
WHITE_PROBES = tuple(LANE_TO_EDGE - d for d in (0.021, 0.039, 0.057))
GREY_PROBES = (0.0, *(LANE_TO_EDGE - d for d in (0.0075, 0.071)), -0.097, -0.137)
CENTRE_LINE = -0.117
FRACTIONS = (0.1, 0.3, 0.5, 0.7, 0.9)
MAPS = ("small_loop", "zigzag", "obstacle_loop")
FOOTPRINT_LENGTH, FOOTPRINT_WIDTH, FOOTPRINT_BEHIND_AXLE = 0.18, 0.15, 0.024
IMAGE_H, IMAGE_W = 240, 320


# ----- colour helpers ------------------------------------------------------------------------

def _hsv(rgb) -> tuple[float, float, float]:
    """OpenCV-style HSV: H in 0-180, S and V in 0-255."""
    h, s, v = colorsys.rgb_to_hsv(*(float(c) / 255 for c in rgb))
    return h * 180, s * 255, v * 255


def _is_white(rgb) -> bool:
    """The real robot's white line range: [0, 0, 150]-[180, 100, 255]."""
    _, s, v = _hsv(rgb)
    return s <= 100 and v >= 150


def _is_yellow(rgb) -> bool:
    """The real robot's yellow line range: [15, 80, 50]-[45, 255, 255]."""
    h, s, v = _hsv(rgb)
    return 15 <= h <= 45 and s >= 80 and v >= 50


def _is_grey(rgb) -> bool:
    """Road grey: unsaturated, mid-dark, neither line colour."""
    _, s, v = _hsv(rgb)
    return not _is_white(rgb) and not _is_yellow(rgb) and s < 80 and 40 <= v < 150


def _close(rgb, expected, tol: int = 8) -> bool:
    return int(np.abs(np.asarray(rgb, int) - np.asarray(expected)).max()) <= tol


# ----- texture probes ------------------------------------------------------------------------

@pytest.fixture(scope="module", params=MAPS)
def textured(request) -> tuple[DuckietownMap, np.ndarray]:
    dmap = load_map(request.param)
    return dmap, render_texture(dmap)


def _texel(dmap: DuckietownMap, texture: np.ndarray, x: float, y: float) -> np.ndarray:
    return texture[world_to_texel(dmap, x, y)]


def test_texture_size_and_orientation(textured):
    """128 texels per tile; row 0 is the north edge, column 0 the west edge."""
    dmap, texture = textured
    assert texture.shape == (dmap.rows * 128, dmap.columns * 128, 3)
    assert texture.dtype == np.uint8
    assert world_to_texel(dmap, 1e-6, dmap.height - 1e-6) == (0, 0)
    assert world_to_texel(dmap, dmap.width - 1e-6, 1e-6) == (dmap.rows * 128 - 1,
                                                             dmap.columns * 128 - 1)


def test_markings_beside_every_lane(textured):
    """Along every lane (straights and arcs alike): white across the 4.8 cm tape 1.5-6.3 cm
    from the tile edge, grey on either side of it, at the lane centre and beside the yellow."""
    dmap, texture = textured
    for lane in dmap.lanes:
        for f in FRACTIONS:
            along = f * lane.length
            where = f"lane {lane.entry}->{lane.exit} of tile {lane.column, lane.row} at {f}"
            for lateral in WHITE_PROBES:
                rgb = _texel(dmap, texture, *lane.point_at(along, lateral)[:2])
                assert _close(rgb, WHITE), (where, lateral)
            for lateral in GREY_PROBES:
                rgb = _texel(dmap, texture, *lane.point_at(along, lateral)[:2])
                assert _close(rgb, ROAD), (where, lateral)


def _centre_line(dmap: DuckietownMap, texture: np.ndarray, lane: Lane) -> np.ndarray:
    """Yellow-or-not of the texels under the road centre line, every 1 mm along ``lane``."""
    alongs = np.arange(0.0, lane.length, 0.001)
    texels = [_texel(dmap, texture, *lane.point_at(a, CENTRE_LINE)[:2]) for a in alongs]
    for rgb in texels:
        assert _is_yellow(rgb) or _is_grey(rgb), rgb
    return np.array([_is_yellow(rgb) for rgb in texels])


def test_centre_line_is_dashed_yellow(textured):
    """Dashes 5 cm on, 2.5 cm off: about 2/3 of the centre line is yellow on every tile, and
    the yellow texels there match the spec's yellow."""
    dmap, texture = textured
    for column, row in {(ln.column, ln.row) for ln in dmap.lanes}:
        lane = dmap.tile_lanes(column, row)[0]
        yellow = _centre_line(dmap, texture, lane)
        # 0.05 / (0.05 + 0.025) = 0.667; partly covered texels at the dash ends add a little.
        assert 0.55 < yellow.mean() < 0.8, (column, row, yellow.mean())
        start, length = max(((a, n) for a, n, on in _runs(yellow) if on), key=lambda r: r[1])
        x, y, _ = lane.point_at((start + length / 2) / 1000, CENTRE_LINE)  # mid-dash
        assert _close(_texel(dmap, texture, x, y), YELLOW, tol=12)


def _runs(flags: np.ndarray) -> list[tuple[int, int, bool]]:
    """(start, length, value) of each run of equal values."""
    edges = [0, *(np.flatnonzero(np.diff(flags.astype(int))) + 1), len(flags)]
    return [(a, b - a, bool(flags[a])) for a, b in itertools.pairwise(edges)]


def test_dash_and_gap_lengths_on_a_straight():
    """Interior runs along the centre line of a straight: dashes ~5 cm, gaps ~2.5 cm."""
    dmap = load_map("small_loop")
    texture = render_texture(dmap)
    lane = dmap.tile_lanes(1, 0)[0]
    yellow = _centre_line(dmap, texture, lane)
    interior = _runs(yellow)[1:-1]  # the first and last runs are cut by the tile edges
    dashes = np.array([n for _, n, on in interior if on])  # lengths in mm
    gaps = np.array([n for _, n, on in interior if not on])
    assert len(dashes) >= 5 and len(gaps) >= 5
    # One texel is 585 / 128 = 4.6 mm; partly yellow texels lengthen dashes by up to a texel.
    assert np.all(np.abs(dashes - 50) <= 10), dashes
    assert np.all(np.abs(gaps - 25) <= 10), gaps
    assert np.mean(dashes) + np.mean(gaps) == pytest.approx(75, abs=2)


def test_curve_arcs_about_the_corner():
    """small_loop's north-west curve_left/W joins the east and south edges, so its arcs are
    centred on the tile's south-east corner (0.585, 1.17): white at r = 0.039 and
    r = 0.585 - 0.039 = 0.546, grey at the lane centres r = 0.1755 and 0.4095."""
    dmap = load_map("small_loop")
    texture = render_texture(dmap)
    corner = (S, 2 * S)
    for angle in np.linspace(math.pi / 2 + 0.1, math.pi - 0.1, 9):
        def at(r, angle=angle):
            return _texel(dmap, texture, corner[0] + r * math.cos(angle),
                          corner[1] + r * math.sin(angle))
        assert _close(at(0.039), WHITE) and _close(at(S - 0.039), WHITE)
        assert _close(at(0.1755), ROAD) and _close(at(0.4095), ROAD)
        assert _is_yellow(at(S / 2)) or _is_grey(at(S / 2))


def test_decor_tiles_have_their_colours(tmp_path):
    """Every texel of a decor tile has the tile kind's colour; asphalt differs from road."""
    cases = [(load_map("small_loop"), (1, 1), "asphalt"),
             (load_map("zigzag"), (0, 0), "asphalt"),
             (load_map("obstacle_loop"), (3, 3), "floor")]
    path = tmp_path / "grass_loop.yaml"
    path.write_text("tile_size: 0.585\ntiles:\n"
                    "- [curve_left/W, straight/W, curve_left/N]\n"
                    "- [straight/S, grass, straight/N]\n"
                    "- [curve_left/S, straight/E, curve_left/E]\n")
    cases.append((load_map(path), (1, 1), "grass"))
    for dmap, (column, row), kind in cases:
        assert dmap.tile(column, row).kind == kind
        block = render_texture(dmap)[row * 128:(row + 1) * 128, column * 128:(column + 1) * 128]
        assert np.all(block == DECOR[kind]), (dmap.name, kind)
    assert np.abs(np.subtract(DECOR["asphalt"], ROAD)).sum() > 30


# ----- rendered probes (overhead orthographic camera) ----------------------------------------

@pytest.fixture(scope="module")
def small_loop_physics():
    physics = Physics.from_map(load_map("small_loop"))
    physics.set_pose(-0.5, -0.5, 0.0)  # out of the overhead camera's view
    physics.forward()
    yield physics
    physics.free_renderers()


def _pixel(dmap: DuckietownMap, x: float, y: float) -> tuple[int, int]:
    """(row, column) of the overhead image pixel over a world point.

    The camera looks straight down from above the map centre; orthographic with a vertical
    extent fovy = max(map height, map width * 3/4) metres and the same metres per pixel
    horizontally. small_loop: fovy = max(1.755, 1.316) = 1.755 m, 7.3 mm per pixel at 240 rows,
    so the 320 columns span 2.34 m, x from -0.2925 to 2.0475.
    """
    fovy = max(dmap.height, dmap.width * 3 / 4)
    metres_per_pixel = fovy / IMAGE_H
    column = (x - dmap.width / 2) / metres_per_pixel + IMAGE_W / 2
    row = (dmap.height / 2 - y) / metres_per_pixel + IMAGE_H / 2
    return math.floor(row), math.floor(column)


def test_overhead_shows_lanes_and_tape_where_they_are(small_loop_physics):
    """Lane centres render grey, the white tape bright white, for every lane of small_loop."""
    dmap = load_map("small_loop")
    image = small_loop_physics.render_camera(IMAGE_H, IMAGE_W, camera="overhead")
    assert image.shape == (IMAGE_H, IMAGE_W, 3)
    for lane in dmap.lanes:
        for f in FRACTIONS:
            along = f * lane.length
            assert _is_grey(image[_pixel(dmap, *lane.point_at(along)[:2])])
            assert _is_white(image[_pixel(dmap, *lane.point_at(along, WHITE_TAPE)[:2])])


def test_overhead_shows_dark_ground_off_the_road(small_loop_physics):
    """The centre asphalt tile and the ground beyond the map's west edge render dark."""
    dmap = load_map("small_loop")
    image = small_loop_physics.render_camera(IMAGE_H, IMAGE_W, camera="overhead")
    for x, y in ((1.5 * S, 1.5 * S), (1.3 * S, 1.7 * S), (-0.2, 1.5 * S), (-0.2, 0.3)):
        rgb = image[_pixel(dmap, x, y)]
        assert not _is_white(rgb) and not _is_yellow(rgb)
        assert max(rgb) < 110, (x, y, rgb)
    road = image[_pixel(dmap, *dmap.tile_lanes(1, 0)[0].point_at(S / 2)[:2])]
    asphalt = image[_pixel(dmap, 1.5 * S, 1.5 * S)]
    assert np.abs(road.astype(int) - asphalt).sum() > 20  # decor looks different from road


def test_overhead_shows_the_robot_at_its_pose(small_loop_physics):
    """The robot covers the road where set_pose puts it, and only there."""
    dmap = load_map("small_loop")
    lane = dmap.tile_lanes(1, 2)[0]
    x, y, heading = lane.point_at(S / 2)
    pixel = _pixel(dmap, x - 0.02 * math.cos(heading), y - 0.02 * math.sin(heading))
    small_loop_physics.set_pose(x, y, heading)
    small_loop_physics.forward()
    with_robot = small_loop_physics.render_camera(IMAGE_H, IMAGE_W, camera="overhead")
    small_loop_physics.set_pose(-0.5, -0.5, 0.0)
    small_loop_physics.forward()
    without = small_loop_physics.render_camera(IMAGE_H, IMAGE_W, camera="overhead")
    assert _is_grey(without[pixel]) and not _close(with_robot[pixel], without[pixel], tol=30)
    changed = np.argwhere(np.abs(with_robot.astype(int) - without).max(axis=2) > 30)
    # The robot is about 0.18 m x 0.15 m (25 x 21 pixels): all change within 0.15 m of it.
    assert len(changed) > 50
    assert np.abs(changed - pixel).max() * (dmap.height / IMAGE_H) < 0.15


def test_overhead_shows_obstacles_where_they_stand():
    """On obstacle_loop, each obstacle covers the floor or road texture at its position."""
    dmap = load_map("obstacle_loop")
    physics = Physics.from_map(dmap)
    try:
        physics.set_pose(-1.0, -1.0, 0.0)
        physics.forward()
        image = physics.render_camera(IMAGE_H, IMAGE_W, camera="overhead")
        texture = render_texture(dmap)
        for obj in dmap.objects:
            rgb = image[_pixel(dmap, obj.x, obj.y)]
            assert not _close(rgb, _texel(dmap, texture, obj.x, obj.y), tol=40), obj.kind
    finally:
        physics.free_renderers()


# ----- collision probes ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def obstacle_physics() -> Physics:
    return Physics.from_map(load_map("obstacle_loop"))


def _corners(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    """Corners (4, 2) of a rectangle centred at (x, y), its length along ``yaw``."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * (length / 2, width / 2)
    return np.array([x, y]) + local @ np.array([[c, s], [-s, c]])


def _separation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest gap (m) between two rectangles' projections on their edge normals; negative
    means they overlap (by at least that much along every axis)."""
    gaps = []
    for poly in (a, b):
        for k in range(2):
            edge = poly[k + 1] - poly[k]
            axis = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
            pa, pb = a @ axis, b @ axis
            gaps.append(max(pb.min() - pa.max(), pa.min() - pb.max()))
    return max(gaps)


def _place_footprint(physics: Physics, x: float, y: float, yaw: float) -> np.ndarray:
    """Put the robot so that its footprint is centred at (x, y); return the footprint."""
    physics.set_pose(x + FOOTPRINT_BEHIND_AXLE * math.cos(yaw),
                     y + FOOTPRINT_BEHIND_AXLE * math.sin(yaw), yaw)
    physics.forward()
    return _corners(x, y, yaw, FOOTPRINT_LENGTH, FOOTPRINT_WIDTH)


def _obstacle_boxes(dmap: DuckietownMap) -> list[np.ndarray]:
    return [_corners(o.x, o.y, o.yaw, o.length, o.width) for o in dmap.objects]


def test_obstacle_footprints_match_the_reference_sizes():
    """Footprints (length x width) at the map's heights, from the object table."""
    sizes = [(o.kind, o.length, o.width) for o in load_map("obstacle_loop").objects]
    expected = [("duckie", 0.065, 0.045), ("cone", 0.051, 0.051), ("cone", 0.051, 0.051),
                ("duckie", 0.087, 0.061), ("duckiebot", 0.195, 0.144),
                ("barrier", 0.285, 0.057), ("duckie", 0.087, 0.061)]
    for (kind, length, width), (kind_ref, length_ref, width_ref) in zip(
            sizes, expected, strict=True):
        assert kind == kind_ref
        assert (length, width) == pytest.approx((length_ref, width_ref), abs=2e-3)


def test_robot_on_an_obstacle_touches_it(obstacle_physics):
    """The footprint centred on each obstacle, at a few yaws, is in contact with it."""
    for obj in load_map("obstacle_loop").objects:
        for yaw in (0.0, 0.7, obj.yaw):
            _place_footprint(obstacle_physics, obj.x, obj.y, yaw)
            assert obstacle_physics.touches_obstacle(), (obj.kind, obj.x, obj.y, yaw)


@pytest.mark.parametrize("gap, touches", [(-0.005, True), (0.005, False)])
def test_footprint_edges_against_obstacle_sides(obstacle_physics, gap, touches):
    """Robot aligned with an obstacle, beside each of its four sides: 5 mm of overlap touches,
    a 5 mm gap does not (skipping poses that come near a second obstacle)."""
    dmap = load_map("obstacle_loop")
    boxes = _obstacle_boxes(dmap)
    tested = 0
    for k, obj in enumerate(dmap.objects):
        c, s = math.cos(obj.yaw), math.sin(obj.yaw)
        for along, across in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            # Centre distance = obstacle half size + footprint half size + gap, on that axis.
            d = (along * ((obj.length + FOOTPRINT_LENGTH) / 2 + gap)
                 + across * ((obj.width + FOOTPRINT_WIDTH) / 2 + gap))
            dx, dy = (d, 0.0) if along else (0.0, d)
            footprint = _place_footprint(obstacle_physics, obj.x + c * dx - s * dy,
                                         obj.y + s * dx + c * dy, obj.yaw)
            if any(_separation(footprint, b) < 0.01 for j, b in enumerate(boxes) if j != k):
                continue
            assert obstacle_physics.touches_obstacle() == touches, (obj.kind, along, across)
            tested += 1
    assert tested >= 20


def test_contact_agrees_with_footprint_overlap(obstacle_physics):
    """Around every obstacle, on a grid of positions and yaws: contact exactly when the
    rectangles overlap by 3 mm or more, none when 3 mm or more apart."""
    dmap = load_map("obstacle_loop")
    boxes = _obstacle_boxes(dmap)
    counts = {True: 0, False: 0}
    for obj in dmap.objects:
        for dx in np.linspace(-0.3, 0.3, 7):
            for dy in np.linspace(-0.3, 0.3, 7):
                for yaw in (0.0, 0.5, 2.0):
                    footprint = _place_footprint(obstacle_physics, obj.x + dx, obj.y + dy, yaw)
                    separation = min(_separation(footprint, b) for b in boxes)
                    if abs(separation) < 0.003:
                        continue
                    overlap = separation < 0
                    assert obstacle_physics.touches_obstacle() == overlap, (obj.kind, dx, dy)
                    counts[overlap] += 1
    assert counts[True] > 50 and counts[False] > 200


def test_robot_clear_of_obstacles_on_the_lanes(obstacle_physics):
    """Driving poses along every lane that keep 0.1 m from every obstacle touch nothing."""
    dmap = load_map("obstacle_loop")
    boxes = _obstacle_boxes(dmap)
    tested = 0
    for lane in dmap.lanes:
        for along in np.arange(0.0, lane.length, 0.05):
            x, y, yaw = lane.point_at(along)
            obstacle_physics.set_pose(x, y, yaw)
            obstacle_physics.forward()
            back = FOOTPRINT_BEHIND_AXLE
            footprint = _corners(x - back * math.cos(yaw), y - back * math.sin(yaw), yaw,
                                 FOOTPRINT_LENGTH, FOOTPRINT_WIDTH)
            if min(_separation(footprint, b) for b in boxes) >= 0.1:
                assert not obstacle_physics.touches_obstacle(), (x, y, yaw)
                tested += 1
    assert tested > 100


def test_wheels_rest_on_the_ground():
    """Placed on a road tile and left alone for 60 physics steps (0.25 s), the chassis stays
    one wheel radius (0.0318 m) above the floor, within 2 mm, and does not drift."""
    dmap = load_map("small_loop")
    physics = Physics.from_map(dmap)
    x, y, yaw = dmap.tile_lanes(1, 2)[0].point_at(S / 2)
    physics.set_pose(x, y, yaw)
    physics.forward()
    physics.data.ctrl[:] = 0.0
    chassis = physics.model.name2id("duckiebot/chassis", "body")
    for _ in range(60):
        physics.step()
        assert physics.data.xpos[chassis][2] == pytest.approx(0.0318, abs=0.002)
    x1, y1, yaw1 = physics.pose()
    assert math.hypot(x1 - x, y1 - y) < 0.002
    assert abs(yaw1 - yaw) < 0.01
    assert not physics.diverged


# ----- export ---------------------------------------------------------------------------------

def test_exported_scene_loads_with_the_same_geoms(tmp_path):
    """export_scene writes an MJCF (and its texture) that MuJoCo loads by itself."""
    # Imported here: mujoco chooses its GL backend on import, and crllk must set MUJOCO_GL
    # (headless EGL) first; a module-level import would sort before crllk's.
    import mujoco

    dmap = load_map("small_loop")
    path = export_scene(dmap, tmp_path)
    assert path.exists() and path.suffix == ".xml"
    assert any(p.suffix == ".png" for p in tmp_path.iterdir())
    exported = mujoco.MjModel.from_xml_path(str(path))
    compiled = compile_scene(dmap)
    assert exported.ngeom == compiled.ngeom
    assert exported.nbody == compiled.nbody
    assert exported.ntex == compiled.ntex
    assert exported.nu == compiled.nu == 2
