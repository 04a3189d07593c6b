"""Markers on wall faces: OpenCV finds them in rendered frames where the ground truth says they
are (ids, QR text, corner pixels), they face the right way on every face, occluders hide them,
and bad placements are refused with the field and what is allowed."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from agvsim.kinematics import DifferentialDrive
from agvsim.scenario import ScenarioError, build, parse_scenario
from agvsim.sensors.camera import CameraSpec, marker_views
from agvsim.sim.engine import Simulation
from agvsim.sim.spec import WALL_HEIGHT_M, RobotSpec, World
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import (
    Appearance,
    Face,
    MarkerKind,
    MarkerSpec,
    aruco_dictionary,
    place_markers,
)

from helpers import walled_room

pytestmark = pytest.mark.usefixtures("one_numba_thread")  # from conftest.py


def room() -> OccupancyGrid:
    """Walled room of 9 x 9 cells, origin (0, 0): free x in [1, 8], y in [1, 8]."""
    return walled_room(rows=9, cols=9)


def snap(markers, pose, boxes=(), spec: CameraSpec | None = None, grid=None):
    """(rgb, depth, spec, placed markers) of one frame from a robot at ``pose``."""
    grid = grid or room()
    spec = spec or CameraSpec(mount_xy_m=(0.0, 0.0), mount_z_m=0.5)
    placed = place_markers(markers, grid, WALL_HEIGHT_M)
    world = World(grid, np.array(boxes, dtype=float).reshape(-1, 5), Appearance(markers=placed))
    r = RobotSpec("r", DifferentialDrive(), initial_pose=pose, body_length_m=0.3,
                  body_width_m=0.3, cameras=(spec,))  # fmt: skip
    sim = Simulation(world, [r])
    return np.asarray(sim.state.images[0]), np.asarray(sim.state.depths[0]), spec, placed


def detect(rgb: np.ndarray, kind: MarkerKind, dictionary: str):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det = cv2.aruco.ArucoDetector(aruco_dictionary(kind, dictionary), params)
    corners, ids, _ = det.detectMarkers(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
    if ids is None:
        return {}
    return {int(i): c.reshape(4, 2) for c, i in zip(corners, ids.ravel(), strict=True)}


def aruco(mid, cell, face, **kw) -> MarkerSpec:
    kw.setdefault("size_m", 0.4)
    kw.setdefault("center_z_m", 0.5)
    return MarkerSpec(MarkerKind.ARUCO, Face(face), cell=cell, marker_id=mid, **kw)


# ---------------------------------------------------------------------------- detection
@pytest.mark.parametrize(
    "pose, pitch_deg",
    [
        ((2.0, 4.5, 0.0), 0.0),  # head-on, 6 m
        ((5.0, 4.5, 0.0), 0.0),  # head-on, 3 m
        ((4.0, 2.0, 0.6), 0.0),  # slanted
        ((4.0, 4.4, 0.05), 10.0),  # pitched down
        ((4.0, 4.4, -0.05), -8.0),  # pitched up
    ],
)
def test_aruco_markers_are_found_where_the_ground_truth_puts_them(pose, pitch_deg):
    markers = [aruco(7, (4, 8), "west"), aruco(11, (3, 8), "west"), aruco(23, (5, 8), "west")]
    spec = CameraSpec(mount_xy_m=(0.0, 0.0), mount_z_m=0.5, pitch_rad=math.radians(pitch_deg))
    rgb, depth, spec, placed = snap(markers, pose, spec=spec)
    truth = {v.marker_id: v for v in marker_views(spec, np.array(pose), placed, depth)}
    found = detect(rgb, MarkerKind.ARUCO, "4x4_50")
    assert set(found) == {k for k, v in truth.items() if v.visible_fraction == 1.0}
    assert found  # something is in view in every case
    for k, corners in found.items():
        # corner order (top-left first, clockwise) and position, to a pixel
        np.testing.assert_allclose(corners, truth[k].corners_px, atol=1.0)


@pytest.mark.parametrize("face, cell, pose", [
    ("north", (8, 4), (4.5, 4.0, math.pi / 2 + math.pi)),  # wall south of the room, faces north
    ("south", (0, 4), (4.5, 5.0, math.pi / 2)),
    ("east", (4, 0), (4.0, 4.5, math.pi)),
    ("west", (4, 8), (5.0, 4.5, 0.0)),
])  # fmt: skip
def test_markers_read_the_right_way_round_on_every_face(face, cell, pose):
    """A mirrored or turned texture would not decode as the same id with the same corners."""
    rgb, depth, spec, placed = snap([aruco(5, cell, face)], pose)
    found = detect(rgb, MarkerKind.ARUCO, "4x4_50")
    (view,) = marker_views(spec, np.array(pose), placed, depth)
    assert list(found) == [5]
    np.testing.assert_allclose(found[5], view.corners_px, atol=1.0)


def test_apriltag_qr_and_patch():
    markers = [
        MarkerSpec(
            MarkerKind.APRILTAG, Face.WEST, 0.35, 0.5, cell=(3, 8), marker_id=42, dictionary="36h11"
        ),  # fmt: skip
        MarkerSpec(MarkerKind.QR, Face.WEST, 0.45, 0.5, cell=(4, 8), text="dock 7"),
        MarkerSpec(MarkerKind.PATCH, Face.WEST, 0.3, 0.5, cell=(5, 8), rgb=(10, 200, 30)),
    ]
    pose = np.array([5.7, 4.5, 0.0])  # 2.3 m from the wall
    rgb, depth, spec, placed = snap(markers, tuple(pose))
    views = {v.name: v for v in marker_views(spec, pose, placed, depth)}
    assert set(views) == {"apriltag:42", "qr:dock 7", "patch2"}
    assert all(v.visible_fraction == 1.0 for v in views.values())
    tags = detect(rgb, MarkerKind.APRILTAG, "36h11")
    assert list(tags) == [42]
    np.testing.assert_allclose(tags[42], views["apriltag:42"].corners_px, atol=1.0)
    text, pts, _ = cv2.QRCodeDetector().detectAndDecode(rgb)
    assert text == "dock 7"
    np.testing.assert_allclose(pts.reshape(4, 2), views["qr:dock 7"].corners_px, atol=2.0)
    u, v = np.rint(views["patch2"].center_px).astype(int)
    assert tuple(rgb[v, u]) == (10, 200, 30)
    # the patch covers its projected square: its colour fills the pixels well inside it
    c = views["patch2"].corners_px
    inner = rgb[int(c[0, 1]) + 2 : int(c[2, 1]) - 1, int(c[0, 0]) + 2 : int(c[1, 0]) - 1]
    assert inner.size and (inner == (10, 200, 30)).all()


def test_occluded_markers_are_neither_seen_nor_counted_visible():
    markers = [aruco(1, (4, 8), "west"), aruco(2, (2, 8), "west")]
    pose = (3.0, 4.5, 0.0)
    box = (6.0, 4.5, 0.0, 0.2, 0.6)  # 1 m tall box straight ahead hides marker 1
    rgb, depth, spec, placed = snap(markers, pose, boxes=[box])
    views = {
        v.marker_id: v
        for v in marker_views(spec, np.array(pose), placed, depth, only_visible=False)
    }
    assert views[1].visible_fraction == 0.0 and views[2].visible_fraction == 1.0
    assert list(detect(rgb, MarkerKind.ARUCO, "4x4_50")) == [2]
    # half hidden: a narrower box covering the left part of marker 1
    rgb, depth, spec, placed = snap(markers, pose, boxes=[(7.0, 4.65, 0.0, 0.05, 0.15)])
    (v1,) = [v for v in marker_views(spec, np.array(pose), placed, depth) if v.marker_id == 1]
    assert 0.0 < v1.visible_fraction < 1.0


def test_a_marker_seen_from_behind_is_not_visible():
    """The face looks west; a camera east of the wall cell sees the cell's other side."""
    g = OccupancyGrid.from_matrix(
        [[1, 1, 1, 1, 1], [1, 0, 0, 0, 1], [1, 0, 1, 0, 1], [1, 0, 0, 0, 1], [1, 1, 1, 1, 1]],
        1.0, (0.0, 0.0),
    )  # fmt: skip
    spec = CameraSpec(mount_xy_m=(0.0, 0.0), mount_z_m=0.5, width_px=64, height_px=48)
    rgb, depth, spec, placed = snap([aruco(3, (2, 2), "west", size_m=0.3)], (3.5, 2.5, math.pi),
                                    spec=spec, grid=g)  # fmt: skip
    assert marker_views(spec, np.array([3.5, 2.5, math.pi]), placed, depth) == []


