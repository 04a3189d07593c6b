"""agvsim: a fast, teachable simulator of AGVs (wheeled mobile robots).

The public API fits on one page:

    from agvsim import load_scenario, build
    sim = build(load_scenario("scenarios/thesis_maze_avoid.yaml"))
    sim.reset(seed=1)
    for _ in range(500):
        sim.step()
    sim.state.poses          # (N, 3) x, y, theta (world frame)
    sim.observation(0).scans # latest scans of robot 0 (LaserScan layout)
"""

__version__ = "0.1.0"

from agvsim.control.api import LaserScan, Observation, Twist, WheelCommand  # noqa: E402
from agvsim.scenario import Scenario, ScenarioError, build, load_scenario  # noqa: E402
from agvsim.sim.engine import Binding, ControllerError, Simulation  # noqa: E402
from agvsim.sim.spec import ControlMode, RobotSpec, World  # noqa: E402

__all__ = [
    "Binding",
    "ControlMode",
    "ControllerError",
    "LaserScan",
    "Observation",
    "RobotSpec",
    "Scenario",
    "ScenarioError",
    "Simulation",
    "Twist",
    "WheelCommand",
    "World",
    "build",
    "load_scenario",
]
