"""Top-view renderer: exact pixels of walls, footprints, beams and the drawing primitives."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.kinematics import DifferentialDrive
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.viz import topview
from agvsim.viz.topview import (
    FLOOR_RGB,
    HEADING_RGB,
    HIT_RGB,
    TAG_RGB,
    WALL_RGB,
    View,
    draw_segments,
    fill_polygon,
    render_top,
)
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Appearance, Face, MarkerKind, MarkerSpec, place_markers


def _sim(sensors=(), pose=(0.0, 0.0, 0.0), color="#0000ff", markers=()) -> Simulation:
    m = np.zeros((4, 4), dtype=int)
    m[0, 0] = 1  # the north-west cell: x in [-2, -1), y in [1, 2)
    grid = OccupancyGrid.from_matrix(m, 1.0)  # spans [-2, 2] x [-2, 2]
    appearance = Appearance(markers=place_markers(markers, grid, 2.0))
    spec = RobotSpec(
        "r",
        DifferentialDrive(),
        body_length_m=1.0,
        body_width_m=0.5,
        initial_pose=pose,
        sensors=tuple(sensors),
        odometry=OdometrySpec(wheel_noise_rel=0.0),
        color=color,
    )
    return Simulation(World(grid, appearance=appearance), [spec])


def _rgb(img, row, col):
    return tuple(int(v) for v in img[row, col])


def test_grid_walls_and_floor_land_on_exact_pixels():
    sim = _sim(pose=(1.0, -1.0, 0.0))
    img = render_top(sim, 40, beams=False)  # 10 px per metre, 40 x 40
    assert img.shape == (40, 40, 3) and img.dtype == np.uint8
    # the wall cell is the top-left 10 x 10 block, nothing else is wall
    assert np.all(img[:10, :10] == WALL_RGB)
    wall = np.all(img == WALL_RGB, axis=-1)
    assert wall.sum() == 100
    assert _rgb(img, 5, 15) == FLOOR_RGB and _rgb(img, 15, 5) == FLOOR_RGB


def test_footprint_fills_its_rectangle_with_the_robot_colour_and_a_heading_mark():
    # robot at (1, -1) facing north: footprint 0.5 m wide (x) and 1 m long (y); at 10 px/m
    # x = 1 is col 30 and y = -1 row 30: corners at cols 27.5 .. 32.5 and rows 25 .. 35. Pixel
    # centres inside: cols 27..32, rows 25..34; the outline's south edge (row 35.0) lands on 35
    sim = _sim(pose=(1.0, -1.0, np.pi / 2), color="#0000ff")
    img = render_top(sim, 40, beams=False)
    blue = np.all(img == (0, 0, 255), axis=-1)
    white = np.all(img == HEADING_RGB, axis=-1)
    body = blue | white | np.all(img == topview.OUTLINE_RGB, axis=-1)
    rows, cols = np.nonzero(body)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (25, 35, 27, 32)
    # the heading mark (white triangle) points north: it lies in the upper half of the body
    wr, _ = np.nonzero(white)
    assert wr.size > 0 and wr.min() < 30 and wr.max() <= 31


def test_lidar_beam_hits_are_drawn_at_the_scan_end_points():
    # one beam east from (1, 1): nothing in the way -> +inf, drawn faint to range_max, no dot;
    # one beam west hits the wall cell's east face at x = -1: 2 m away -> a red dot on the
    # boundary between cols 9 and 10 (x = -1), row 5 (y = 1.45 -> row 5.5)
    lidar = RangeSensorSpec("lidar", 2, 0.0, np.pi, 10.0)
    sim = _sim(sensors=[lidar], pose=(1.0, 1.45, 0.0))
    np.testing.assert_allclose(sim.state.scans[0], [np.inf, 2.0])
    img = render_top(sim, 40, beams=True)
    red = np.all(img == HIT_RGB, axis=-1)
    rows, cols = np.nonzero(red)
    assert rows.tolist() == [5] and cols[0] in (9, 10)
    # the beam between the robot and the wall is blended (neither floor nor wall colour)
    assert _rgb(img, 5, 15) not in (FLOOR_RGB, WALL_RGB)


def test_fill_polygon_covers_pixel_centres_inside():
    img = np.zeros((10, 10, 3), np.uint8)
    fill_polygon(img, np.array([[2.0, 2.0], [6.0, 2.0], [6.0, 6.0], [2.0, 6.0]]), (9, 9, 9))
    filled = np.all(img == 9, axis=-1)
    assert filled.sum() == 16 and filled[2:6, 2:6].all()
    # a triangle with the clockwise winding fills the same pixels as counter-clockwise
    a = np.zeros((10, 10, 3), np.uint8)
    b = np.zeros((10, 10, 3), np.uint8)
    tri = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 8.0]])
    fill_polygon(a, tri, (1, 1, 1))
    fill_polygon(b, tri[::-1], (1, 1, 1))
    assert np.array_equal(a, b) and np.all(a == 1, axis=-1).sum() == 36  # 8+7+...+1 centres


def test_draw_segments_marks_one_pixel_per_step_and_clips():
    img = np.zeros((8, 12, 3), np.uint8)
    draw_segments(img, np.array([[-50.0, 3.5]]), np.array([[9.5, 3.5]]), (200, 0, 0))
    on = np.all(img == (200, 0, 0), axis=-1)
    assert on.sum() == 10 and on[3, :10].all()
    img[:] = 100
    draw_segments(img, np.array([[0.5, 0.5]]), np.array([[5.5, 5.5]]), (200, 200, 200), 0.5)
    assert all(_rgb(img, k, k) == (150, 150, 150) for k in range(6))
    assert _rgb(img, 0, 1) == (100, 100, 100)


def test_view_fit_keeps_aspect_and_centres():
    v = View.fit((-2.0, 2.0, -1.0, 1.0), 80)
    assert (v.width_px, v.height_px, v.px_per_m) == (80, 40, 20.0)
    v2 = View.fit((-2.0, 2.0, -1.0, 1.0), 80, 80)  # square image: map centred vertically
    np.testing.assert_allclose(v2.to_px(np.array([0.0, 0.0])), [40.0, 40.0])
    with pytest.raises(ValueError, match="xmax > xmin"):
        View.fit((1.0, 1.0, 0.0, 1.0), 10)


def test_render_follows_a_changed_grid_and_trails():
    sim = _sim(pose=(0.5, 0.5, 0.0))
    render_top(sim, 40, beams=False)
    sim.set_grid(sim.world.grid.with_cell(3, 3, True))  # south-east cell becomes a wall
    img = render_top(sim, 40, beams=False, trails={"r": np.array([[-1.5, -0.5], [0.5, -0.5]])})
    assert np.all(img[30:40, 30:40] == WALL_RGB)
    # the trail runs along row 25 from col 5 to col 25 in the robot's colour, blended
    assert _rgb(img, 25, 10) not in (FLOOR_RGB,)
    assert _rgb(img, 20, 10) == FLOOR_RGB


PATCH_RGB = (255, 128, 0)
# on the wall cell (0, 0): a 0.3 m patch on its east face (x = -1), 0.25 m to the right of the
# face's middle seen from the front (north), so y in [1.6, 1.9]; an ArUco 4x4 code of 0.45 m on
# its south face (y = 1): 6 modules + 1 quiet module each side print 0.6 m, x in [-1.8, -1.2]
EAST_PATCH = MarkerSpec(
    MarkerKind.PATCH, Face.EAST, 0.3, 1.0, cell=(0, 0), offset_m=0.25, rgb=PATCH_RGB
)
SOUTH_TAG = MarkerSpec(MarkerKind.ARUCO, Face.SOUTH, 0.45, 1.0, cell=(0, 0), marker_id=3)


def _where(img, rgb):
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(np.all(img == rgb, axis=-1)), strict=True)}


def test_markers_are_strips_on_the_floor_along_their_faces():
    sim = _sim(pose=(1.0, -1.0, 0.0), markers=[EAST_PATCH, SOUTH_TAG])
    img = render_top(sim, 40, beams=False)  # 10 px per metre: col = 10 (x + 2), row = 10 (2 - y)
    # patch: y in [1.6, 1.9] -> rows [1, 4); 2 px (the minimum depth) east of x = -1 (col 10)
    assert _where(img, PATCH_RGB) == {(r, c) for r in (1, 2, 3) for c in (10, 11)}
    # tag, drawn magenta: x in [-1.8, -1.2] -> cols [2, 8); 2 px south of y = 1 (row 10)
    assert _where(img, TAG_RGB) == {(r, c) for r in (10, 11) for c in range(2, 8)}
    # the wall itself is untouched, and the floor around the strips too
    assert np.all(img[:10, :10] == WALL_RGB)
    assert _rgb(img, 0, 10) == FLOOR_RGB and _rgb(img, 4, 10) == FLOOR_RGB
    assert _rgb(img, 1, 12) == FLOOR_RGB and _rgb(img, 12, 5) == FLOOR_RGB


def test_marker_strip_depth_follows_the_scale_and_hides_under_new_walls():
    sim = _sim(pose=(1.0, -1.0, 0.0), markers=[EAST_PATCH])
    img = render_top(sim, 400, beams=False)  # 100 px per metre: 0.08 m deep = 8 px
    assert _where(img, PATCH_RGB) == {(r, c) for r in range(10, 40) for c in range(100, 108)}
    # a view that leaves the marker out shows none of it
    part = render_top(sim, 40, beams=False, extent=(0.0, 2.0, -2.0, 0.0))
    assert not np.any(np.all(part == PATCH_RGB, axis=-1))
    # the floor in front of the patch becomes a wall: the strip is not drawn over it
    sim.set_grid(sim.world.grid.with_cell(0, 1, True))
    img = render_top(sim, 400, beams=False)
    assert not np.any(np.all(img == PATCH_RGB, axis=-1))