# ---------------------------------------------------------------------------- placing
def test_placing_by_cell_offset_or_by_point_agree():
    g = room()
    by_cell = place_markers([aruco(1, (4, 8), "west", offset_m=0.2)], g, WALL_HEIGHT_M)[0]
    by_xy = place_markers(
        [MarkerSpec(MarkerKind.ARUCO, Face.WEST, 0.4, 0.5, xy_m=(8.0, 4.3), marker_id=1)],
        g,
        WALL_HEIGHT_M,
    )[0]
    # west face of column 8 is x = 8; offset 0.2 to the right seen from the west is south
    assert by_cell.center_xyz_m == pytest.approx((8.0, 4.3, 0.5))
    assert by_xy.center_xyz_m == pytest.approx(by_cell.center_xyz_m)
    # a 4x4 marker is 6 modules with its black border; the quiet zone adds one each side
    assert by_cell.extent_m == pytest.approx(0.4 * 8 / 6)
    assert by_cell.texture.shape == (8, 8, 3)
    np.testing.assert_allclose(
        by_cell.corners_world(),
        [[8.0, 4.5, 0.7], [8.0, 4.1, 0.7], [8.0, 4.1, 0.3], [8.0, 4.5, 0.3]],
    )


def _world_with(marker: dict, **extra) -> dict:
    return {
        "world": {
            "matrix": room().occupied.astype(int).tolist(),
            "origin_xy_m": [0, 0],
            "markers": [marker],
            **extra,
        },
        "robots": [{"name": "r", "model": "differential", "pose": {"x_m": 4.5, "y_m": 4.5}}],
    }


