"""The example vision controller: find ArUco marker 3 with the camera in a small maze with
decoys, and stop 0.8 m in front of it (checked against the marker's true place)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from agvsim.control.marker_search import MarkerSearch
from agvsim.scenario import ScenarioError, build, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "marker_search.yaml"


pytestmark = pytest.mark.usefixtures("one_numba_thread")  # from conftest.py


def stop_pose(sim, name: str, distance_m: float) -> tuple[np.ndarray, float]:
    """Where the robot's reference point must end for the camera to be ``distance_m`` in front
    of marker ``name``, facing it (from the world's ground truth)."""
    mk = next(m for m in sim.world.appearance.markers if m.name == name)
    n = np.array(mk.normal_xy)
    heading = math.atan2(-n[1], -n[0])
    cam = np.array(mk.center_xyz_m[:2]) + distance_m * n
    mx, my = sim.robots[0].cameras[0].mount_xy_m
    c, s = math.cos(heading), math.sin(heading)
    return cam - np.array([c * mx - s * my, s * mx + c * my]), heading


@pytest.mark.slow
def test_finds_marker_3_and_stops_in_front_of_it():
    sim = build(load_scenario(SCENARIO))
    ctrl = sim.bindings[0].controller
    assert isinstance(ctrl, MarkerSearch)
    # it has to look for it: marker 3 is not in view from the start (ground truth)
    first = sim.cameras.marker_views(sim.state, 0)
    assert "aruco:1" in [v.name for v in first] and "aruco:3" not in [v.name for v in first]
    while sim.state.t_s < 120.0 and ctrl.state_name != "done":
        sim.step()
    assert ctrl.state_name == "done", f"still {ctrl.state_name} at {sim.state.t_s:.1f} s"
    goal, heading = stop_pose(sim, "aruco:3", 0.8)
    pose = sim.state.poses[0]
    assert np.hypot(*(pose[:2] - goal)) < 0.1
    assert abs(math.remainder(pose[2] - heading, 2 * math.pi)) < math.radians(3.0)
    decoy, _ = stop_pose(sim, "aruco:4", 0.8)  # one metre beside it
    assert np.hypot(*(pose[:2] - decoy)) > 0.8
    assert sim.state.collisions[0] == 0
    for _ in range(25):  # and it stays put
        sim.step()
    assert np.allclose(sim.state.poses[0], pose)
    # summary.json says what the search came to
    from agvsim.record.outputs import summary

    report = summary(sim, 1.0)["robots"][0]["controller"]
    assert report["marker_id"] == 3 and report["marker_found"] and report["stopped_in_front"]
    assert 0.0 < report["found_at_s"] < sim.state.t_s
    assert report["marker_xy_m"] == pytest.approx([5.0, -2.5], abs=0.1)


def test_locate_turns_a_frame_into_the_stop_pose():
    """From one frame, the stop pose in front of a marker seen at a slant is within a
    centimetre and half a degree of the truth."""
    data = load_scenario(SCENARIO).model_dump()
    data["robots"][0]["pose"] = {"x_m": 1.0, "y_m": -3.2, "theta_deg": 15.0}
    sim = build(parse_scenario(data))
    ctrl = sim.bindings[0].controller
    rgb, depth = sim.state.images[0], sim.state.depths[0]
    target = ctrl.locate(rgb, depth, tuple(sim.state.poses[0]))
    assert target is not None
    goal, heading = stop_pose(sim, "aruco:3", 0.8)
    assert np.hypot(target.x_m - goal[0], target.y_m - goal[1]) < 0.01
    assert abs(math.remainder(target.theta_rad - heading, 2 * math.pi)) < math.radians(0.5)
    assert target.marker_xy_m == pytest.approx((5.0, -2.5), abs=0.01)


def test_marker_search_needs_a_camera():
    data = load_scenario(SCENARIO).model_dump()
    data["robots"][0]["sensors"] = [{"type": "lidar"}]
    with pytest.raises(ScenarioError, match=r"controller\.camera: the robot has no camera"):
        build(parse_scenario(data))
