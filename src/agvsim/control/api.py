"""The controller API.

A controller turns what a robot observes into a command, once per kinematics step:

* a plain function ``obs -> command``, or
* an object with ``reset()`` and ``step(obs) -> command``, or
* a *batch* controller (``BatchController``) that drives several robots with one call on
  arrays: the fast path used by the built-in behaviours.

A command is, in **inverse** mode, a body twist ``(vx m/s, vy m/s, omega rad/s)``
(a ``Twist`` or any 3 numbers); in **forward** mode, the driven wheels' speeds in rad/s
followed, for car-like models, by the steering angle in rad (a ``WheelCommand`` or numbers).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Protocol, runtime_checkable

import numpy as np

from agvsim.scan import LaserScan
from agvsim.sensors.floor_codes import FloorFixReading
from agvsim.sensors.line_sensor import LineReading


class ControlMode(StrEnum):
    """What a controller commands: a body twist (inverse kinematics computes the wheels) or the
    wheels themselves (forward kinematics computes the motion), as the thesis lets users pick.
    A ``StrEnum``: ``mode == "forward"`` holds for ``ControlMode.FORWARD``."""

    INVERSE = "inverse"
    FORWARD = "forward"


@dataclass(frozen=True)
class Observation:
    """What one robot's controller sees at time ``t_s``."""

    t_s: float
    name: str
    scans: dict[str, LaserScan]  # sensor frame + mount pose (agvsim.scan)
    odom_pose: np.ndarray  # (3,) dead-reckoned x, y, theta from wheel encoders
    wheel_speeds: np.ndarray  # (W,) measured rad/s
    bump: bool  # collided during the last step
    true_pose: np.ndarray  # (3,) GROUND TRUTH x, y, theta: not available to a real robot
    others: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (3,) pose of the
    # robots this one is allowed to know about (the scenario's `knows:`; ground truth)
    model: object = None  # this robot's kinematic model (for command_for / inverse kinematics)
    mode: ControlMode = ControlMode.INVERSE  # INVERSE: commands are twists; FORWARD: wheels
    dt_s: float = 0.02  # the kinematics step
    # guidance sensors (docs/guidance.md), by sensor name: each line sensor's reading and each
    # floor camera's latest fix (seq 0: none yet)
    lines: dict[str, LineReading] = field(default_factory=dict)
    floor_fixes: dict[str, FloorFixReading] = field(default_factory=dict)


@dataclass(frozen=True)
class Twist:
    vx: float = 0.0
    vy: float = 0.0
    omega: float = 0.0


@dataclass(frozen=True)
class WheelCommand:
    speeds: Sequence[float] = ()  # driven wheels, rad/s, in the model's driven-wheel order
    steering: float = 0.0  # rad, car-like models only


@dataclass
class BatchObservation:
    """Observations of a group of k robots, as arrays."""

    t_s: float
    robots: np.ndarray  # (k,) robot indices in the simulation
    ranges: Mapping[str, np.ndarray]  # sensor name -> (k, B) latest readings
    odom_pose: np.ndarray  # (k, 3)
    bump: np.ndarray  # (k,) bool
    true_pose: np.ndarray  # (k, 3) GROUND TRUTH
    extra: dict = field(default_factory=dict)


@runtime_checkable
class BatchController(Protocol):
    """Drives k robots at once. ``step`` returns a ``(k, m)`` command array: m = 3 twist values
    in inverse mode, or the driven wheel speeds (+ steering) in forward mode."""

    def reset(self, k: int, rng: np.random.Generator) -> None: ...

    def step(self, obs: BatchObservation) -> np.ndarray: ...


Controller = Callable[[Observation], object]


def command_for(obs: Observation, vx: float, vy: float = 0.0, omega: float = 0.0):
    """The command that asks for body twist (vx, vy, omega) in this robot's control mode: the
    twist itself in inverse mode, or, in forward mode, the driven wheel speeds (+ steering)
    that the robot's own inverse kinematics gives. Behaviours written in twists use this to
    work for every model and both modes."""
    if obs.mode != ControlMode.FORWARD:
        return Twist(float(vx), float(vy), float(omega))
    from agvsim.kinematics.actuation import forward_command

    model: Any = obs.model
    cmd = forward_command(model, np.array([[vx, vy, omega]]))[0]
    n = len(model.driven_wheels)
    return WheelCommand(tuple(float(v) for v in cmd[:n]), float(cmd[n]) if cmd.size > n else 0.0)


def command_to_array(
    cmd: object, width: int, mode: ControlMode, name: str, t_s: float
) -> np.ndarray:
    """Normalise a controller's return value to ``width`` floats, with a clear error."""
    if isinstance(cmd, Twist):
        values = [cmd.vx, cmd.vy, cmd.omega]
    elif isinstance(cmd, WheelCommand):
        values = list(cmd.speeds) + ([cmd.steering] if width > len(cmd.speeds) else [])
    else:
        try:
            values = np.asarray(cmd, dtype=np.float64).ravel().tolist()
        except (TypeError, ValueError):
            values = None
    if values is None or len(values) != width:
        what = (
            "a Twist or (vx, vy, omega)"
            if mode == ControlMode.INVERSE
            else (
                f"a WheelCommand or {width} numbers (driven wheel speeds rad/s"
                + (", then steering rad)" if width else ")")
            )
        )
        raise ValueError(
            f"controller of robot {name!r} at t={t_s:.3f} s returned {cmd!r}; "
            f"in {mode} mode it must return {what}"
        )
    return np.asarray(values, dtype=np.float64)


@dataclass(frozen=True)
class ControllerContext:
    """What a scenario gives a controller builder: ``build(config, ctx) -> controller``."""

    robot_index: int
    spec: object  # the robot's RobotSpec (model, body, sensors, initial pose)
    grid: object  # the world's OccupancyGrid (for behaviours that plan on a known map)
    robot_names: tuple[str, ...] = ()
    base_dir: object = None  # the scenario file's folder (pathlib.Path)
    static: object = None  # the known map's StaticMap (walls + boxes), to tell robots apart
    world: object = None  # the sim.spec.World: tape, floor codes, reflectors (guidance)
