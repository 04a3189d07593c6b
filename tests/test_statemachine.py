"""State machines (agvsim.control.statemachine) and their diagrams (agvsim.control.statechart):
step semantics, timers, angle helpers, validation, exports, and the example charts driving
robots in a simulation and in a scenario run."""

from __future__ import annotations

import csv
import importlib.util
import math
from pathlib import Path

import numba
import numpy as np
import pytest

from agvsim.control.api import Observation, Twist
from agvsim.control.statechart import resolve, to_dot, to_mermaid
from agvsim.control.statemachine import (
    ActionError,
    ChartError,
    Context,
    StateMachine,
    after,
    before,
    near,
    reached,
    wrap,
)
from agvsim.kinematics import DifferentialDrive
from agvsim.runner import run_scenario
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.engine import Binding, ControllerError, Simulation
from agvsim.sim.spec import OdometrySpec, RobotSpec, World
from agvsim.world.grid import OccupancyGrid

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


@pytest.fixture
def one_thread():
    """The ray-casting kernel is parallel over sensors; with one sensor, threads only cost."""
    before_n = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before_n)


def obs(t: float = 0.0, name: str = "r", heading: float = 0.0, bump: bool = False) -> Observation:
    pose = np.array([0.0, 0.0, heading])
    return Observation(t, name, {}, pose.copy(), np.zeros(2), bump, pose, dt_s=0.02)


def load_example(name: str):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def recorder(log: list[str], text: str, result=None):
    def action(ctx):
        log.append(text)
        return result

    action.__name__ = text.replace(" ", "_")
    return action


# ------------------------------------------------------------------------------ semantics
def test_lower_priority_first_and_ties_in_declaration_order():
    sm = StateMachine("p", initial="a")
    for s in "abcd":
        sm.add_state(s)
    sm.transition("a", "b", guard=lambda c: True, priority=2)
    sm.transition("a", "c", guard=lambda c: True, priority=1)
    sm.transition("a", "d", guard=lambda c: True, priority=1)
    sm.step(obs(0.0))
    assert sm.state_name == "a"  # the first step only enters the initial state
    sm.step(obs(0.02))
    assert sm.state_name == "c"
    assert [t.target for t in sm.leaving("a")] == ["c", "d", "b"]


def test_guards_decide_and_at_most_one_transition_per_step():
    sm = StateMachine("g", initial="a")
    sm.add_state("a")
    sm.add_state("b")
    sm.add_state("c")
    sm.transition("a", "b", guard=lambda c: c.t >= 0.1)
    sm.transition("b", "c", guard=lambda c: True)  # true at once, but only next step
    seen = []
    for k in range(8):
        sm.step(obs(k * 0.02))
        seen.append(sm.state_name)
    assert seen == ["a"] * 5 + ["b", "c", "c"]


def test_entry_during_exit_and_transition_action_order():
    log: list[str] = []
    sm = StateMachine("order", initial="a")
    sm.add_state(
        "a",
        entry=recorder(log, "entry a"),
        during=recorder(log, "during a", Twist(1.0)),
        exit=recorder(log, "exit a"),
    )
    sm.add_state("b", entry=recorder(log, "entry b"), during=recorder(log, "during b", Twist(2.0)))
    sm.transition("a", "b", guard=lambda c: c.t > 0.03, action=recorder(log, "action a->b"))
    assert sm.step(obs(0.0)) == Twist(1.0)
    assert log == ["entry a", "during a"]
    log.clear()
    sm.step(obs(0.02))
    assert log == ["during a"]
    log.clear()
    assert sm.step(obs(0.04)) == Twist(2.0)
    assert log == ["exit a", "action a->b", "entry b", "during b"]


def test_none_or_no_during_action_holds_the_previous_command():
    sm = StateMachine("hold", initial="quiet")
    sm.add_state("quiet", during=lambda c: None)  # nothing yet: a stop
    sm.add_state("go", during=lambda c: Twist(0.3, 0.0, 0.1))
    sm.add_state("coast")  # no during action: holds the last command
    sm.transition("quiet", "go", guard=lambda c: c.t >= 0.02)
    sm.transition("go", "coast", guard=lambda c: c.t >= 0.04)
    cmds = [sm.step(obs(k * 0.02)) for k in range(4)]
    assert cmds == [Twist(), Twist(0.3, 0.0, 0.1), Twist(0.3, 0.0, 0.1), Twist(0.3, 0.0, 0.1)]
    assert sm.state_name == "coast"


