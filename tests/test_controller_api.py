"""Controller API: failing controllers, the stop_robot policy, what a robot may know, the state
column, and command_for in both modes."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from agvsim.control.api import ControlMode, Twist, WheelCommand, command_for
from agvsim.kinematics import Ackermann, DifferentialDrive
from agvsim.runner import run_scenario
from agvsim.sim.engine import Binding, ControllerError, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid


def arena() -> World:
    m = np.zeros((12, 12), dtype=int)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = 1
    return World(OccupancyGrid.from_matrix(m))


def robot(name, y, model=None, mode=ControlMode.INVERSE):
    return RobotSpec(
        name,
        model or DifferentialDrive(),
        mode=mode,
        initial_pose=(-3.0, y, 0.0),
        odometry=OdometrySpec(0.0),
    )


class Failing:
    state_name = "failing"

    def __init__(self, at_s: float, value=None):
        self.at_s, self.value = at_s, value

    def reset(self):
        pass

    def step(self, obs):
        if obs.t_s >= self.at_s:
            if self.value is None:
                raise ZeroDivisionError("division by zero in my controller")
            return self.value
        return Twist(0.5, 0.0, 0.0)


@pytest.mark.parametrize("bad", [None, (np.inf, 0.0, 0.0), (0.1, np.nan, 0.0)])
def test_stop_robot_policy_stops_only_the_failing_robot(bad):
    sim = Simulation(
        arena(),
        [robot("good", 2.0), robot("bad", -2.0)],
        [Binding(lambda o: Twist(0.5, 0.0, 0.0), (0,)), Binding(Failing(1.0, bad), (1,))],
        on_controller_error="stop_robot",
    )
    sim.run(3.0)
    x_good, x_bad = sim.state.poses[:, 0]
    assert x_good == pytest.approx(-3.0 + 0.5 * 3.0)
    assert x_bad == pytest.approx(-3.0 + 0.5 * 1.0)  # stopped where it failed
    assert sim.state.stopped.tolist() == [False, True]
    assert [e.robot for e in sim.errors] == ["bad"]
    assert sim.errors[0].t_s == pytest.approx(1.0)
    assert sim.active_states() == ["", "stopped"]


def test_stop_run_policy_raises_with_robot_and_time():
    sim = Simulation(arena(), [robot("bob", 0.0)], [Binding(Failing(0.5), (0,))])
    with pytest.raises(ControllerError, match=r"'bob' failed at t=0\.500 s: division by zero"):
        sim.run(2.0)


def test_knows_gives_only_the_named_robots_true_pose():
    seen = {}

    def look(obs):
        seen[obs.name] = dict(obs.others)
        return Twist()

    sim = Simulation(
        arena(),
        [robot("red", 2.0), robot("blue", -2.0), robot("green", 0.0)],
        [Binding(look, (i,)) for i in range(3)],
        knows={"red": ["blue"]},
    )
    sim.step()
    assert set(seen["red"]) == {"blue"} and seen["blue"] == {} and seen["green"] == {}
    np.testing.assert_allclose(seen["red"]["blue"], [-3.0, -2.0, 0.0])
    with pytest.raises(ValueError, match="unknown robot"):
        Simulation(arena(), [robot("red", 0.0)], knows={"red": ["nobody"]})


def test_command_for_matches_each_mode():
    sim = Simulation(
        arena(), [robot("inv", 2.0), robot("fwd", -2.0, Ackermann(), ControlMode.FORWARD)]
    )
    inv, fwd = sim.observation(0), sim.observation(1)
    assert command_for(inv, 0.4, 0.0, 0.2) == Twist(0.4, 0.0, 0.2)
    cmd = command_for(fwd, 0.5, 0.0, 0.5)  # R = 1 m: rear wheels (v -/+ w l)/r, delta atan(L/R)
    assert isinstance(cmd, WheelCommand)
    np.testing.assert_allclose(cmd.speeds, [(0.5 - 0.5 * 0.2) / 0.1, (0.5 + 0.5 * 0.2) / 0.1])
    assert cmd.steering == pytest.approx(np.arctan(0.5 / 1.0))


SCENARIO = """
name: states
duration_s: 2
on_controller_error: stop_robot
world: {picture: "######\\n#....#\\n#....#\\n#....#\\n######", cell_size_m: 2.0}
robots:
  - {name: a, model: differential, pose: {x_m: -2.0, y_m: 1.0},
     controller: {type: python, file: ctrl.py, name: Named}}
  - {name: b, model: differential, pose: {x_m: -2.0, y_m: -1.0},
     controller: {type: python, file: ctrl.py, name: broken}}
"""

CONTROLLER = """
class Named:
    def __init__(self):
        self.state_name = "waiting"
    def reset(self):
        self.state_name = "waiting"
    def step(self, obs):
        self.state_name = "going" if obs.t_s >= 1.0 else "waiting"
        return (0.2, 0.0, 0.0) if obs.t_s >= 1.0 else (0.0, 0.0, 0.0)

def broken(obs):
    if obs.t_s >= 0.5:
        return (float("nan"), 0.0, 0.0)
    return (0.1, 0.0, 0.0)
"""


def test_state_column_and_errors_in_outputs(tmp_path):
    (tmp_path / "ctrl.py").write_text(CONTROLLER)
    (tmp_path / "s.yaml").write_text(SCENARIO)
    data = run_scenario(tmp_path / "s.yaml", tmp_path / "out", plot=False)
    assert data["run"]["status"] == "completed_with_controller_errors"
    errs = data["run"]["controller_errors"]
    assert errs[0]["robot"] == "b" and errs[0]["t_s"] == pytest.approx(0.5)
    assert "finite" in errs[0]["error"]
    with (tmp_path / "out" / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    a_states = [r["state"] for r in rows if r["robot"] == "a"]
    assert a_states[1] == "waiting" and a_states[-1] == "going"
    assert [r["state"] for r in rows if r["robot"] == "b"][-1] == "stopped"
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [r["stopped_by_error"] for r in summary["robots"]] == [False, True]
