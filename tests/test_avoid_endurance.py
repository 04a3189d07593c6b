"""Endurance: the thesis's obstacle avoidance (Fig. 22, ``ObstacleAvoidance`` reading the four
rangers) drives every model alone in the App. C.1 maze for 10 simulated minutes, in inverse
and in forward mode, without touching a wall once.

Each robot is the one of ``scenarios/thesis_maze_avoid.yaml`` (parameters, body, rangers,
start pose, trigger and speed; omni3, which that scenario lacks, takes the Mecanum robot's
place), built by the scenario builder as ``type: avoid`` builds it: one robot per run, the
mode set to inverse or forward (forward wraps the behaviour in ``WheelsFromTwist``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from agvsim.control.avoid import side_beams_of
from agvsim.scenario import build, cone_beams, parse_scenario
from agvsim.sensors.range_sensor import RangeSensorSpec

pytestmark = pytest.mark.slow  # endurance: 10-minute runs of every model

ROOT = Path(__file__).resolve().parents[1]
DURATION_S = 600.0  # 10 minutes: 30,000 steps of 20 ms
MODELS = ("differential", "tricycle", "ackermann", "mecanum", "omni3")


def _robots() -> dict[str, dict]:
    data = yaml.safe_load((ROOT / "scenarios" / "thesis_maze_avoid.yaml").read_text())
    robots = {r["model"]: r for r in data["robots"]}
    mecanum = robots["mecanum"]
    robots.setdefault(
        "omni3",
        {
            **mecanum,
            "name": "omni3",
            "model": "omni3",
            "params": {"wheel_radius_m": 0.05, "base_radius_m": 0.2},
            "body": {"length_m": 0.5, "width_m": 0.5},
        },
    )
    return robots


def _alone_in_c1(model: str, mode: str, pose: tuple[float, float, float] | None = None):
    robot = {**_robots()[model], "mode": mode}
    if pose is not None:
        robot["pose"] = {"x_m": pose[0], "y_m": pose[1], "theta_deg": pose[2]}
    robot["sensors"] = [s for s in robot["sensors"] if s["type"] == "rangers"]
    scenario = parse_scenario(
        {
            "name": f"{model} {mode} avoiding alone",
            "seed": 1,
            "dt_s": 0.02,
            "duration_s": DURATION_S,
            "world": {"maze": "thesis_c1"},
            "robots": [robot],
        },
        "endurance",
    )
    return build(scenario)


@pytest.mark.parametrize("mode", ["inverse", "forward"])
@pytest.mark.parametrize("model", MODELS)
def test_ten_minutes_without_a_wall_collision(model, mode):
    sim = _alone_in_c1(model, mode)
    sim.run(DURATION_S)
    st = sim.state
    assert st.t_s == pytest.approx(DURATION_S)
    assert not sim.errors
    assert int(st.wall_collisions[0]) == 0, (
        f"{model} ({mode}) touched a wall {int(st.wall_collisions[0])} times"
    )
    # it kept driving the whole time (not parked in a corner): ~0.4 m/s on average or more
    assert st.distance_m[0] > 0.4 * DURATION_S


# Starts half a metre from the wall on the right, a wall ahead: the first right turn used to
# swing the nose into that wall (a tricycle spins about its rear axle, an Ackermann car turns
# on an arc), 6 or 7 collisions in the first minute before avoid.py kept clear of side walls.
NEXT_TO_A_WALL = [
    ("tricycle", (-0.5, -0.5, 0.0)),
    ("tricycle", (-7.5, 6.5, 90.0)),
    ("ackermann", (-8.5, -5.5, -90.0)),
    ("ackermann", (5.5, 2.5, 180.0)),
]


@pytest.mark.parametrize("mode", ["inverse", "forward"])
@pytest.mark.parametrize(("model", "pose"), NEXT_TO_A_WALL)
def test_car_like_robots_turn_right_clear_of_a_wall_on_the_right(model, pose, mode):
    sim = _alone_in_c1(model, mode, pose)
    sim.run(60.0)
    assert int(sim.state.wall_collisions[0]) == 0


def test_forward_and_inverse_mode_drive_the_same_way_for_a_wheeled_robot():
    """For a model without steering the wheel speeds of the inverse kinematics give back the
    twist exactly, so the two modes trace the same path (a cheap check that the forward-mode
    wiring is the adapter, not another behaviour)."""
    a, b = _alone_in_c1("differential", "inverse"), _alone_in_c1("differential", "forward")
    a.run(30.0)
    b.run(30.0)
    assert abs(a.state.poses[0] - b.state.poses[0]).max() < 1e-6


def test_side_beams_are_a_quarter_turn_from_the_front():
    rangers = RangeSensorSpec.thesis_rangers()
    lidar = RangeSensorSpec.fan("lidar", 240, 2 * np.pi, 10.0)  # beam 120 looks ahead
    from_zero = RangeSensorSpec.fan("lidar", 240, 2 * np.pi, 10.0, angle_min_rad=0.0)
    front_fan = RangeSensorSpec.fan("lidar", 90, np.pi, 5.0)  # no beam looks sideways-back
    expected = [(rangers, ((1,), (3,))), (lidar, ((180,), (60,))), (from_zero, ((60,), (180,)))]
    for spec, want in [*expected, (front_fan, ((), ()))]:
        front, back = cone_beams(spec)
        assert side_beams_of(np.array(front), np.array(back), spec.num_beams) == want
