"""Simulation engine: scripted motion against hand-worked values, collisions, sensors, rates,
odometry, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.control.api import ControlMode, Twist, WheelCommand
from agvsim.control.script import ScriptController, ScriptStep
from agvsim.kinematics import Ackermann, DifferentialDrive, Mecanum, Tricycle
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Binding, ControllerError, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid


def arena(n: int = 12, res: float = 1.0) -> World:
    m = np.zeros((n, n), dtype=int)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = 1
    return World(OccupancyGrid.from_matrix(m, res))


def robot(name="r", model=None, pose=(0.0, 0.0, 0.0), sensors=(), **kw) -> RobotSpec:
    return RobotSpec(
        name=name,
        model=model or DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25),
        initial_pose=pose,
        sensors=tuple(sensors),
        odometry=kw.pop("odometry", OdometrySpec(wheel_noise_rel=0.0)),
        **kw,
    )


def test_script_wheels_then_twist_matches_hand_worked_pose():
    # wheels 5, 5 rad/s with r = 0.1 for 2 s: straight 0.5 m/s * 2 s = 1.0 m east.
    # then twist (0.5, 0, 0.5) for 2 s: an arc of radius 1 m through 1 rad:
    # dx = R sin(1) = 0.841471, dy = R (1 - cos(1)) = 0.459698, theta = 1 rad.
    steps = [ScriptStep(2.0, wheels=(5.0, 5.0)), ScriptStep(2.0, twist=(0.5, 0.0, 0.5))]
    sim = Simulation(
        arena(),
        [robot(pose=(-3.0, -3.0, 0.0), mode=ControlMode.FORWARD)],
        [Binding(ScriptController(steps), (0,))],
    )
    sim.run(2.0)
    np.testing.assert_allclose(sim.state.poses[0], [-2.0, -3.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(sim.state.wheel_speeds[0, :2], [5.0, 5.0])
    sim.run(2.0)
    np.testing.assert_allclose(
        sim.state.poses[0], [-2.0 + np.sin(1.0), -3.0 + 1.0 - np.cos(1.0), 1.0], atol=1e-9
    )
    # inverse kinematics gave the wheels: phi_l = (0.5 - 0.5*0.25)/0.1, phi_r = (0.5 + 0.125)/0.1
    np.testing.assert_allclose(sim.state.wheel_speeds[0, :2], [3.75, 6.25])
    assert sim.state.distance_m[0] == pytest.approx(1.0 + 1.0, abs=1e-6)
    sim.run(1.0)  # the script is over: the robot stands still
    np.testing.assert_allclose(sim.state.twists[0], 0.0)


def test_full_circle_in_simulation_returns_to_start():
    # omega = 2 pi / 4 s; 200 steps of 0.02 s -> exactly one turn
    w = 2 * np.pi / 4.0
    sim = Simulation(
        arena(), [robot(pose=(0.0, -1.5, 0.0))], [Binding(lambda obs: Twist(0.5, 0.0, w), (0,))]
    )
    sim.run(4.0)
    np.testing.assert_allclose(sim.state.poses[0, :2], [0.0, -1.5], atol=1e-9)


def test_wall_stops_robot_without_tunnelling_at_top_speed():
    # one-cell wall column at x in [2, 2.05) on a 0.05 m grid; robot drives east at top speed
    res = 0.05
    m = np.zeros((80, 200), dtype=int)
    m[:, 120] = 1  # x = -5 + 120*0.05 = 1.0 .. 1.05
    world = World(OccupancyGrid.from_matrix(m, res))
    model = DifferentialDrive(wheel_radius_m=0.1, half_track_m=0.25, max_wheel_speed_rad_s=200.0)
    # 200 rad/s * 0.1 m = 20 m/s -> 0.4 m per step, 8 times the wall thickness
    sim = Simulation(
        world,
        [robot(model=model, pose=(-2.0, 0.0, 0.0))],
        [Binding(lambda obs: Twist(100.0, 0.0, 0.0), (0,))],
    )
    sim.run(1.0)
    x = sim.state.poses[0, 0]
    front = x + 0.3  # body half length
    assert front <= 1.0 + 1e-9, "the body crossed into the wall"
    assert front > 1.0 - 0.06, "the robot stopped too early"
    assert sim.state.bump[0]
    assert sim.state.collisions[0] == 1  # one collision event, not one per step in contact


def test_robots_bump_into_each_other_and_stop():
    sim = Simulation(
        arena(),
        [robot("a", pose=(-2.0, 0.0, 0.0)), robot("b", pose=(2.0, 0.0, np.pi))],
        [
            Binding(lambda obs: Twist(0.5, 0.0, 0.0), (0,)),
            Binding(lambda obs: Twist(0.5, 0.0, 0.0), (1,)),
        ],
    )
    sim.run(6.0)
    a, b = sim.state.poses[:, 0]
    assert b - a >= 0.6 - 1e-9  # bodies 0.6 m long never overlap
    assert b - a < 0.6 + 0.05
    assert sim.state.collisions.tolist() == [1, 1]


def test_lidar_sees_walls_and_other_robot_exactly():
    lidar = RangeSensorSpec.fan("lidar", 4, 2 * np.pi, 10.0, angle_min_rad=0.0, rate_hz=10.0)
    sim = Simulation(
        arena(),
        [
            robot("a", pose=(-2.0, 0.0, 0.0), sensors=[lidar]),
            robot("b", pose=(1.0, 0.0, np.pi / 2)),
        ],
    )
    r = sim.observation(0).scans["lidar"].ranges
    # east: robot b (rotated 90 deg: its 0.45 m width lies along x) face at x = 1 - 0.225
    # north/south: border walls at y = +-5; west: wall at x = -5
    np.testing.assert_allclose(r, [3.0 - 0.225, 5.0, 3.0, 5.0], atol=1e-9)


def test_rangers_hit_flag_and_inf_without_return():
    rangers = RangeSensorSpec.thesis_rangers(range_max_m=1.0, rate_hz=50.0)
    sim = Simulation(arena(), [robot(pose=(-4.2, 0.0, 0.0), sensors=[rangers])])
    scan = sim.observation(0).scans["rangers"]
    # front (east) free for > 1 m: inf; back (west) wall at x = -5: 0.8 m
    assert scan.ranges[0] == np.inf and not scan.hits[0]
    assert scan.ranges[2] == pytest.approx(0.8) and scan.hits[2]


def test_sensor_rates_follow_their_own_clock():
    fast = RangeSensorSpec.thesis_rangers(1.0, rate_hz=50.0)
    slow = RangeSensorSpec.fan("lidar", 8, 2 * np.pi, 5.0, rate_hz=10.0)
    sim = Simulation(
        arena(), [robot(sensors=[fast, slow])], [Binding(lambda obs: Twist(0.1, 0.0, 0.0), (0,))]
    )
    stamps = {"rangers": set(), "lidar": set()}
    for _ in range(50):
        sim.step()
        obs = sim.observation(0)
        for k in stamps:
            stamps[k].add(round(obs.scans[k].stamp_s, 6))
    assert len(stamps["rangers"]) == 50  # every 0.02 s step
    # the t = 0 scan is seen until the first 10 Hz scan at 0.1 s
    assert sorted(stamps["lidar"]) == pytest.approx([0.1 * k for k in range(0, 11)])


def _noisy_sim(seed: int) -> Simulation:
    lidar = RangeSensorSpec.thesis_lidar(noise_std_m=0.02, dropout_prob=0.05)
    return Simulation(
        arena(),
        [robot(pose=(0.0, 0.0, 0.3), sensors=[lidar], odometry=OdometrySpec(0.05, 0.01, 0.0))],
        [Binding(lambda obs: Twist(0.3, 0.0, 0.2), (0,))],
        seed=seed,
    )


def test_determinism_same_seed_identical_different_seed_differs():
    runs = []
    for seed in (7, 7, 8):
        sim = _noisy_sim(seed)
        sim.run(3.0)
        runs.append((sim.state.scans.copy(), sim.state.odom_poses.copy(), sim.state.poses.copy()))
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])
    assert not np.array_equal(runs[0][0], runs[2][0])
    assert not np.array_equal(runs[0][1], runs[2][1])
    # the ground truth does not depend on sensor or encoder noise
    assert np.array_equal(runs[0][2], runs[2][2])


def test_odometry_drifts_from_ground_truth_with_encoder_noise():
    sim = _noisy_sim(3)
    sim.run(5.0)
    err = np.hypot(*(sim.state.odom_poses[0, :2] - sim.state.poses[0, :2]))
    assert 1e-4 < err < 0.5


def test_lidar_noise_never_exceeds_max_range():
    sim = _noisy_sim(1)
    sim.run(1.0)
    r = sim.state.scans
    assert np.all((r <= 10.0) | np.isinf(r))


def test_mixed_fleet_forward_and_inverse_modes():
    cmds = {
        "diff": Twist(0.3, 0.0, 0.0),
        "tri": WheelCommand((3.0,), 0.0),  # front wheel 3 rad/s * 0.1 m = 0.3 m/s
        "ack": WheelCommand((3.0, 3.0), 0.0),
        "mec": Twist(0.0, 0.3, 0.0),  # sideways
    }
    robots = [
        robot("diff", pose=(-3.0, 3.0, 0.0)),
        robot("tri", Tricycle(), pose=(-3.0, 1.0, 0.0), mode=ControlMode.FORWARD),
        robot("ack", Ackermann(), pose=(-3.0, -1.0, 0.0), mode=ControlMode.FORWARD),
        robot("mec", Mecanum(), pose=(-3.0, -3.0, 0.0)),
    ]
    sim = Simulation(arena(), robots, [Binding(lambda o: cmds[o.name], (i,)) for i in range(4)])
    sim.run(1.0)
    np.testing.assert_allclose(sim.state.poses[:3, 0], -3.0 + 0.3, atol=1e-9)
    np.testing.assert_allclose(sim.state.poses[3, :2], [-3.0, -3.0 + 0.3], atol=1e-9)


def test_controller_error_names_robot_and_time():
    def bad(obs):
        if obs.t_s > 0.5:
            raise RuntimeError("boom")
        return Twist(0.1, 0.0, 0.0)

    sim = Simulation(arena(), [robot("alice")], [Binding(bad, (0,))])
    with pytest.raises(ControllerError, match=r"alice.*t=0\.5\d+ s.*boom"):
        sim.run(2.0)


def test_nan_command_is_refused_clearly():
    sim = Simulation(arena(), [robot("bob")], [Binding(lambda o: (np.nan, 0.0, 0.0), (0,))])
    with pytest.raises(ControllerError, match="bob.*finite"):
        sim.step()


def test_wall_and_robot_collisions_are_told_apart():
    # a drives into b (standing still) and stops; b never moves but is bumped into
    sim = Simulation(
        arena(),
        [robot("a", pose=(-2.0, 0.0, 0.0)), robot("b", pose=(0.0, 0.0, 0.0))],
        [
            Binding(lambda obs: Twist(0.5, 0.0, 0.0) if obs.name == "a" else Twist(), (0,)),
            Binding(lambda obs: Twist(), (1,)),
        ],
    )
    sim.run(5.0)
    st = sim.state
    assert st.robot_collisions.tolist() == [1, 1] and st.wall_collisions.tolist() == [0, 0]
    assert sim.state.poses[1, 0] == 0.0  # the one standing still was not moved
    assert 0.6 - 1e-9 <= st.poses[1, 0] - st.poses[0, 0] < 0.62