def test_events_fire_their_transition_and_are_consumed_at_the_next_step():
    sm = StateMachine("ev", initial="a")
    sm.add_state("a")
    sm.add_state("b")
    sm.transition("a", "b", event="go")
    sm.transition("b", "a", guard=lambda c: True)
    sm.step(obs(0.0))
    sm.step(obs(0.02))
    assert sm.state_name == "a"  # no event: no transition
    sm.send("go")
    sm.step(obs(0.04))
    assert sm.state_name == "b"
    sm.step(obs(0.06))
    assert sm.state_name == "a"
    sm.step(obs(0.08))
    assert sm.state_name == "a"  # "go" was used once
    sm.send("go")  # sent twice before one step: both are this step's events, both used up
    sm.send("go")
    sm.step(obs(0.10))
    assert sm.state_name == "b"
    sm.send("go")  # pending while in b, where nothing waits for it: consumed there
    sm.step(obs(0.12))
    assert sm.state_name == "a"
    sm.step(obs(0.14))
    assert sm.state_name == "a"
    with pytest.raises(ChartError, match=r"no transition waits for event 'goo'; did you mean 'go'"):
        sm.send("goo")


def test_an_event_sent_by_an_action_is_seen_at_the_next_step():
    sm = StateMachine("ev", initial="a")
    sm.add_state("a", during=lambda c: c.send("tick") if c.t >= 0.04 else None)
    sm.add_state("b")
    sm.transition("a", "b", event="tick")
    states = []
    for k in range(5):
        sm.step(obs(k * 0.02))
        states.append(sm.state_name)
    assert states == ["a", "a", "a", "b", "b"]  # sent at t = 0.04, fired at t = 0.06


def test_after_fires_at_the_first_step_two_seconds_in_despite_float_time():
    """50 Hz time accumulated by repeated addition: entered at t = 2.08 (step 104), the step
    two seconds later sees t - t_entry = 1.9999999999999996, and must fire."""
    fired = []
    sm = StateMachine("timer", initial="idle")
    sm.add_state("idle")
    sm.add_state("wait")
    sm.add_state("done")
    sm.transition("idle", "wait", guard=lambda c: c.t > 2.07)
    sm.transition("wait", "done", guard=after(2.0), action=lambda c: fired.append(c.time_in_state))
    t, log = 0.0, []
    for _ in range(260):
        t += 0.02
        sm.step(obs(t))
        log.append((t, sm.state_name))
    entered = next(k for k, (_, s) in enumerate(log) if s == "wait")
    done = next(k for k, (_, s) in enumerate(log) if s == "done")
    assert done - entered == 100  # 2.00 s at 50 Hz: not at 1.98 s, not a step late
    assert fired == [log[done][0] - log[entered][0]] and fired[0] < 2.0


def test_before_and_ctx_timers():
    seen = []
    sm = StateMachine("t", initial="a")
    sm.add_state("a", during=lambda c: seen.append((c.before(0.06), c.after(0.06))))
    for k in range(5):
        sm.step(obs(k * 0.02))
    assert seen == [(True, False)] * 3 + [(False, True)] * 2
    assert before(0.06).__name__ == "before(0.06 s)"


