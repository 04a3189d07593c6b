"""The one controller registry (agvsim.behaviours.BEHAVIOURS): every ``type`` of a scenario's
controller is registered once, validated by its config class and built through the same path;
batched types group the robots that share a config and a model kind."""

from __future__ import annotations

import typing
from dataclasses import dataclass

import numpy as np
import pytest

from agvsim.app.mask import controller_types
from agvsim.behaviours import BEHAVIOURS
from agvsim.config_base import StrictConfig, construct
from agvsim.control.avoid import ObstacleAvoidance
from agvsim.control.script import ScriptController
from agvsim.control.traffic import KeepClear
from agvsim.scenario import ScenarioError, build, parse_scenario
from agvsim.scenario_schema import ControllerConfig

ROOM = "\n".join(["###########"] + ["#.........#"] * 5 + ["###########"])
SCRIPT = {"type": "script", "steps": [{"duration_s": 1.0, "twist": [0.2, 0.0]}]}
AVOID = {"type": "avoid", "sensor": "lidar"}


def _scenario(*controllers: dict, model: str = "differential") -> dict:
    robots = [
        {
            "name": f"r{k}",
            "model": model,
            "pose": {"x_m": -4.0 + 2.0 * k, "y_m": 0.0, "theta_deg": 90},
            "sensors": [{"type": "lidar", "beams": 16}],
            "controller": c,
        }
        for k, c in enumerate(controllers)
    ]
    return {"world": {"picture": ROOM}, "robots": robots}


def test_the_schema_and_the_app_offer_exactly_the_registered_types():
    union = typing.get_args(typing.get_args(ControllerConfig)[0])
    tags = [typing.get_args(c.model_fields["type"].annotation)[0] for c in union]
    assert tags == list(BEHAVIOURS)
    assert {"script", "avoid", "python", "idle"} <= set(BEHAVIOURS)
    for tag, entry in BEHAVIOURS.items():
        assert entry.config.model_fields["type"].annotation == typing.Literal[tag]
        # a type builds one robot's controller, or a group's, or (idle) none at all
        assert not (entry.build and entry.build_group)
    assert controller_types() == [t for t in BEHAVIOURS if t != "python"]
    assert controller_types(allow_python=True) == list(BEHAVIOURS)


def test_robots_avoiding_with_one_sensor_are_one_batched_binding():
    """Avoidance robots reading the same sensor share one batch controller, each with its own
    trigger, speed and side clearance; another heading source makes another group."""
    other = {**AVOID, "trigger_m": 0.6, "speed_m_s": 0.3}
    by_odometry = {**AVOID, "heading_source": "odometry"}
    sim = build(parse_scenario(_scenario(AVOID, SCRIPT, AVOID, other, by_odometry)))
    shapes = [(type(b.controller).__name__, b.robots, b.batch) for b in sim.bindings]
    assert shapes == [
        ("ScriptController", (1,), False),  # one robot's controllers first, in robot order
        ("ObstacleAvoidance", (0, 2, 3), True),  # then the groups
        ("ObstacleAvoidance", (4,), True),
    ]
    avoid = sim.bindings[1].controller
    assert isinstance(avoid, ObstacleAvoidance) and avoid.sensor == "lidar"
    assert avoid.trigger_m.tolist() == [0.8, 0.8, 0.6]
    assert avoid.speed.tolist() == [0.5, 0.5, 0.3]
    assert avoid.side_clear.tolist() == pytest.approx([0.64, 0.64, 0.48])  # 0.8 x trigger
    assert sim.bindings[2].controller.heading_source == "odometry"
    assert isinstance(sim.bindings[0].controller, ScriptController)


