"""The app's Session split into parts: run control and pacing, keyboard driving, editing as
functions of the config, the panel's immutable snapshots, and the rebuild that carries every
robot row over."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_app_session import ROOM

from agvsim.app import editing
from agvsim.app.keyboard import Keyboard, UnknownKey
from agvsim.app.run_control import RunControl
from agvsim.app.session import Session
from agvsim.scenario import parse_scenario


def two_robots() -> Session:
    cfg = {
        "name": "room",
        "world": {"picture": ROOM},
        "robots": [
            {
                "name": "car",
                "model": "ackermann",
                "pose": {"x_m": -2.0, "y_m": -1.5, "theta_deg": 0.0},
                "controller": {
                    "type": "script",
                    "steps": [{"duration_s": 100, "twist": [0.3, 0, 0.4]}],
                },
            },
            {
                "name": "diff",
                "model": "differential",
                "pose": {"x_m": 2.0, "y_m": 1.5, "theta_deg": 180.0},
                "knows": ["car"],
                "controller": {"type": "idle"},
            },
        ],
    }
    return Session(parse_scenario(cfg), "test")


def test_pacing_banks_wall_time_at_the_speed_and_never_more_than_a_quarter_second():
    run, calls = RunControl(), []

    def step() -> bool:
        calls.append(1)
        return True

    assert run.advance(0.02, 1.0, step, 10.0) == 0  # paused: nothing
    run.play()
    # real time, 0.1 s of wall clock at dt 0.02 s: 5 steps, nothing left over
    assert run.advance(0.02, 0.1, step, 10.0) == 5
    assert run.budget_s == pytest.approx(0.0, abs=1e-12)
    # a 3 s stall banks only 0.25 s: 12 steps (12 * 0.02 = 0.24, 0.01 s left)
    assert run.advance(0.02, 3.0, step, 10.0) == 12
    assert run.budget_s == pytest.approx(0.01, abs=1e-12)
    run.set_speed("x10")  # a new speed starts from an empty bank
    assert run.budget_s == 0.0
    assert run.advance(0.02, 0.01, step, 10.0) == 5  # 0.1 simulated s
    run.failed("boom")
    assert (run.playing, run.error) == (False, "boom")
    run.play()
    assert run.error is None


def test_a_failing_step_ends_the_advance():
    run = RunControl()
    run.play()
    assert run.advance(0.02, 0.2, lambda: False, 10.0) == 0


def test_keys_add_up_clip_at_the_limits_and_space_stops():
    kb = Keyboard()
    assert kb.key("ArrowUp") == (0.1, 0.0, 0.0)
    assert kb.key("w") == (0.2, 0.0, 0.0)
    assert kb.key("q") == (0.2, 0.1, 0.0)
    for _ in range(20):
        kb.key("left")
    assert kb.twist[2] == 3.0  # 20 * 0.25 clipped at 3 rad/s
    assert kb.key("space") == (0.0, 0.0, 0.0)
    with pytest.raises(UnknownKey, match="unknown key 'z'"):
        kb.key("z")


def test_keyboard_swaps_the_controller_and_gives_it_back():
    robots = [{"name": "a", "controller": {"type": "avoid"}}, {"name": "b"}]
    kb = Keyboard()
    kb.swap(robots, "a")
    kb.driving("a")
    assert robots[0]["controller"]["type"] == "teleop"
    assert kb.saved_controller == {"type": "avoid"}
    kb.swap(robots, "b")  # a gets its own back, b (no controller given) drives by keys
    kb.driving("b")
    assert robots[0]["controller"] == {"type": "avoid"}
    assert robots[1]["controller"]["type"] == "teleop" and kb.saved_controller == {"type": "idle"}


def test_editing_functions_leave_the_config_they_read_alone():
    cfg = {"robots": [{"name": "a", "knows": ["b"]}, {"name": "b"}]}
    before = repr(cfg)
    added, name = editing.with_new_robot(cfg, "mecanum", 1.0, 2.0, 90.0)
    assert name == "mecanum_1"
    assert added["robots"][-1]["pose"] == {"x_m": 1.0, "y_m": 2.0, "theta_deg": 90.0}
    assert editing.with_new_robot(added, "mecanum", 0, 0, 0)[1] == "mecanum_2"
    fewer = editing.without_robot(cfg, "b")
    assert fewer["robots"] == [{"name": "a", "knows": []}]
    with pytest.raises(editing.EditError, match="at least one robot"):
        editing.without_robot(fewer, "a")
    with pytest.raises(editing.EditError, match="no robot named 'c'"):
        editing.with_robot(cfg, "c", {})
    assert repr(cfg) == before


def test_the_panel_view_is_a_copy_taken_under_the_lock():
    s = two_robots()
    s.step(10)
    view = s.view("car")
    assert view.robot_names == ("car", "diff") and view.t_s == pytest.approx(0.2)
    robot = view.robot
    assert robot is not None and robot.model_name == "Ackermann"
    pose = robot.pose.copy()
    np.testing.assert_array_equal(pose, s.sim.state.poses[0])
    s.step(10)  # the run goes on: the view stays as it was
    np.testing.assert_array_equal(robot.pose, pose)
    assert not np.array_equal(s.sim.state.poses[0], pose)
    # plots sample every round(0.05 / 0.02) = 2 steps: t = 0, 0.04, ..., 0.2
    np.testing.assert_allclose(robot.history_t, [0.0, 0.04, 0.08, 0.12, 0.16, 0.2], atol=1e-12)
    with pytest.raises(dataclasses.FrozenInstanceError):
        view.t_s = 1.0  # type: ignore[misc]
    assert s.view("nobody").robot is None


def test_apply_carries_the_other_robots_steering_and_wheels_over():
    s = two_robots()
    s.step(50)
    st = s.sim.state
    steer, wheels, twist = st.steering[0], st.wheel_speeds[0].copy(), st.twists[0].copy()
    assert steer > 0.05  # the car is turning left
    s.apply_robot("diff", s.robot_config("diff"))  # rebuild; the car carries on
    st = s.sim.state
    assert st.steering[0] == steer
    np.testing.assert_array_equal(st.wheel_speeds[0], wheels)
    np.testing.assert_array_equal(st.twists[0], twist)
    assert st.poses[1].tolist() == pytest.approx([2.0, 1.5, np.pi])  # diff restarted