@pytest.mark.parametrize(
    "marker, words",
    [
        ({"kind": "aruco", "id": 1, "cell": [4, 4], "face": "west"},
         ["markers[0].cell", "(4, 4) is free floor"]),
        ({"kind": "aruco", "id": 1, "cell": [0, 0], "face": "south"},
         ["markers[0].cell", "touches the wall cell (1, 0)"]),
        ({"kind": "aruco", "id": 1, "cell": [4, 8], "face": "east"}, ["map's edge"]),
        ({"kind": "aruco", "id": 60, "cell": [4, 8], "face": "west"},
         ["markers[0].id", "60", "0..49"]),
        ({"kind": "aruco", "id": 1, "cell": [1, 8], "face": "west", "size_m": 0.6,
          "offset_m": -0.3}, ["markers[0].size_m", "overhangs", "(0, 8)"]),
        ({"kind": "aruco", "id": 1, "cell": [4, 8], "face": "west", "size_m": 0.9},
         ["markers[0].size_m", "taller than the wall", "size_m <= 0.75"]),
        ({"kind": "aruco", "id": 1, "cell": [4, 8], "face": "west", "center_z_m": 0.9},
         ["markers[0].center_z_m", "0.9", "allowed"]),
        ({"kind": "aruco", "id": 1, "cell": [4, 8], "x_m": 8.0, "y_m": 4.0, "face": "west"},
         ["exactly one place"]),
        ({"kind": "arucco", "id": 1, "cell": [4, 8], "face": "west"}, ["did you mean 'aruco'"]),
        ({"kind": "qr", "text": "x", "cell": [4, 8], "face": "wset"}, ["'west'"]),
        ({"kind": "patch", "rgb": [0, 300, 0], "cell": [4, 8], "face": "west"}, ["255"]),
        ({"kind": "aruco", "id": 1, "x_m": 4.5, "y_m": 4.5, "face": "west"},
         ["x_m, y_m (4.5, 4.5)", "free floor"]),
    ],
)  # fmt: skip
def test_bad_markers_are_refused_with_the_field(marker, words):
    with pytest.raises(ScenarioError) as err:
        build(parse_scenario(_world_with(marker)))
    msg = str(err.value)
    for w in words:
        assert w in msg, msg


def test_paint_outside_the_map_is_refused():
    data = _world_with({"kind": "aruco", "id": 1, "cell": [4, 8], "face": "west"})
    data["world"]["colors"] = {"paint": [{"rows": [0, 9], "cols": [0, 0], "rgb": [1, 2, 3]}]}
    with pytest.raises(ScenarioError, match=r"colors.paint\[0\].rows.*0..8"):
        build(parse_scenario(data))


def test_painted_cells_show_their_colour():
    data = _world_with({"kind": "patch", "rgb": [0, 0, 255], "cell": [2, 8], "face": "west"})
    data["world"]["colors"] = {
        "paint": [{"rows": [4, 4], "cols": [8, 8], "rgb": [200, 0, 0]}],
        "shade_faces": False,
    }
    data["robots"][0]["sensors"] = [{"type": "camera", "width_px": 65, "height_px": 49}]
    sim = build(parse_scenario(data))
    rgb = np.asarray(sim.state.images[0])
    assert tuple(rgb[20, 32]) == (200, 0, 0)  # straight ahead: the painted cell (4, 8)
