"""Keyboard driving in the app: which robot the keys drive, the twist they have set, and the
teleop controller that robot runs meanwhile (its own controller is kept to give back)."""

from __future__ import annotations

from typing import Any

import numpy as np

from agvsim.control.teleop import Teleop
from agvsim.sim.engine import Simulation

KEY_STEP = {"linear": 0.1, "lateral": 0.1, "turn": 0.25}  # per key press: m/s, m/s, rad/s
KEY_LIMIT = {"linear": 2.0, "lateral": 2.0, "turn": 3.0}
#: key -> (twist axis, change per press); space stops
STEPS = {
    "up": (0, KEY_STEP["linear"]),
    "down": (0, -KEY_STEP["linear"]),
    "q": (1, KEY_STEP["lateral"]),
    "e": (1, -KEY_STEP["lateral"]),
    "left": (2, KEY_STEP["turn"]),
    "right": (2, -KEY_STEP["turn"]),
}
ALIASES = {"w": "up", "s": "down", "a": "left", "d": "right", " ": "space", "x": "space"}
TELEOP = {"type": "teleop", "clock": "wall"}


class UnknownKey(ValueError):
    pass


class Keyboard:
    """The keyboard-driven robot (None: none) and the twist its keys have set. No lock of its
    own: the session calls it under its lock."""

    def __init__(self) -> None:
        self.robot: str | None = None
        self.saved_controller: dict[str, Any] | None = None  # the robot's own, given back
        self.twist = np.zeros(3)

    def swap(self, robots: list[dict[str, Any]], name: str | None) -> None:
        """In the robot configs ``robots`` (edited in place): give the driven robot its own
        controller back, and give ``name`` (None: nobody) the teleop controller; the twist
        stops. The caller commits with :meth:`driving` once the edit holds."""
        index = {r["name"]: k for k, r in enumerate(robots)}
        if self.robot is not None and self.robot in index:
            robots[index[self.robot]]["controller"] = self.saved_controller or {"type": "idle"}
        self.twist[:] = 0.0
        if name is not None:
            rc = robots[index[name]]
            self.saved_controller = rc.get("controller", {"type": "idle"})
            rc["controller"] = dict(TELEOP)

    def driving(self, name: str | None) -> None:
        self.robot = name
        if name is None:
            self.saved_controller = None

    def forget(self) -> None:
        """Nobody is driven any more (the robot is gone, another scenario is loaded)."""
        self.robot, self.saved_controller = None, None

    def key(self, name: str) -> tuple[float, float, float]:
        """One key press: up/down add forward speed, left/right turn rate, q/e sideways speed
        (holonomic robots), space stops. Returns the twist now."""
        k = name.strip().lower()
        k = ALIASES.get(k, k.removeprefix("arrow"))
        if k == "space":
            self.twist[:] = 0.0
        elif k in STEPS:
            axis, step = STEPS[k]
            lim = (KEY_LIMIT["linear"], KEY_LIMIT["lateral"], KEY_LIMIT["turn"])[axis]
            self.twist[axis] = round(float(np.clip(self.twist[axis] + step, -lim, lim)), 6)
        else:
            raise UnknownKey(f"unknown key {name!r}; use arrows/WASD, q/e and space")
        vx, vy, om = (float(v) for v in self.twist)
        return vx, vy, om

    def stop(self) -> None:
        self.twist[:] = 0.0

    def feed(self, sim: Simulation) -> None:
        """Hand the twist to the driven robot's teleop controller (before a step)."""
        tele = self._teleop(sim)
        if tele is not None:
            vx, vy, om = self.twist
            if vx == vy == om == 0.0:
                tele.stop()
            else:
                tele.set_twist(vx, vy, om)

    def _teleop(self, sim: Simulation) -> Teleop | None:
        if self.robot is None:
            return None
        i = sim.robot_index(self.robot)
        for b in sim.bindings:
            if i in b.robots and isinstance(b.controller, Teleop):
                return b.controller
        return None
