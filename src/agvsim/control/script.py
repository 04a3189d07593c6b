"""The ``script`` controller: plays a timed list of commands written in the scenario file.

Each step holds for ``duration_s`` and is either a body twist (inverse kinematics) or wheel
speeds (+ steering) (forward kinematics), so one script may mix both, e.g. wheel speeds 5, 5
rad/s for 2 s, then twist 0.5 m/s, 0.3 rad/s for 3 s. After the last step the robot stops (or
the script starts over with ``loop=True``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvsim.control.api import Observation, Twist, WheelCommand


@dataclass(frozen=True)
class ScriptStep:
    duration_s: float
    twist: tuple[float, float, float] | None = None  # vx m/s, vy m/s, omega rad/s
    wheels: tuple[float, ...] | None = None  # driven wheel speeds rad/s
    steering_rad: float = 0.0

    def __post_init__(self) -> None:
        if not self.duration_s > 0:
            raise ValueError(f"a script step needs duration_s > 0, got {self.duration_s}")
        if (self.twist is None) == (self.wheels is None):
            raise ValueError("a script step has exactly one of 'twist' or 'wheels'")

    def command(self) -> Twist | WheelCommand:
        if self.twist is not None:
            return Twist(*self.twist)
        return WheelCommand(tuple(self.wheels or ()), self.steering_rad)


class ScriptController:
    def __init__(self, steps: Sequence[ScriptStep], loop: bool = False):
        if not steps:
            raise ValueError("a script needs at least one step")
        self.steps = list(steps)
        self.loop = loop
        self.ends_s = np.cumsum([s.duration_s for s in self.steps])

    def reset(self) -> None:  # stateless: the command is a function of time
        pass

    def active_step(self, t_s: float) -> int | None:
        """Index of the step playing at ``t_s`` (None once the script is over)."""
        total = float(self.ends_s[-1])
        if self.loop:
            t_s = t_s % total
        # a step covers [start, end); a small tolerance absorbs accumulated float time
        k = int(np.searchsorted(self.ends_s, t_s + 1e-9, side="right"))
        return k if k < len(self.steps) else None

    def step(self, obs: Observation) -> Twist | WheelCommand:
        k = self.active_step(obs.t_s)
        if k is None:
            last = self.steps[-1]
            if last.wheels is not None:
                return WheelCommand(tuple(0.0 for _ in last.wheels), last.steering_rad)
            return Twist()
        return self.steps[k].command()

    @property
    def state_name(self) -> str:  # pragma: no cover - shown by viewers
        return "script"
