"""Run control of the app: playing or paused, the speed, the last controller error, and the
pacing of steps by the wall clock. Plain state, no lock of its own: the session calls it under
its lock."""

from __future__ import annotations

import time
from collections.abc import Callable

#: run speeds offered by the app: label -> simulated seconds per wall-clock second
SPEEDS: dict[str, float | None] = {"real time": 1.0, "x2": 2.0, "x10": 10.0, "max": None}
#: seconds of banked run time at most, per unit of speed: a stall must not cause a burst
MAX_BANK_S = 0.25


class RunControl:
    def __init__(self) -> None:
        self.playing = False
        self.speed_label = "real time"
        self.error: str | None = None  # the last controller error (the run pauses on it)
        self.budget_s = 0.0  # simulated seconds due and not stepped yet

    def play(self) -> None:
        self.playing, self.error = True, None
        self.budget_s = 0.0

    def pause(self) -> None:
        self.playing = False

    def set_speed(self, label: str) -> None:
        """``label`` one of ``SPEEDS`` (checked by the caller)."""
        self.speed_label, self.budget_s = label, 0.0

    def failed(self, error: str) -> None:
        """A step failed (a controller error): the run pauses and shows it."""
        self.playing, self.error = False, error

    def advance(
        self, dt_s: float, wall_dt_s: float, step: Callable[[], bool], max_work_s: float
    ) -> int:
        """Run the steps (``step()``; False: it failed, stop) due after ``wall_dt_s`` of wall
        time at the chosen speed, spending at most ``max_work_s`` of work ("max" speed: as
        many as fit). Returns the steps taken."""
        if not self.playing:
            return 0
        speed = SPEEDS[self.speed_label]
        if speed is not None:
            self.budget_s = min(self.budget_s + wall_dt_s * speed, MAX_BANK_S * speed)
        t0, taken = time.perf_counter(), 0
        while speed is None or self.budget_s >= dt_s * (1.0 - 1e-9):
            if not step():
                break
            taken += 1
            if speed is not None:
                self.budget_s -= dt_s
            if time.perf_counter() - t0 > max_work_s:
                break
        return taken