def test_a_batch_of_avoiders_drives_each_robot_as_it_would_alone():
    """Three robots of different models and settings, batched in one controller, move
    exactly as when each has a controller of its own (each reads an identical copy of the
    lidar under a name of its own, which puts it in a group alone): the settings are each
    robot's, nothing of one robot's leaks into another's."""
    settings = [AVOID, {**AVOID, "speed_m_s": 0.8, "trigger_m": 0.5}, {**AVOID, "trigger_m": 1.0}]
    copies = [{"type": "lidar", "name": n, "beams": 16} for n in ("lidar", "copy1", "copy2")]
    runs = []
    for apart in (False, True):
        data = _scenario(*settings)
        models = ["differential", "mecanum", "omni3"]
        for k, (robot, model) in enumerate(zip(data["robots"], models, strict=True)):
            robot["model"], robot["sensors"] = model, copies
            robot["controller"] = {
                **robot["controller"],
                "sensor": copies[k if apart else 0]["name"],
            }
        sim = build(parse_scenario(data))
        for _ in range(400):
            sim.step()
        runs.append(sim)
    assert [b.robots for b in runs[0].bindings] == [(0, 1, 2)]
    assert [b.robots for b in runs[1].bindings] == [(0,), (1,), (2,)]
    np.testing.assert_array_equal(runs[0].state.poses, runs[1].state.poses)
    assert runs[0].state.distance_m.min() > 1.0  # they drove


def test_flags_of_a_type_reach_its_binding(tmp_path):
    (tmp_path / "mine.py").write_text("def controller(obs):\n    return (0.0, 0.0, 0.0)\n")
    python = {"type": "python", "file": "mine.py"}
    goal = {"type": "goto_goal", "goal_x_m": -2.0, "goal_y_m": 2.0}
    sim = build(parse_scenario(_scenario(python, goal, {"type": "teleop"})), base_dir=tmp_path)
    user, keep, teleop = sim.bindings
    assert (user.user_code, keep.user_code, teleop.user_code) == (True, False, False)
    assert isinstance(keep.controller, KeepClear)  # goto_goal stops short of robots it sees
    assert not isinstance(teleop.controller, KeepClear)  # the user drives a teleop robot


@pytest.mark.parametrize(
    "controller,expected",
    [
        (
            {"type": "avoid", "sensor": "lidr"},
            "robots[0] (r0).controller.sensor: the robot has no sensor 'lidr'; did you mean "
            "'lidar'? (allowed: lidar)",
        ),
        (
            {"type": "wall_follow", "sensor": "rangers"},
            "robots[0] (r0).controller.sensor: the robot has no sensor 'rangers' (it has lidar)",
        ),
        (
            {"type": "script", "steps": [{"duration_s": 1.0, "wheels": [1.0]}]},
            "robots[0] (r0).controller.steps: a differential robot has 2 driven wheel(s) "
            "['left', 'right'], got 1 speeds [1.0]",
        ),
        (
            {"type": "maze_solver", "goal_cell": [3, 3], "method": "tremaux", "sensor": "x"},
            "robots[0] (r0).controller: maze_solver (tremaux) needs the sensor 'x'; has ['lidar']",
        ),
    ],
)
def test_a_builder_refusal_names_the_robot_and_the_config_field(controller, expected):
    with pytest.raises(ScenarioError) as info:
        build(parse_scenario(_scenario(controller)))
    assert info.value.problems == [expected]


@dataclass
class _Core:
    speed_m_s: float
    turn_rad: float
    name: str = "core"


class _Cfg(StrictConfig):
    type: typing.Literal["core"] = "core"
    speed_m_s: float = 0.5
    turn_deg: float = 90.0
    name: str = "from config"


def test_construct_hands_fields_over_by_name_and_derived_values_win():
    cfg = _Cfg(speed_m_s=0.25)
    assert construct(_Core, cfg, turn_rad=1.5) == _Core(0.25, 1.5, "from config")
    assert construct(_Core, cfg, turn_rad=1.5, name="derived") == _Core(0.25, 1.5, "derived")
    with pytest.raises(TypeError):  # a derived value the class does not take is a bug
        construct(_Core, cfg, turn_rad=1.5, turn_deg=90.0)
