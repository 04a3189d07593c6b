"""Teleoperation: a controller that plays the latest command given from outside.

A user interface (the browser app, a notebook, a joystick loop) calls ``set_twist``,
``set_wheels`` or the keyboard helpers at any time; each simulation step the robot gets the
latest command. A **dead-man timeout** stops the robot when no command has arrived for
``deadman_s`` seconds, so a lost connection or a released key never leaves it running away.
Time is the simulation's (``obs.t_s``, stamped at the first step after a command arrives)
unless a ``clock`` such as ``time.monotonic`` is given, which an interactive app running in
real time should use.

Keys (``key(name)`` for one, ``keys(names)`` for several held together; arrow keys, WASD, and
the browser's ``KeyboardEvent.key`` names such as "ArrowUp" are understood):

=================  =====================================  =====================
key                command                                default
=================  =====================================  =====================
up, w              forward,  vx = +linear_speed_m_s        0.5 m/s
down, s            backward, vx = -linear_speed_m_s        -0.5 m/s
left, a            turn left,  omega = +turn_rate_rad_s    1.0 rad/s
right, d           turn right, omega = -turn_rate_rad_s    -1.0 rad/s
q, e               strafe left / right, vy = +-lateral    0.5 m/s (holonomic)
space, x, stop     stop                                    0
=================  =====================================  =====================

Held together the keys add (up + left: an arc). In **inverse** mode the robot gets the twist;
in **forward** mode the keys drive wheel speeds: the twist becomes the driven wheels' speeds
(+ steering) through the robot's own inverse kinematics (``command_for``), e.g. "up" on a
differential drive sets both wheels to ``linear_speed_m_s / wheel_radius_m``. Robots that
cannot move sideways ignore q/e; car-like robots only steer on left/right and need up or down
as well to turn. ``set_wheels`` sends wheel speeds (+ steering) in either mode.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

from agvsim.control.api import Observation, Twist, WheelCommand, command_for

#: key -> (vx, vy, omega) as fractions of the linear, lateral and turn speeds
KEYS: dict[str, tuple[float, float, float]] = {
    "up": (1.0, 0.0, 0.0),
    "down": (-1.0, 0.0, 0.0),
    "left": (0.0, 0.0, 1.0),
    "right": (0.0, 0.0, -1.0),
    "q": (0.0, 1.0, 0.0),
    "e": (0.0, -1.0, 0.0),
    "stop": (0.0, 0.0, 0.0),
}
ALIASES = {
    "w": "up",
    "s": "down",
    "a": "left",
    "d": "right",
    "arrowup": "up",
    "arrowdown": "down",
    "arrowleft": "left",
    "arrowright": "right",
    "space": "stop",
    " ": "stop",
    "x": "stop",
}


def key_name(name: str) -> str:
    """The canonical key for ``name`` (case-insensitive); ValueError for unknown keys."""
    k = name if name == " " else name.strip().lower()
    k = ALIASES.get(k, k)
    if k not in KEYS:
        known = sorted(set(KEYS) | set(ALIASES) - {" "})
        raise ValueError(f"unknown teleop key {name!r}; known: {', '.join(known)}")
    return k


class Teleop:
    """Plays the latest outside command, with a dead-man timeout (see the module docstring).

    ``state_name``: "idle" (nothing received yet), "driving", "stopped" (a stop key or
    ``stop()``) or "deadman" (no command for ``deadman_s`` seconds)."""

    def __init__(
        self,
        deadman_s: float = 0.5,
        linear_speed_m_s: float = 0.5,
        lateral_speed_m_s: float = 0.5,
        turn_rate_rad_s: float = 1.0,
        clock: Callable[[], float] | None = None,
    ):
        if not deadman_s > 0:
            raise ValueError(f"deadman_s must be > 0, got {deadman_s}")
        self.deadman_s = deadman_s
        self.speeds = (linear_speed_m_s, lateral_speed_m_s, turn_rate_rad_s)
        self.clock = clock
        self.reset()

    def reset(self) -> None:
        self._cmd: Twist | WheelCommand | None = None
        self._stamp: float | None = None
        self._fresh = False
        self.state_name = "idle"

    # ---------------------------------------------------------------- from outside
    def _set(self, cmd: Twist | WheelCommand | None) -> None:
        self._cmd = cmd
        if self.clock is not None:
            self._stamp = self.clock()
        else:
            self._fresh = True  # stamped with the simulation time at the next step

    def set_twist(self, vx: float, vy: float = 0.0, omega: float = 0.0) -> None:
        """Body twist: vx, vy m/s (robot frame), omega rad/s."""
        self._set(Twist(float(vx), float(vy), float(omega)))

    def set_wheels(self, speeds: Sequence[float], steering_rad: float = 0.0) -> None:
        """Driven wheel speeds rad/s (the model's driven-wheel order) and, for car-like
        models, the steering angle."""
        self._set(WheelCommand(tuple(float(v) for v in speeds), float(steering_rad)))

    def stop(self) -> None:
        self._set(None)

    def key(self, name: str) -> None:
        """One key pressed (see the table in the module docstring)."""
        self.keys([name])

    def keys(self, names: Iterable[str]) -> None:
        """Keys held together: their commands add (each component clipped to +-1 x speed)."""
        pressed = {key_name(n) for n in names}
        if not pressed or "stop" in pressed:
            self.stop()
            return
        total = [0.0, 0.0, 0.0]
        for k in pressed:
            for j, f in enumerate(KEYS[k]):
                total[j] += f
        self.set_twist(
            *(max(-1.0, min(1.0, f)) * s for f, s in zip(total, self.speeds, strict=True))
        )

    # ---------------------------------------------------------------- the step
    def step(self, obs: Observation):
        if self._fresh:
            self._stamp, self._fresh = obs.t_s, False
        now = self.clock() if self.clock is not None else obs.t_s
        if self._stamp is None:
            self.state_name = "idle"
        elif now - self._stamp > self.deadman_s:
            self.state_name = "deadman"
        elif self._cmd is None:
            self.state_name = "stopped"
        else:
            self.state_name = "driving"
        if self.state_name != "driving":
            return command_for(obs, 0.0, 0.0, 0.0)
        cmd = self._cmd
        if isinstance(cmd, WheelCommand):
            want = len(obs.model.driven_wheels)  # type: ignore[attr-defined]
            if len(cmd.speeds) != want:
                raise ValueError(
                    f"set_wheels got {len(cmd.speeds)} speeds; this robot has {want} driven "
                    "wheel(s)"
                )
            return cmd
        assert isinstance(cmd, Twist)
        return command_for(obs, cmd.vx, cmd.vy, cmd.omega)
