"""Other robots seen by the lidar (``agvsim.control.traffic``): hand-worked geometry, the
safety limit's invariants, and whole scenarios in which built-in behaviours meet head on."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.control.api import Twist, WheelCommand
from agvsim.control.traffic import Footprint, KeepClear, RobotSight, StaticMap
from agvsim.scenario import build, parse_scenario
from agvsim.world.grid import OccupancyGrid

from helpers import walled_room

BEAMS = 360  # one beam a degree, beam j looks at j degrees
ANGLES = np.deg2rad(np.arange(BEAMS, dtype=np.float64))


def _open_floor(size: int = 40) -> StaticMap:
    """No walls anywhere near the origin (a 40 x 40 m room centred on it)."""
    grid = walled_room(size, size)
    return StaticMap.of(OccupancyGrid(grid.occupied, 1.0, (-size / 2, -size / 2)))


def _sight(static: StaticMap | None = None, **kw) -> RobotSight:
    body = Footprint(half_length_m=0.3, half_width_m=0.2)
    return RobotSight(static or _open_floor(), "lidar", ANGLES, body, **kw)


def _scan(*hits: tuple[float, float]) -> np.ndarray:
    """(1, 360) ranges: inf except ``(degree, range)`` pairs."""
    r = np.full((1, BEAMS), np.inf)
    for deg, rng in hits:
        r[0, int(deg)] = rng
    return r


POSE = np.zeros((1, 3))


def test_static_map_distance_is_the_distance_to_the_nearest_wall():
    # walled 10 x 10 room, origin (0, 0): the inner wall faces are x = 1, x = 9, y = 1, y = 9
    static = StaticMap.of(walled_room(10, 10))
    d = static.distance_m(np.array([5.0, 2.0, 1.02]), np.array([5.0, 5.0, 5.0]))
    assert d == pytest.approx([4.0, 1.0, 0.0], abs=0.06)
    # a box of half sizes 0.5 x 0.25 at (5, 5): 0.75 m from (5, 6)
    boxed = StaticMap.of(walled_room(10, 10), np.array([[5.0, 5.0, 0.0, 0.5, 0.25]]))
    assert boxed.distance_m(np.array([5.0]), np.array([6.0]))[0] == pytest.approx(0.75, abs=0.06)


def test_a_return_on_a_wall_is_not_a_robot_one_in_free_floor_is():
    static = StaticMap.of(walled_room(10, 10))
    sight = RobotSight(static, "lidar", ANGLES, Footprint(0.3, 0.2))
    pose = np.array([[5.0, 5.0, 0.0]])
    # beam 0 hits the east wall face x = 9 at 4 m; beam 90 a robot at (5, 7)
    pts = sight.robot_points(pose, _scan((0, 4.0), (90, 2.0)))
    assert pts.hit[0, 0] and not pts.moving[0, 0]
    assert pts.moving[0, 90]
    assert pts.x_m[0, 90] == pytest.approx(0.0, abs=1e-12) and pts.y_m[0, 90] == 2.0
    assert pts.moving.sum() == 1


def test_room_ahead_is_the_gap_between_the_nose_and_the_robot():
    sight = _sight()
    # a robot 2 m ahead: the nose (x = 0.3) is 1.7 m from it
    assert sight.free_m(POSE, _scan((0, 2.0)))[0] == pytest.approx(1.7)
    # a point 10 deg off the axis at 2 m: y = 0.347 > half width 0.2 + margin 0.12: not ahead
    assert math.isinf(sight.free_m(POSE, _scan((10, 2.0)))[0])
    # 5 deg off: y = 0.174, in the corridor; along x = 1.992
    got = sight.free_m(POSE, _scan((5, 2.0)))[0]
    assert got == pytest.approx(2.0 * math.cos(math.radians(5)) - 0.3)
    # behind the robot: in the way only when reversing (the tail is 0.3 m back too)
    assert math.isinf(sight.free_m(POSE, _scan((180, 1.0)))[0])
    assert sight.free_m(POSE, _scan((180, 1.0)), math.pi)[0] == pytest.approx(0.7)
    # sideways (a holonomic robot), the lead is the half width
    assert sight.free_m(POSE, _scan((90, 1.0)), math.pi / 2)[0] == pytest.approx(0.8)


def test_time_to_contact_straight_on_the_spot_and_away():
    sight = _sight()  # margin 0.12 m, horizon 1.2 s in 8 steps of 0.15 s
    ahead = _scan((0, 1.0))
    # at 0.5 m/s the nose + margin (0.42 m) reaches x = 1 after 0.58 m: 1.16 s -> sampled 1.2
    t = sight.time_to_contact_s(np.array([[0.5, 0.0, 0.0]]), POSE, ahead)
    assert t[0] == pytest.approx(1.2)
    # at 1 m/s: 0.58 s -> 0.6
    assert sight.time_to_contact_s(np.array([[1.0, 0.0, 0.0]]), POSE, ahead)[0] == pytest.approx(
        0.6
    )
    # backing away from it: never
    assert math.isinf(sight.time_to_contact_s(np.array([[-0.5, 0.0, 0.0]]), POSE, ahead)[0])
    # a robot 0.27 m to the left (inside the margin, clear of the body): spinning sweeps the
    # corners (0.36 m from the centre) through it; driving straight on does not touch it
    side = _scan((90, 0.27))
    assert math.isfinite(sight.time_to_contact_s(np.array([[0.0, 0.0, 1.0]]), POSE, side)[0])
    assert math.isinf(sight.time_to_contact_s(np.array([[0.3, 0.0, 0.0]]), POSE, side)[0])


@settings(max_examples=60, deadline=None)
@given(
    vx=st.floats(-1.0, 1.0),
    vy=st.floats(-1.0, 1.0),
    w=st.floats(-2.0, 2.0),
    deg=st.integers(0, 359),
    rng=st.floats(0.4, 5.0),
)
def test_limit_only_scales_a_twist_down(vx, vy, w, deg, rng):
    sight = _sight()
    twist = np.array([[vx, vy, w]])
    out = sight.limit(twist, POSE, _scan((deg, rng)))
    f = np.linalg.norm(out) / max(np.linalg.norm(twist), 1e-300)
    assert 0.0 <= f <= 1.0 + 1e-12
    # the same direction (a path keeps its curvature): out is f * twist
    assert np.allclose(out, f * twist, atol=1e-12)


def test_no_robot_in_sight_leaves_every_command_alone():
    sight = _sight()
    twist = np.array([[0.7, 0.1, -0.4]])
    assert np.array_equal(sight.limit(twist, POSE, _scan()), twist)


class _Fixed:
    def __init__(self, cmd):
        self.cmd = cmd
        self.state_name = "go"

    def step(self, obs):
        return self.cmd


def _obs(ranges: np.ndarray, model=None, mode: str = "inverse"):
    from agvsim.control.api import LaserScan, Observation

    scan = LaserScan(0.0, 0.0, math.radians(1.0), 0.0, 10.0, ranges[0])
    zero = np.zeros(3)
    return Observation(0.0, "r", {"lidar": scan}, zero, np.zeros(2), False, zero, {}, model, mode)


def test_keep_clear_stops_a_behaviour_short_of_a_robot_and_keeps_its_state():
    sight = _sight()
    near = _obs(_scan((0, 0.65)))  # contact at 0.5 m/s in 0.46 s: under stop (0.4) + slow
    slowed = KeepClear(_Fixed(Twist(0.5, 0.0, 0.2)), sight).step(near)
    assert 0.0 <= slowed.vx < 0.5 and slowed.omega == pytest.approx(0.2 * slowed.vx / 0.5)
    stopped = KeepClear(_Fixed(Twist(0.5, 0.0, 0.0)), sight).step(_obs(_scan((0, 0.5))))
    assert stopped == Twist(0.0, 0.0, 0.0)
    free = KeepClear(_Fixed(Twist(0.5, 0.0, 0.0)), sight).step(_obs(_scan((0, 5.0))))
    assert free == Twist(0.5, 0.0, 0.0)
    assert KeepClear(_Fixed(Twist()), sight).state_name == "go"


def test_keep_clear_scales_wheel_speeds_and_keeps_the_steering():
    from agvsim.kinematics.ackermann import Ackermann

    car = Ackermann(wheel_radius_m=0.1, wheelbase_m=0.45, half_track_m=0.18)
    cmd = WheelCommand((5.0, 5.0), 0.2)
    out = KeepClear(_Fixed(cmd), _sight()).step(_obs(_scan((0, 0.5)), car, "forward"))
    assert out.steering == 0.2 and out.speeds == (0.0, 0.0)


def _head_on(controller: dict, model: str = "differential") -> dict:
    """Two robots 6 m apart in a 3 m wide corridor, facing each other."""
    picture = "\n".join(["#" * 14] + ["#" + "." * 12 + "#"] * 3 + ["#" * 14])
    robot = {
        "model": model,
        "sensors": [{"type": "rangers", "range_max_m": 1.5}, {"type": "lidar"}],
    }
    return {
        "name": "head on",
        "seed": 0,
        "dt_s": 0.02,
        "world": {"picture": picture, "cell_size_m": 1.0},
        "robots": [
            {
                **robot,
                "name": "west",
                "pose": {"x_m": -3.0, "y_m": 0.0, "theta_deg": 0},
                "controller": controller,
            },
            {
                **robot,
                "name": "east",
                "pose": {"x_m": 3.0, "y_m": 0.0, "theta_deg": 180},
                "controller": controller,
            },
        ],
    }


@pytest.mark.parametrize("model", ["differential", "mecanum", "ackermann"])
def test_avoiding_robots_meeting_head_on_turn_away_and_drive_on(model, one_numba_thread):
    data = _head_on({"type": "avoid", "trigger_m": 1.0, "speed_m_s": 0.6}, model)
    sim = build(parse_scenario(data, "head on"))
    sim.run(60.0)
    assert sim.state.robot_collisions.tolist() == [0, 0]
    assert np.all(sim.state.distance_m > 15.0)  # they kept going


def test_goal_seekers_whose_paths_cross_stop_short_of_each_other(one_numba_thread):
    # each heads for the other's start: straight through the other robot
    goals = {"west": 3.0, "east": -3.0}
    data = _head_on({})
    for r in data["robots"]:
        r["controller"] = {"type": "goto_goal", "goal_x_m": goals[r["name"]], "goal_y_m": 0.0}
    sim = build(parse_scenario(data, "head on"))
    sim.run(20.0)
    assert sim.state.robot_collisions.tolist() == [0, 0]
    gap = abs(sim.state.poses[1, 0] - sim.state.poses[0, 0]) - 0.6  # nose to nose
    assert 0.0 < gap < 1.5  # they came close, and stopped before touching


def test_without_a_lidar_a_behaviour_is_not_wrapped():
    data = _head_on({"type": "goto_goal", "goal_x_m": 0.0, "goal_y_m": 0.0})
    for r in data["robots"]:
        r["sensors"] = [{"type": "rangers"}]
    sim = build(parse_scenario(data, "head on"))
    assert not any(isinstance(b.controller, KeepClear) for b in sim.bindings)
    goal = {"type": "goto_goal", "goal_x_m": 0.0, "goal_y_m": 0.0}
    with_lidar = build(parse_scenario(_head_on(goal), "head on"))
    assert all(isinstance(b.controller, KeepClear) for b in with_lidar.bindings)


def test_several_room_queries_in_one_pass_give_each_query_alone():
    """``free_m_many`` (obstacle avoidance's four questions in one kernel call) answers each
    ``(direction, walls_margin)`` exactly as ``free_m`` asked alone: a wall east at 4 m,
    robots north and west, two robots at once."""
    static = StaticMap.of(walled_room(10, 10))
    sight = RobotSight(static, "lidar", ANGLES, Footprint(0.3, 0.2))
    poses = np.array([[5.0, 5.0, 0.0], [3.0, 4.0, 0.5]])
    scan = np.vstack([_scan((0, 4.0), (90, 2.0), (180, 1.5)), _scan((3, 1.0), (200, 0.9))])
    queries = [
        (0.0, None),
        (0.0, 0.03),
        (math.pi, None),
        (math.pi, 0.03),
        (np.array([0.3, -1.0]), None),
    ]
    many = sight.free_m_many(poses, scan, queries)
    assert many.shape == (5, 2)
    for q, (direction, margin) in enumerate(queries):
        alone = sight.free_m(poses, scan, direction, walls_margin_m=margin)
        np.testing.assert_array_equal(many[q], alone)
    # robot 0: nothing but the wall ahead, which counts only with a walls margin; the robot
    # 1.5 m behind it is 1.5 - 0.3 (the tail) away when reversing
    assert math.isinf(many[0, 0]) and many[1, 0] == pytest.approx(4.0 - 0.3)
    assert many[2, 0] == pytest.approx(1.5 - 0.3)