def test_reached_near_and_wrap_across_the_seam():
    assert reached(math.pi - 0.004, -math.pi + 0.004, 0.01)  # 0.008 rad apart across +-pi
    assert not reached(3.1, -3.1, 0.01)
    assert reached(-math.pi, math.pi, 1e-12)
    assert wrap(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap(-math.pi) == math.pi and wrap(math.pi) == math.pi
    assert near(0.799, 0.8, 0.002) and not near(0.79, 0.8, 0.002)
    # the thesis's trap: 90 deg turns in 0.02 rad steps never hit the target exactly
    heading, target = 0.0, -math.pi / 2
    hits = reached_hits = 0
    while heading > -2.0:
        heading -= 0.0203
        hits += heading == target
        reached_hits += reached(heading, target, 0.011)
    assert hits == 0 and reached_hits == 1


# ------------------------------------------------------------------------------ validation
def test_validation_errors_name_the_fault():
    sm = StateMachine("v")
    with pytest.raises(ChartError, match="has no states"):
        sm.validate()
    sm.add_state("drive")
    with pytest.raises(
        ChartError, match=r"'v' has no initial state; pass initial=\.\.\. \(drive\)"
    ):
        sm.step(obs())
    sm.initial = "drve"
    with pytest.raises(ChartError, match=r"initial state 'drve' is not a state; did you mean"):
        sm.validate()
    sm.initial = "drive"
    sm.add_state("turn")
    sm.transition("drive", "trun")
    with pytest.raises(ChartError, match=r"unknown target state 'trun'; did you mean 'turn'"):
        sm.reset()
    with pytest.raises(ChartError, match="already has a during action"):
        sm.add_state("turn", during=lambda c: None)
        sm.add_state("turn", during=lambda c: None)
    with pytest.raises(ChartError, match="guard must be callable"):
        sm.transition("drive", "turn", guard=0.8)
    with pytest.raises(ChartError, match="priority must be an int"):
        sm.transition("drive", "turn", priority=1.5)
    with pytest.raises(ChartError, match="pose_source"):
        StateMachine("x", "a", pose_source="gps")


def test_one_machine_drives_one_robot_and_copy_gives_a_fresh_one():
    sm = StateMachine("c", initial="a", data={"count": 0})

    @sm.state("a")
    def count(ctx):
        ctx.vars["count"] += 1
        return Twist()

    sm.step(obs(0.0, "r1"))
    with pytest.raises(ChartError, match=r"drives robot 'r1' .* one machine drives one robot"):
        sm.step(obs(0.0, "r2"))
    other = sm.copy()
    other.step(obs(0.0, "r2"))
    assert sm.vars == {"count": 1} and other.vars == {"count": 1}
    sm.reset()
    assert sm.vars == {"count": 0}
    sm.step(obs(0.0, "r2"))  # reset forgets the robot


def test_a_failing_action_names_chart_state_and_function():
    sm = StateMachine("boom", initial="a")

    @sm.state("a")
    def divide(ctx):
        return 1 / 0

    with pytest.raises(ActionError, match=r"chart 'boom', state 'a', during action divide: Zero"):
        sm.step(obs())


def test_inputs_are_computed_once_per_step():
    calls = []
    sm = StateMachine("in", initial="a")

    @sm.input
    def front(ctx):
        calls.append(ctx.t)
        return 0.5

    sm.add_state("a", during=lambda c: Twist(c.front + c.front))
    sm.add_state("b")
    sm.transition("a", "b", guard=lambda c: c.front < 0.4)
    assert sm.step(obs(0.0)) == Twist(1.0)
    sm.step(obs(0.02))
    assert calls == [0.0, 0.02]

    def heading(ctx):
        return 0.0

    with pytest.raises(ChartError, match=r"ctx.heading exists; rename the input"):
        sm.input(heading)
    with pytest.raises(AttributeError, match=r"has no input 'frnt'; did you mean 'front'"):
        Context(sm, obs()).frnt  # noqa: B018


# ------------------------------------------------------------------------------ diagrams
def chart() -> StateMachine:
    sm = StateMachine("demo", initial="drive")

    @sm.state("drive")
    def go(ctx):
        return Twist(0.5)

    def aim(ctx):
        pass

    def bumped(ctx):
        return ctx.obs.bump

    sm.add_state("turn right")
    sm.transition("drive", "turn right", guard=lambda c: False, label="front < 0.8 m", priority=1)
    sm.transition("drive", "turn right", guard=bumped, action=aim)
    sm.transition("turn right", "drive", event="done")
    return sm


def test_mermaid_lists_initial_state_actions_and_labelled_transitions():
    text = to_mermaid(chart())
    lines = text.splitlines()
    assert lines[0] == "stateDiagram-v2"
    assert '    state "turn right" as s1' in lines
    assert "    [*] --> drive" in lines
    assert "    drive : during / go" in lines
    assert "    drive --> s1 : (1) [bumped] / aim" in lines
    assert "    drive --> s1 : (2) [front < 0.8 m]" in lines
    assert "    s1 --> drive : (1) done" in lines


def test_dot_is_a_digraph_with_the_same_transitions():
    text = to_dot(chart())
    assert text.startswith('digraph "demo" {')
    assert '    __start -> "drive";' in text
    assert '    "drive" [label="drive\\nduring / go"];' in text
    assert '    "drive" -> "turn right" [label="(2) [front < 0.8 m]"];' in text
    assert '    "turn right" -> "drive" [label="(1) done"];' in text
    assert text.rstrip().endswith("}")


def test_resolve_builtin_files_and_errors(tmp_path):
    avoid = resolve("avoid")
    assert {s.name for s in avoid.states} == {"drive", "turn_right", "reverse", "back_off"}
    assert "drive --> turn_right : (2) [front < 0.8 m] / aim_right" in to_mermaid(avoid)
    assert resolve(str(EXAMPLES / "avoid_statemachine.py")).name == "avoid"  # default name
    assert resolve(f"{EXAMPLES / 'square_path.py'}:build").name == "square"  # a factory
    (tmp_path / "mine.py").write_text(
        "from agvsim.control.statemachine import StateMachine\n"
        "chart = StateMachine('x', 'a')\n"
        "def make():\n    return chart\n"
        "def step(obs):\n    return (0, 0, 0)\n"
        "speed = 3\n"
    )
    mine = tmp_path / "mine.py"
    with pytest.raises(
        ChartError, match=r"mine.py defines no 'chrt'; it has state machines: chart"
    ):
        resolve(f"{mine}:chrt")
    with pytest.raises(ChartError, match=r"mine.py:step needs arguments.*functions or .*: make"):
        resolve(f"{mine}:step")
    with pytest.raises(ChartError, match=r"mine.py:speed is a int, not a state machine"):
        resolve(f"{mine}:speed")
    with pytest.raises(ChartError, match="no such file"):
        resolve(f"{tmp_path / 'nope.py'}:chart")
    with pytest.raises(ChartError, match=r"neither a built-in chart \(avoid\)"):
        resolve("avoidance")


# ------------------------------------------------------------------------------ in simulation
MAZE = [
    "##########",
    "#........#",
    "#........#",
    "#..##....#",
    "#..##....#",
    "#......#.#",
    "#......#.#",
    "#........#",
    "#........#",
    "##########",
]


@pytest.mark.parametrize("which", ["example", "builtin"])
def test_avoid_chart_keeps_a_differential_robot_off_the_walls(which, one_thread):
    grid = OccupancyGrid.from_matrix([[c == "#" for c in row] for row in MAZE])
    sm = load_example("avoid_statemachine").controller if which == "example" else resolve("avoid")
    rangers = RangeSensorSpec.thesis_rangers(1.5, rate_hz=50.0)
    robot = RobotSpec(
        "diff", DifferentialDrive(), initial_pose=(-3.5, -2.5, 0.3), sensors=(rangers,),
        odometry=OdometrySpec(0.0),
    )  # fmt: skip
    sim = Simulation(World(grid), [robot], [Binding(sm, (0,))])
    states = set()
    for _ in range(3000):  # 60 s at 50 Hz
        sim.step()
        states.add(sim.active_states()[0])
    assert sim.state.wall_collisions[0] == 0
    assert sim.state.distance_m[0] > 15.0
    assert {"drive", "turn_right"} <= states


def test_square_path_comes_back_to_its_start():
    sm = load_example("square_path").controller
    robot = RobotSpec("sq", DifferentialDrive(), odometry=OdometrySpec(0.0))
    grid = OccupancyGrid.from_matrix(np.pad(np.zeros((6, 6)), 1, constant_values=1))
    sim = Simulation(World(grid), [robot], [Binding(sm, (0,))])
    sim.run(20.0)
    np.testing.assert_allclose(sim.state.poses[0], [0.0, 0.0, -math.pi / 2], atol=1e-9)
    assert sm.state_name == "done" and sm.vars["sides_done"] == 4
    assert sim.state.distance_m[0] == pytest.approx(4.0)


def test_errors_inside_a_chart_reach_the_engine_with_robot_and_time():
    sm = StateMachine("bad", initial="a")
    sm.add_state("a", during=lambda c: Twist(0.1) if c.t < 0.5 else {}["missing"])
    robot = RobotSpec("bob", DifferentialDrive(), odometry=OdometrySpec(0.0))
    grid = OccupancyGrid.from_matrix(np.pad(np.zeros((4, 4)), 1, constant_values=1))
    sim = Simulation(World(grid), [robot], [Binding(sm, (0,))])
    with pytest.raises(ControllerError, match=r"'bob' failed at t=0\.500 s: chart 'bad', state"):
        sim.run(1.0)


SCENARIO = """
name: chart states
duration_s: 8
world:
  picture: |
    ########
    #......#
    #......#
    #......#
    #......#
    ########
robots:
  - name: twin1
    model: differential
    pose: {x_m: -1.5, y_m: 1.0, theta_deg: 0}
    body: {length_m: 0.5, width_m: 0.4}
    sensors: [{type: rangers, range_max_m: 1.5}]
    odometry: {wheel_noise_rel: 0.0}
    controller: {type: python, file: EXAMPLE, name: controller}
  - name: twin2
    model: differential
    pose: {x_m: 1.5, y_m: -1.0, theta_deg: 180}
    body: {length_m: 0.5, width_m: 0.4}
    sensors: [{type: rangers, range_max_m: 1.5}]
    odometry: {wheel_noise_rel: 0.0}
    controller: {type: python, file: EXAMPLE, name: controller}
"""


def test_state_column_of_a_scenario_run_shows_the_chart_states(tmp_path, one_thread):
    example = (EXAMPLES / "avoid_statemachine.py").as_posix()
    (tmp_path / "s.yaml").write_text(SCENARIO.replace("EXAMPLE", example))
    data = run_scenario(tmp_path / "s.yaml", tmp_path / "out", plot=False)
    assert data["run"]["status"] == "completed"
    with (tmp_path / "out" / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    for name in ("twin1", "twin2"):  # each robot got a machine of its own
        states = [r["state"] for r in rows if r["robot"] == name]
        assert states[0] == "drive" and "turn_right" in states
        assert set(states) <= {"drive", "turn_right", "back_off"}
