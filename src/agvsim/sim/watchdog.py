"""A wall-clock limit on each controller call: user code that sleeps or loops forever must
not stall a run.

A controller is often a student's Python code. The simulation cannot know whether a slow call
will ever return, so it gives each call ``limit_s`` seconds of wall clock and ends it with
:class:`TimeLimitExceeded` after that. While the clock runs (``with clock:``, around a whole
run), a real-time interval timer sends SIGALRM every quarter of the limit; the handler raises
the exception inside the controller when the call in progress has run out of time, which
interrupts Python code, ``time.sleep`` and blocking waits alike. A call itself costs only two
reads of the monotonic clock (arming a timer per call would cost two system calls each). The
exception is a ``BaseException`` so that a controller's own ``except Exception`` does not
swallow it; a controller that swallows it all the same is told again at the next tick, and
``expired`` stays set so the engine reports the call when it returns.

Signals belong to the main thread of a POSIX process: elsewhere (a thread, Windows) the clock
is not ``enforced`` and calls run unlimited. ``agvsim run``, sweeps and grading step their
simulations on the main thread of their process.
"""

from __future__ import annotations

import math
import signal
import threading
import time
from types import FrameType, TracebackType
from typing import Any

TICKS_PER_LIMIT = 4  # a call is stopped between 1 and 1.25 limits after it began


class TimeLimitExceeded(BaseException):
    """A controller call ran past its wall-clock limit."""

    def __init__(self, limit_s: float):
        super().__init__(f"the call took longer than its time limit of {limit_s:g} s (wall clock)")
        self.limit_s = limit_s


def check_limit(limit_s: float | None) -> float | None:
    """``limit_s`` if it is a usable limit (None: no limit); ValueError otherwise."""
    if limit_s is None:
        return None
    if isinstance(limit_s, bool) or not isinstance(limit_s, int | float):
        raise ValueError(f"a controller time limit must be a number of seconds, got {limit_s!r}")
    if not (math.isfinite(limit_s) and limit_s > 0):
        raise ValueError(f"a controller time limit must be finite and > 0 s, got {limit_s!r}")
    return float(limit_s)


class ControllerClock:
    """Times controller calls: ``with clock:`` around the run, :meth:`begin` / :meth:`end`
    around each call (``end`` returns whether that call ran out of time)."""

    def __init__(self, limit_s: float):
        checked = check_limit(limit_s)
        assert checked is not None
        self.limit_s = checked
        self.running = False
        self.expired = False
        self._began: float | None = None
        self._previous: Any = None

    @property
    def enforced(self) -> bool:
        """Whether the clock can stop a call here (POSIX, main thread)."""
        return hasattr(signal, "setitimer") and (
            threading.current_thread() is threading.main_thread()
        )

    def __enter__(self) -> ControllerClock:
        if self.enforced and not self.running:
            self._previous = signal.signal(signal.SIGALRM, self._tick)
            tick_s = self.limit_s / TICKS_PER_LIMIT
            signal.setitimer(signal.ITIMER_REAL, tick_s, tick_s)
            self.running = True
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if not self.running:
            return
        signal.setitimer(signal.ITIMER_REAL, 0.0, 0.0)
        if self._previous is not None:
            signal.signal(signal.SIGALRM, self._previous)
        self._previous, self.running, self._began = None, False, None

    def begin(self) -> None:
        self.expired = False
        self._began = time.monotonic()

    def end(self) -> bool:
        self._began = None
        return self.expired

    def _tick(self, signum: int, frame: FrameType | None) -> None:
        began = self._began
        now = time.monotonic()
        if began is not None and now - began >= self.limit_s:
            self.expired = True
            self._began = now  # a controller that swallows this is told again a limit later
            raise TimeLimitExceeded(self.limit_s)
