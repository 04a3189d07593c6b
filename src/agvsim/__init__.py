"""agvsim: a fast, teachable simulator of AGVs (wheeled mobile robots).

The public API fits on one page:

    from agvsim import build, load_scenario
    sim = build(load_scenario("scenarios/thesis_maze_avoid.yaml"))
    sim.reset(seed=1)
    for _ in range(500):
        sim.step()
    sim.state.poses          # (N, 3) x, y, theta (world frame, ground truth)
    sim.observation(0).scans # latest scans of robot 0 (LaserScan layout)

Names are loaded on first use, so ``import agvsim.sim.engine`` (the headless core) pulls in
neither the scenario parser nor any plotting or CLI library.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

_PUBLIC = {
    "Binding": "agvsim.sim.engine",
    "ControlMode": "agvsim.control.api",
    "ControllerError": "agvsim.sim.engine",
    "LaserScan": "agvsim.scan",
    "Observation": "agvsim.control.api",
    "RobotSpec": "agvsim.sim.spec",
    "Scenario": "agvsim.scenario",
    "ScenarioError": "agvsim.scenario",
    "Simulation": "agvsim.sim.engine",
    "StateMachine": "agvsim.control.statemachine",
    "Twist": "agvsim.control.api",
    "WheelCommand": "agvsim.control.api",
    "World": "agvsim.sim.spec",
    "build": "agvsim.scenario",
    "command_for": "agvsim.control.api",
    "load_scenario": "agvsim.scenario",
}

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
    "StateMachine",
    "Twist",
    "WheelCommand",
    "World",
    "build",
    "command_for",
    "load_scenario",
]


def __getattr__(name: str):
    if name in _PUBLIC:
        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'agvsim' has no attribute {name!r}")


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from agvsim.control.api import (
        ControlMode,
        Observation,
        Twist,
        WheelCommand,
        command_for,
    )
    from agvsim.control.statemachine import StateMachine
    from agvsim.scan import LaserScan
    from agvsim.scenario import Scenario, ScenarioError, build, load_scenario
    from agvsim.sim.engine import Binding, ControllerError, Simulation
    from agvsim.sim.spec import RobotSpec, World
