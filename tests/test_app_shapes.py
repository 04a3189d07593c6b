"""Geometry of the 3D view: wall mesh, robot parts, wheel orientation, beams, cameras."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from agvsim.app import shapes
from agvsim.kinematics import MODELS
from agvsim.scenario import build, parse_scenario
from agvsim.sim.spec import RobotSpec
from agvsim.world import mazes
from agvsim.world.grid import OccupancyGrid


def _areas_and_normals(verts, faces):
    tri = verts[faces].astype(np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return 0.5 * np.linalg.norm(n, axis=1), n, tri.mean(axis=1)


@settings(max_examples=60, deadline=None)
@given(arrays(bool, st.tuples(st.integers(1, 7), st.integers(1, 7))), st.floats(0.05, 2.0))
def test_wall_mesh_covers_exactly_the_exposed_faces(occ, res):
    g = OccupancyGrid(occ, res, (0.3, -1.0))
    h = 0.8
    verts, faces = shapes.wall_mesh(g, h)
    area, normal, centre = _areas_and_normals(verts, faces)
    up = normal[:, 2] > 0
    # top faces: the occupied cells' area, once
    assert area[up].sum() == pytest.approx(occ.sum() * res * res, rel=1e-5, abs=1e-9)
    # side faces: one cell edge x height for every wall cell edge that borders free space
    pad = np.pad(occ, 1)
    exposed = sum(
        int((occ & ~np.roll(pad, s, axis=a)[1:-1, 1:-1]).sum()) for a in (0, 1) for s in (1, -1)
    )
    assert area[~up].sum() == pytest.approx(exposed * res * h, rel=1e-5, abs=1e-9)
    # every side face looks out of its wall: a step along the normal lands on free space
    side = ~up & (area > 0)
    n = normal[side] / np.linalg.norm(normal[side], axis=1, keepdims=True)
    probe = centre[side] + n * (0.25 * res)
    assert not g.is_occupied_at(probe[:, 0], probe[:, 1])[
        g.contains(probe[:, 0], probe[:, 1])
    ].any()
    behind = centre[side] - n * (0.25 * res)
    assert g.is_occupied_at(behind[:, 0], behind[:, 1]).all()


def test_a_200_by_200_maze_is_one_modest_mesh():
    g = mazes.random_maze(66, 66, 3)  # 199 x 199 cells
    verts, faces = shapes.wall_mesh(g)
    occ = g.occupied
    pad = np.pad(occ, 1)
    exposed = sum(
        int((occ & ~np.roll(pad, s, axis=a)[1:-1, 1:-1]).sum()) for a in (0, 1) for s in (1, -1)
    )
    per_cell = 2 * (occ.sum() + exposed)  # two triangles per cell top and per exposed side
    assert occ.sum() > 10000
    assert len(faces) < 0.4 * per_cell  # runs merged into long quads


def _spec(model: str, **params) -> RobotSpec:
    sc = parse_scenario(
        {
            "world": {"maze": "thesis_c1"},
            "robots": [
                {"name": "r", "model": model, "params": params, "pose": {"x_m": -8, "y_m": 5}}
            ],
        }
    )
    return build(sc).robots[0]


@pytest.mark.parametrize("model", list(MODELS))
def test_wheels_sit_where_the_model_puts_them(model):
    spec = _spec(model)
    parts = shapes.robot_parts(spec)
    pos = np.asarray(spec.model.wheel_positions_m())
    assert [(w.x_m, w.y_m) for w in parts.wheels] == [tuple(p) for p in pos]
    assert all(w.radius_m == spec.model.wheel_radius_m for w in parts.wheels)
    assert sum(w.steered >= 0 for w in parts.wheels) == len(spec.model.steered_wheels)
    assert any(w.rollers for w in parts.wheels) == (model == "mecanum")


def test_wheel_turns_forward_about_its_axle_and_follows_its_steering():
    spec = _spec("ackermann")
    parts = shapes.robot_parts(spec)
    n = len(parts.wheels)
    q = shapes.wheel_quaternions(parts, np.zeros(4), np.zeros(2))
    for k in range(n):  # the cylinder's axis (local z) lies along the axle (robot y)
        np.testing.assert_allclose(shapes.rotate(q[k], [0, 0, 1]), [0, 1, 0], atol=1e-12)
    # a quarter turn forward brings the top of the wheel to the front
    q = shapes.wheel_quaternions(parts, np.full(4, np.pi / 2), np.zeros(2))
    top = shapes.rotate(shapes.wheel_quaternions(parts, np.zeros(4), np.zeros(2))[2], [0, 0, 0])
    assert np.allclose(top, 0)
    # the point of the tyre that starts at the top of the wheel ...
    q0 = shapes.wheel_quaternions(parts, np.zeros(4), np.zeros(2))[2]
    local_top = shapes.rotate(np.array([q0[0], -q0[1], -q0[2], -q0[3]]), [0, 0, 1])
    ahead = shapes.rotate(q[2], local_top)
    np.testing.assert_allclose(ahead, [1, 0, 0], atol=1e-12)  # ... is in front after 90 deg
    # steered front wheels: the axle turns with the steering angle
    q = shapes.wheel_quaternions(parts, np.zeros(4), np.array([0.3, 0.2]))
    np.testing.assert_allclose(
        shapes.rotate(q[0], [0, 0, 1]), [-np.sin(0.3), np.cos(0.3), 0], atol=1e-12
    )
    np.testing.assert_allclose(shapes.rotate(q[2], [0, 0, 1]), [0, 1, 0], atol=1e-12)


def test_beams_end_at_the_measured_range():
    sc = parse_scenario(
        {
            "world": {"picture": "#####\n#...#\n#...#\n#...#\n#####"},
            "robots": [
                {
                    "name": "r",
                    "model": "differential",
                    "pose": {"theta_deg": 90},
                    "body": {"length_m": 0.4, "width_m": 0.3},
                    "sensors": [
                        {"type": "rangers", "range_max_m": 1.0},
                        {"type": "lidar", "beams": 4, "range_max_m": 5.0},
                    ],
                }
            ],
        }
    )
    sim = build(sc)
    sim.step()
    seg, slot, hit = shapes.beam_segments(sim.sensors, sim.state.poses, sim.state.scans)
    assert seg.shape == (8, 2, 3) and list(slot) == [0] * 4 + [1] * 4
    length = np.linalg.norm(seg[:, 1, :2] - seg[:, 0, :2], axis=1)
    ranges = sim.state.scans[slot, [0, 1, 2, 3, 0, 1, 2, 3]]
    np.testing.assert_allclose(length[hit], ranges[hit], atol=1e-9)
    np.testing.assert_allclose(length[~hit & (slot == 0)], 1.0)  # no return: drawn to range_max
    # the lidar's beam along the heading (+y) ends on the north wall's face at y = 1.5
    np.testing.assert_allclose(seg[4 + 2, 1, :2], [0.0, 1.5], atol=1e-9)


def test_views_frame_the_map_and_follow_the_robot():
    g = OccupancyGrid.from_matrix(np.zeros((20, 30)), 0.5)
    cam = shapes.camera_top(g, np.deg2rad(50))
    # the whole 15 m x 10 m map fits in the vertical field of view
    assert cam.position[2] * np.tan(np.deg2rad(25)) >= 7.5
    assert cam.position[:2] == cam.look_at[:2] == (0.0, 0.0)
    c = shapes.camera_chase(np.array([1.0, 2.0, np.pi / 2]))
    assert c.position[1] < 2.0 < c.look_at[1] and c.position[0] == pytest.approx(1.0)


def test_markers_sit_on_their_wall_face_the_right_way_round():
    from agvsim.world.markers import Face, MarkerKind, MarkerSpec, place_marker

    m = np.zeros((5, 5), dtype=int)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = 1
    g = OccupancyGrid.from_matrix(m, 1.0, (0.0, 0.0))  # free x, y in [1, 4]
    # ArUco 4x4 (6 modules with its border, + 1 quiet module each side: 8) of size 0.4 m:
    # printed square 0.4 * 8 / 6 = 0.5333 m, half 0.26667; on the west face of the east wall
    # cell (row 2, col 4): the face line x = 4, the cell's middle y = 2.5; seen from the front
    # (looking east) right is south (-y)
    aruco = place_marker(
        MarkerSpec(MarkerKind.ARUCO, Face.WEST, 0.4, 0.5, cell=(2, 4), marker_id=3), g, 1.0
    )
    h = 0.4 * 8 / 6 / 2
    want = [
        (3.99, 2.5 + h, 0.5 + h),  # top-left: north, up
        (3.99, 2.5 - h, 0.5 + h),
        (3.99, 2.5 - h, 0.5 - h),
        (3.99, 2.5 + h, 0.5 - h),
    ]
    assert shapes.marker_quad(aruco, 0.01) == pytest.approx(np.array(want), abs=1e-12)
    # a 0.3 m patch on the north face of the south wall cell (row 4, col 2), 0.2 m to the right
    # (looking south, right is west): centre x = 2.5 - 0.2, face y = 1, 1 cm out: y = 1.01
    patch = place_marker(
        MarkerSpec(MarkerKind.PATCH, Face.NORTH, 0.3, 0.5, cell=(4, 2), offset_m=0.2), g, 1.0
    )
    want = [(2.45, 1.01, 0.65), (2.15, 1.01, 0.65), (2.15, 1.01, 0.35), (2.45, 1.01, 0.35)]
    assert shapes.marker_quad(patch, 0.01) == pytest.approx(np.array(want), abs=1e-12)
    for mk in (aruco, patch):
        # the image node's corners (column 0 left, row 0 top) land on the printed square, its
        # z points into the wall (the viewer reads it looking along +z)
        pos, q = shapes.marker_pose(mk, 0.01)
        assert np.linalg.norm(q) == pytest.approx(1.0)
        local = shapes.image_corners_local(mk.extent_m, mk.extent_m)
        placed = np.array([pos + shapes.rotate(q, c) for c in local])
        assert placed == pytest.approx(shapes.marker_quad(mk, 0.01), abs=1e-12)
        nx, ny = mk.normal_xy
        assert shapes.rotate(q, [0.0, 0.0, 1.0]) == pytest.approx([-nx, -ny, 0.0], abs=1e-12)
        img = shapes.marker_image(mk, 128)
        k = img.shape[0] // mk.texture.shape[0]
        assert img.shape[0] >= 128 and img.shape[:2] == (k * mk.texture.shape[0],) * 2
        assert np.array_equal(img[::k, ::k], mk.texture)


@pytest.mark.parametrize("yaw", [0.0, 0.5, 2.0, np.pi, -2.5])
@pytest.mark.parametrize("tilt", [0.0, 1.0, np.pi / 2, 3.0])
def test_rotation_matrices_become_the_same_quaternions(yaw, tilt):
    q = shapes.quat_mul(shapes.quat_z(yaw), [np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0])
    r = np.column_stack([shapes.rotate(q, e) for e in np.eye(3)])
    got = shapes._quat_of(r)
    assert got == pytest.approx(q * np.sign(q @ got), abs=1e-12)


def test_map_overlay_colours_do_not_wrap_around() -> None:
    from agvsim.app.scene import overlay_rgb

    rgb = overlay_rgb(np.array([[0.0, 0.5, 1.0, 1.7, -0.3]]))
    assert rgb.dtype == np.uint8
    assert rgb[0, 0].tolist() == [30, 30, 30]  # a wall: near black
    assert rgb[0, 1].tolist() == [90, 130, 142]  # unknown: grey-blue (30 + 0.5 x colour)
    assert rgb[0, 2].tolist() == [150, 230, 255]  # free: light blue, not wrapped past 255
    assert rgb[0, 3].tolist() == rgb[0, 2].tolist() and rgb[0, 4].tolist() == [30, 30, 30]
