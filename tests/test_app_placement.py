"""Apply rebuilds a robot at its initial pose only when that is free; otherwise at the nearest
free pose, and says so (``agvsim.app.placement``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.app.placement import CLEARANCE_M, blocker
from agvsim.app.session import Session
from agvsim.scenario import parse_scenario

ROOM = "\n".join(["#########"] + ["#.......#"] * 7 + ["#########"])  # free x, y in [-3.5, 3.5]


def _robot(name: str, x: float, speed_rad_s: float) -> dict:
    return {
        "name": name,
        "model": "differential",
        "mode": "forward",
        "pose": {"x_m": x, "y_m": 0.0, "theta_deg": 0.0},
        "body": {"length_m": 0.6, "width_m": 0.45},
        "sensors": [{"type": "rangers"}],
        "controller": {
            "type": "script",
            "steps": [{"duration_s": 1000, "wheels": [speed_rad_s, speed_rad_s]}],
        },
    }


def _session() -> Session:
    robots = [_robot("agv", -2.0, 5.0), _robot("parked", 2.0, 0.0)]
    return Session(parse_scenario({"name": "room", "world": {"picture": ROOM}, "robots": robots}))


def test_apply_puts_a_robot_back_at_its_initial_pose_when_that_is_free():
    s = _session()
    s.step(100)  # agv drives 1 m at 0.5 m/s
    note = s.apply_robot("agv", s.robot_config("agv"))
    assert tuple(s.sim.state.poses[0]) == (-2.0, 0.0, 0.0)
    assert "initial pose" in note and "placed" not in note


def test_apply_with_another_robot_on_the_initial_pose_picks_the_nearest_free_pose():
    s = _session()
    s.step(100)  # agv at (-1.5, 0)
    s.sim.state.poses[1] = (-2.6, 0.0, 0.0)  # 'parked' now stands on agv's start (it was pushed)
    note = s.apply_robot("agv", s.robot_config("agv"))
    x, y, th = s.sim.state.poses[0]
    assert th == 0.0 and np.array_equal(s.sim.state.odom_poses[0], s.sim.state.poses[0])
    # hand-worked: bodies 0.6 x 0.45, agv's grown by 0.1; 'parked' is 0.6 m west of the start,
    # closer than 0.3 + 0.4: the start is taken; 0.1 m east of it the bodies are 0.7 m apart
    d = math.hypot(x + 2.0, y)
    assert d == pytest.approx(0.1, abs=0.1 + 1e-9) and x > -2.0
    fp = s.sim.footprints(s.sim.state.poses)
    assert len(s.sim.collider.overlapping_pairs(fp)) == 0
    assert blocker(s.sim, 0, (x, y, th)) is None
    # nothing nearer is free: every pose on the rings inside d is blocked
    for r in np.arange(0.1, d - 1e-9, 0.1):
        for a in np.linspace(0, 2 * np.pi, 32, endpoint=False):
            assert blocker(s.sim, 0, (-2.0 + r * np.cos(a), r * np.sin(a), 0.0)) is not None
    assert "placed at" in note and "'parked'" in note and f"{d:.2f} m" in note
    # and it does not start bumping into the robot it was moved away from
    s.step(5)
    assert s.sim.state.robot_collisions.tolist() == [0, 0]


def test_a_wall_on_the_initial_pose_also_counts():
    s = _session()
    cfg = s.robot_config("agv")
    cfg["pose"] = {"x_m": -3.15, "y_m": 0.0, "theta_deg": 0.0}  # tail 0.05 m off the wall
    note = s.apply_robot("agv", cfg)
    x = s.sim.state.poses[0, 0]
    assert "a wall" in note
    # the west wall face is x = -3.5: the tail (0.3) plus the clearance must fit
    assert x - 0.3 - CLEARANCE_M >= -3.5 - 1e-9
    assert x == pytest.approx(-3.1, abs=0.06)


def test_placing_a_robot_by_a_click_takes_the_nearest_free_spot():
    s = _session()
    note = s.move_robot("agv", 1.0, -1.0)  # free floor
    assert tuple(s.sim.state.poses[0]) == (1.0, -1.0, 0.0) and "placed at (1.00, -1.00)" in note
    note = s.move_robot("agv", 2.0, 0.0)  # on 'parked': beside it instead
    x, y, _ = s.sim.state.poses[0]
    assert blocker(s.sim, 0, (x, y, 0.0)) is None and 0.0 < math.hypot(x - 2.0, y) < 1.0
    assert s.robot_config("agv")["pose"]["x_m"] == -2.0  # the initial pose stays


def test_a_wall_added_in_the_maze_editor_is_a_wall_to_the_behaviours_not_a_robot():
    """The behaviours tell robots from walls with a distance field of the walls: the maze
    editor renews it, so a new wall is at distance 0 and a removed one is free floor."""
    from agvsim.control.traffic import RobotSight

    robot = {
        "name": "agv",
        "model": "differential",
        "pose": {"x_m": -2.5, "y_m": -2.5, "theta_deg": 0.0},
        "sensors": [{"type": "lidar", "beams": 36, "range_max_m": 5.0}],
        "controller": {"type": "avoid", "sensor": "lidar"},
    }
    s = Session(parse_scenario({"name": "room", "world": {"picture": ROOM}, "robots": [robot]}))
    sights = [
        c.sight for c in (b.controller for b in s.sim.bindings) if isinstance(c.sight, RobotSight)
    ]
    assert sights
    centre = (np.array([0.0]), np.array([0.0]))  # the free cell (4, 4) of the room
    assert all(sg.static.distance_m(*centre)[0] > 2.5 for sg in sights)
    assert s.toggle_cell(4, 4)  # a wall now
    assert all(sg.static.distance_m(*centre)[0] == 0.0 for sg in sights)
    assert not s.toggle_cell(4, 4)  # free again
    assert all(sg.static.distance_m(*centre)[0] > 2.5 for sg in sights)


def test_dragging_the_place_gizmo_moves_the_robot_to_the_nearest_free_pose():
    """The "place robots" gizmo (viser transform controls, x/y only) sits on the picked
    robot; letting it go over the other robot puts the robot at the nearest free pose beside
    it, and the gizmo follows to where the robot really went."""
    viser = pytest.importorskip("viser")
    from agvsim.app.drag_place import GIZMO_Z_M, DragPlace
    from agvsim.net import free_port

    s = _session()
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    notes: list[str] = []
    try:
        drag = DragPlace(server.scene, s, notes.append)
        drag.show("agv")
        np.testing.assert_allclose(drag.handle.position, (-2.0, 0.0, GIZMO_Z_M))
        text = drag.release(2.0, 0.0)  # onto "parked"
        x, y, th = s.sim.state.poses[0]
        assert text == notes[-1] and text.startswith("agv placed at")
        assert th == 0.0 and blocker(s.sim, 0, (x, y, th)) is None  # clear of robot and walls
        assert 0.0 < math.hypot(x - 2.0, y) < 1.5  # beside it, as near as it fits
        np.testing.assert_allclose(drag.handle.position, (x, y, GIZMO_Z_M))
        drag.hide()
        assert not drag.shown and not drag.handle.visible and drag.release(0.0, 0.0) == ""
    finally:
        server.stop()
