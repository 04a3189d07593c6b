"""Wall following (thesis 7.2) and the corridor coverage metric.

The thesis case: the Swedish-wheel (Mecanum) robot, driven through its forward kinematics,
follows the wall on its left round the Fig. 16 maze with its 240-beam lidar on, and comes back
to its start. What "covered" means here (``agvsim.metrics.coverage``):

* reachable cells: the free cells of the 1 m maze 4-connected to the start cell (257 in
  Fig. 16). A robot body fits in every one of them (corridors are 2 m wide or more), so none
  is left out for being too narrow;
* corridor cells: the reachable cells with a wall among their 8 neighbours (202 of the 257):
  the cells a wall follower is meant to run through. The other 55 are room interiors, a cell
  or more from every wall, which a robot holding ``distance_m`` from a wall never enters;
* visited: the body centre was in the cell; seen: a lidar beam passed through the cell.

So the tour is asked to visit >= 90 % of the corridor cells (it visits all 202) and to see
>= 99 % of all reachable cells with the lidar (it sees all 257); its centre visits 78.6 % of
all reachable cells, which the test pins from below.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from agvsim.behaviours import WallFollowConfig
from agvsim.behaviours import build_wall_follow as build
from agvsim.control.api import ControllerContext, LaserScan, Observation
from agvsim.control.script import ScriptController, ScriptStep
from agvsim.control.wall_follow import WallFollower
from agvsim.kinematics import DifferentialDrive
from agvsim.metrics.coverage import CorridorCoverage, CoverageConfig, build_coverage
from agvsim.scenario import parse_robot, robot_spec
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Binding, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.loaders import parse_text_picture
from agvsim.world.mazes import thesis_maze

# the thesis's robots (as in scenarios/thesis_maze_avoid.yaml), omni3 added
ROBOTS = {
    "mecanum": (
        {"wheel_radius_m": 0.05, "half_length_m": 0.2, "half_width_m": 0.2},
        {"length_m": 0.55, "width_m": 0.5},
    ),
    "differential": (
        {"wheel_radius_m": 0.1, "half_track_m": 0.25},
        {"length_m": 0.6, "width_m": 0.45},
    ),
    "omni3": ({"wheel_radius_m": 0.05, "base_radius_m": 0.2}, {"length_m": 0.5, "width_m": 0.5}),
    "tricycle": (
        {"wheel_radius_m": 0.1, "wheelbase_m": 0.5, "half_track_m": 0.2},
        {"length_m": 0.7, "width_m": 0.45},
    ),
    "ackermann": (
        {"wheel_radius_m": 0.1, "wheelbase_m": 0.45, "half_track_m": 0.18, "max_steer_rad": 0.7},
        {"length_m": 0.65, "width_m": 0.42},
    ),
}
# in the west corridor of Fig. 16 (x in [-9, -7] m), heading north, 0.6 m off the wall to follow
START = {"left": (-8.4, 0.5, 90.0), "right": (-7.6, 0.5, 90.0)}
TOUR_LIMIT_S = 900.0


def _robot(model: str, mode: str, pose, sensors=None) -> RobotSpec:
    params, body = ROBOTS[model]
    rc = parse_robot(
        {
            "name": model,
            "model": model,
            "mode": mode,
            "params": params,
            "body": body,
            "pose": {"x_m": pose[0], "y_m": pose[1], "theta_deg": pose[2]},
            "sensors": sensors
            or [
                {"type": "lidar", "beams": 240, "range_max_m": 10.0, "rate_hz": 10.0},
                {"type": "rangers", "range_max_m": 1.5},
            ],
        }
    )
    return robot_spec(rc, "robots[0]", 0.02)


def _follower_sim(model: str, mode: str, side: str, sensor: str = "lidar", pose=None):
    spec = _robot(model, mode, pose or START[side])
    grid = thesis_maze("thesis_fig16")
    cfg = WallFollowConfig(type="wall_follow", side=side, sensor=sensor)
    ctrl = build(cfg, ControllerContext(0, spec, grid))
    return Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.02, seed=1)


def _tour(model: str, mode: str, side: str, sensor: str = "lidar"):
    sim = _follower_sim(model, mode, side, sensor)
    cover = CorridorCoverage(sim.world.grid, 0, return_heading_tol_rad=math.pi / 2)
    cover.update(sim)
    while sim.state.t_s < TOUR_LIMIT_S:
        sim.step()
        if cover.update(sim):
            break
    return sim, cover.result()


# ---------------------------------------------------------------------------------- the tour
@pytest.mark.parametrize(
    ("model", "mode", "side", "sensor"),
    [
        ("mecanum", "forward", "left", "lidar"),  # the thesis's experiment
        ("mecanum", "forward", "right", "lidar"),
        ("differential", "inverse", "left", "lidar"),
        ("mecanum", "forward", "left", "rangers"),  # the four rangers alone
    ],
)
@pytest.mark.slow
def test_tour_of_fig16_comes_back_having_covered_the_corridors(model, mode, side, sensor):
    sim, res = _tour(model, mode, side, sensor)
    print(f"{model} {mode} {side} {sensor}: {res}")
    assert res["returned_to_start"], res
    assert res["return_time_s"] < TOUR_LIMIT_S
    assert int(sim.state.wall_collisions[0]) == 0
    assert res["reachable_cells"] == 257 and res["wall_side_cells"] == 202
    assert res["wall_side_visited_fraction"] >= 0.9
    assert res["visited_fraction"] >= 0.75  # all reachable cells, room interiors included
    assert res["seen_fraction"] >= 0.99


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["inverse", "forward"])
@pytest.mark.parametrize("model", list(ROBOTS))
def test_every_model_follows_the_wall_without_touching_it(model, mode):
    """Every model, both modes: 90 s of the tour (three corners, a wall end, a dead end's
    K-turn for the car) with no collision, mostly in ``follow``."""
    sim = _follower_sim(model, mode, "left")
    states = []
    for _ in range(4500):
        sim.step()
        states.append(sim.active_states()[0])
    assert int(sim.state.collisions[0]) == 0
    assert states.count("follow") > 0.5 * len(states)
    assert {"turn_corner", "follow"} <= set(states)
    assert sim.state.distance_m[0] > 20.0


def test_follower_holds_its_distance_along_a_straight_wall():
    spec = _robot("differential", "inverse", (-4.0, -3.3, 0.0))
    grid = parse_text_picture("\n".join(["#" * 12] + ["#" + "." * 10 + "#"] * 8 + ["#" * 12]))
    ctrl = WallFollower(side="right", distance_m=0.7, speed_m_s=0.4)  # the south wall, y = -4
    sim = Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.02, seed=0)
    sim.run(12.0)
    x, y, th = sim.state.poses[0]
    assert ctrl.state_name == "follow"
    assert y == pytest.approx(-4.0 + 0.7, abs=0.03)
    assert th == pytest.approx(0.0, abs=0.03)
    assert x > 0.0


def test_a_wall_ahead_makes_it_turn_away_from_the_wall_side():
    grid = parse_text_picture("\n".join(["#" * 8] + ["#" + "." * 6 + "#"] * 6 + ["#" * 8]))
    spec = _robot("mecanum", "forward", (2.4, 0.0, 0.0))  # facing the east wall (x = 3), 0.6 m
    for side, sign in (("left", -1.0), ("right", 1.0)):
        ctrl = WallFollower(side=side)
        sim = Simulation(World(grid), [spec], [Binding(ctrl, (0,))], dt_s=0.02, seed=0)
        sim.run(0.2)
        assert ctrl.state_name == "turn_corner"
        sim.run(0.5)
        assert sign * sim.state.poses[0, 2] > 0.2  # left follower turns right, and back


@pytest.mark.slow
def test_same_seed_same_tour():
    a, b = (_follower_sim("tricycle", "forward", "left") for _ in range(2))
    a.run(40.0)
    b.run(40.0)
    np.testing.assert_array_equal(a.state.poses, b.state.poses)


# ---------------------------------------------------------------------------------- config
def test_config_rejects_unknown_keys_and_values_out_of_range():
    ok = WallFollowConfig(type="wall_follow", side="right", distance_m=0.8)
    assert ok.side == "right" and ok.sensor == "lidar"
    for bad in (
        {"sid": "left"},
        {"side": "up"},
        {"distance_m": 0.0},
        {"speed_m_s": -1.0},
        {"heading_source": "gps"},
    ):
        with pytest.raises(ValidationError):
            WallFollowConfig(type="wall_follow", **bad)
    with pytest.raises(ValidationError):
        ok.side = "left"  # frozen


def test_build_names_a_missing_sensor_and_a_distance_too_short_to_turn_in():
    spec = _robot("differential", "inverse", (0.0, 0.0, 0.0))
    ctx = ControllerContext(0, spec, thesis_maze("thesis_fig16"))
    with pytest.raises(ValueError, match="no sensor 'laser'.*lidar, rangers"):
        build(WallFollowConfig(type="wall_follow", sensor="laser"), ctx)
    with pytest.raises(ValueError, match="distance_m"):
        build(WallFollowConfig(type="wall_follow", distance_m=0.2), ctx)
    ctrl = build(WallFollowConfig(type="wall_follow", side="right", sensor="rangers"), ctx)
    assert isinstance(ctrl, WallFollower) and ctrl.side == "right"


def test_reading_a_sensor_the_robot_lacks_is_a_clear_error():
    obs = Observation(
        t_s=0.0,
        name="r",
        scans={"rangers": LaserScan(0.0, 0.0, math.pi / 2, 0.0, 1.0, np.full(4, np.inf))},
        odom_pose=np.zeros(3),
        wheel_speeds=np.zeros(2),
        bump=False,
        true_pose=np.zeros(3),
        model=DifferentialDrive(),
    )
    with pytest.raises(KeyError, match="'lidar'.*rangers"):
        WallFollower().step(obs)


# ---------------------------------------------------------------------------------- metric
PICTURE = "\n".join(
    [
        "#########",
        "#.....#.#",  # the cell at the right is walled off: not reachable
        "#########",
    ]
)


def _scripted(grid, pose, steps, sensors=()):
    spec = RobotSpec(
        name="r",
        model=DifferentialDrive(),
        initial_pose=pose,
        body_length_m=0.5,
        body_width_m=0.4,
        sensors=tuple(sensors),
        odometry=OdometrySpec(0.0),
    )
    return Simulation(World(grid), [spec], [Binding(ScriptController(steps), (0,))], dt_s=0.02)


def test_coverage_counts_reachable_visited_and_seen_cells():
    grid = parse_text_picture(PICTURE)  # 9 x 3 cells of 1 m, centred: x in [-4.5, 4.5]
    lidar = RangeSensorSpec.fan("lidar", 36, 2 * math.pi, 10.0, rate_hz=10.0)
    sim = _scripted(grid, (-3.0, 0.0, 0.0), [ScriptStep(2.0, twist=(0.5, 0.0, 0.0))], [lidar])
    cover = CorridorCoverage(grid, 0, stop_on_return=False)
    cover.update(sim)
    res = cover.result()
    assert res["reachable_cells"] == 5  # the walled-off cell is free but out of reach
    assert res["wall_side_cells"] == 5
    assert res["visited_cells"] == 1
    assert res["seen_cells"] == 5  # a straight corridor: the first scan sees all of it
    assert not cover.seen[1, 7]  # ... and nothing through the wall
    sim.run(2.0)  # 1 m east: from x = -3.0 to -2.0, the next cell (x in [-2.5, -1.5])
    assert cover.update(sim) is False
    assert cover.result()["visited_cells"] == 2
    assert cover.result()["visited_fraction"] == pytest.approx(0.4)


def test_coverage_return_to_start_needs_leaving_first():
    grid = parse_text_picture("\n".join(["#" * 12] + ["#" + "." * 10 + "#"] * 3 + ["#" * 12]))
    out_and_back = [ScriptStep(4.0, twist=(1.0, 0.0, 0.0)), ScriptStep(4.0, twist=(-1.0, 0, 0))]
    sim = _scripted(grid, (-4.0, 0.0, 0.0), out_and_back)
    cover = CorridorCoverage(grid, 0, return_heading_tol_rad=0.1)
    ended_at = None
    for _ in range(400):
        sim.step()
        if cover.update(sim):
            ended_at = sim.state.t_s
            break
    # out to 4 m at t = 4 s (left the 3 m circle at t = 3 s), back inside 1 m at t = 7 s
    assert ended_at == pytest.approx(7.0, abs=0.021)
    assert cover.result()["return_time_s"] == ended_at
    assert cover.result()["returned_to_start"]


def test_coverage_return_heading_tolerance_and_config():
    grid = parse_text_picture("\n".join(["#" * 12] + ["#" + "." * 10 + "#"] * 3 + ["#" * 12]))
    # out 4 m, turn round on the spot (pi rad in 2 s), back: facing the other way at the start
    steps = [
        ScriptStep(4.0, twist=(1.0, 0.0, 0.0)),
        ScriptStep(2.0, twist=(0.0, 0.0, math.pi / 2)),
        ScriptStep(4.0, twist=(1.0, 0.0, 0.0)),
    ]
    sim = _scripted(grid, (-4.0, 0.0, 0.0), steps)
    strict = build_coverage(
        CoverageConfig(robot="r", return_heading_tol_deg=90.0, end_run=False), sim
    )
    loose = build_coverage(CoverageConfig(robot="r", end_run=False), sim)
    for _ in range(500):
        sim.step()
        strict.update(sim)
        loose.update(sim)
    assert loose.result()["returned_to_start"]
    assert loose.result()["return_time_s"] == pytest.approx(9.0, abs=0.021)
    assert not strict.result()["returned_to_start"]
    with pytest.raises(ValueError, match="no robot named 'x'"):
        build_coverage(CoverageConfig(robot="x"), sim)
    with pytest.raises(ValueError, match="no sensor 'lidar'"):
        build_coverage(CoverageConfig(robot="r", sensor="lidar"), sim)
