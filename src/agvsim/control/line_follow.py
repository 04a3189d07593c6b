"""Line following: a PID on the line sensor's lateral offset, with junction choices.

The line sensor (agvsim.sensors.line_sensor) reports, for each separate run of lit elements,
the line's lateral offset ``e`` (m, positive to the left) at the bar, ``mount_x_m`` ahead of
the reference point. The law turns towards the line,

    omega = kp e + ki integral(e) + kd de/dt,

and slows in proportion to how far off the line the bar is. Two or more runs are a junction
(a fork or a crossing): the next entry of ``junctions`` picks one (``left``: the leftmost run,
``right``: the rightmost, ``straight``: the one nearest the previous offset); the entry is
used up when the bar has passed the junction (one run again). No run at all: the line is lost
and the vehicle stops (a real guided vehicle must not wander).

The law is per robot and model-free: it gives a body twist, which a holonomic or
differential robot drives as it is and a car-like robot through its inverse kinematics
(steering from the curvature omega / v).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from agvsim.control.api import Observation, command_for

JUNCTION_CHOICES = ("left", "right", "straight")


@dataclass
class LineFollowLaw:
    speed_m_s: float = 0.5
    kp: float = 20.0  # rad/s per metre of offset
    ki: float = 0.0
    kd: float = 1.0
    slow_offset_m: float = 0.05  # at this offset the speed has fallen to min_speed_frac
    min_speed_frac: float = 0.3
    junctions: Sequence[str] = ()
    state: str = "follow"
    _prev_e: float | None = None
    _integral: float = 0.0
    _next_junction: int = 0
    _in_junction: bool = False
    _forced: str | None = None  # a choice a spot asked for, used at the next junction
    taken: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        bad = [j for j in self.junctions if j not in JUNCTION_CHOICES]
        if bad:
            raise ValueError(f"junctions: {bad[0]!r} is not one of {', '.join(JUNCTION_CHOICES)}")

    def reset(self) -> None:
        self.state, self._prev_e, self._integral = "follow", None, 0.0
        self._next_junction, self._in_junction = 0, False
        self._forced = None
        self.taken.clear()

    def force(self, choice: str) -> None:
        """Take ``choice`` at the next junction (or the one under the bar now) instead of the
        next entry of ``junctions`` (a spot's code asked for it); the list is not advanced."""
        if choice not in JUNCTION_CHOICES:
            raise ValueError(f"{choice!r} is not one of {', '.join(JUNCTION_CHOICES)}")
        self._forced = choice

    def choice(self) -> str:
        if self._forced is not None:
            return self._forced
        if not self.junctions:
            return "straight"
        return self.junctions[self._next_junction % len(self.junctions)]

    def step(self, runs: Sequence[float], dt_s: float) -> tuple[float, float]:
        """(forward speed m/s, turn rate rad/s) for the runs the bar reads now."""
        if not runs:
            self.state = "lost"
            self._prev_e = None
            return 0.0, 0.0
        if len(runs) == 1:
            if self._in_junction:  # passed it: the next junction gets the next choice
                self._in_junction = False
                if self._forced is None:
                    self._next_junction += 1
                self._forced = None
            e = runs[0]
            self.state = "follow"
        else:
            if not self._in_junction:
                self._in_junction = True
                self.taken.append(self.choice())
            c = self.choice()
            prev = 0.0 if self._prev_e is None else self._prev_e
            e = (
                max(runs)
                if c == "left"
                else min(runs)
                if c == "right"
                else min(runs, key=lambda r: abs(r - prev))
            )
            self.state = "junction"
        de = 0.0 if self._prev_e is None or dt_s <= 0 else (e - self._prev_e) / dt_s
        self._prev_e = e
        self._integral = max(-1.0, min(1.0, self._integral + e * dt_s))  # anti-windup
        omega = self.kp * e + self.ki * self._integral + self.kd * de
        frac = max(
            self.min_speed_frac, 1.0 - (1.0 - self.min_speed_frac) * abs(e) / self.slow_offset_m
        )
        return self.speed_m_s * frac, omega


class LineFollower:
    """A controller around :class:`LineFollowLaw`: reads the line sensor ``sensor`` of the
    observation and commands the law's twist in the robot's mode (``command_for``: car-like
    models steer through their inverse kinematics). ``spot_choices`` maps a spot's code to the
    choice to take at the next junction (a magnet or tag before a fork tells the way).

    ``state_name``: "follow", "junction" or "lost" (no line under the bar: it stands)."""

    def __init__(
        self,
        sensor: str = "line",
        speed_m_s: float = 0.5,
        kp: float = 20.0,
        ki: float = 0.0,
        kd: float = 1.0,
        slow_offset_m: float = 0.05,
        min_speed_frac: float = 0.3,
        junctions: Sequence[str] = (),
        spot_choices: Mapping[int, str] | None = None,
    ):
        self.sensor = sensor
        self.law = LineFollowLaw(
            speed_m_s, kp, ki, kd, slow_offset_m, min_speed_frac, tuple(junctions)
        )
        self.spot_choices = dict(spot_choices or {})
        for code, choice in self.spot_choices.items():
            if choice not in JUNCTION_CHOICES:
                raise ValueError(
                    f"spot_choices[{code}]: {choice!r} is not one of {', '.join(JUNCTION_CHOICES)}"
                )
        self.reset()

    def reset(self) -> None:
        self.law.reset()
        self.state_name = "follow"
        self._last_spot = -1
        self.spots_seen: list[int] = []

    def step(self, obs: Observation) -> object:
        reading = obs.lines.get(self.sensor)
        if reading is None:
            raise ValueError(
                f"line_follow: robot {obs.name!r} has no line sensor {self.sensor!r} "
                f"(it has: {', '.join(obs.lines) or 'none'})"
            )
        spot = reading.spot_code
        if spot >= 0 and spot != self._last_spot:
            self.spots_seen.append(spot)
            if spot in self.spot_choices:
                self.law.force(self.spot_choices[spot])
        self._last_spot = spot
        v, omega = self.law.step(reading.offsets_m, obs.dt_s)
        self.state_name = self.law.state
        return command_for(obs, v, 0.0, omega)

    def report(self) -> dict:
        return {"junctions_taken": list(self.law.taken), "spots_seen": list(self.spots_seen)}
