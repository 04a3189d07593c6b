"""SIGTERM ends a job as gracefully as Ctrl-C, and outputs are written whole.

``kill``, ``timeout``, ``docker stop`` and service managers send SIGTERM, whose default action
ends the process at once: no ``finally`` runs, so a run's summary and plot would be lost.
Inside :func:`terminate_as_interrupt` a SIGTERM raises :class:`Terminated` instead. It is a
``KeyboardInterrupt``, so every path that already saves the work on Ctrl-C serves SIGTERM too;
the exit status tells them apart (130 after Ctrl-C, 143 after SIGTERM, as shells report a
process ended by the signal). :func:`hold_signals` makes both signals wait while outputs are
being written, so an interruption never leaves half a file.

Signal handlers belong to the main thread: off it, both context managers change nothing.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType

EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(KeyboardInterrupt):
    """The process received SIGTERM (handled like Ctrl-C)."""

    def __init__(self) -> None:
        super().__init__("terminated by SIGTERM")


@dataclass
class StopRequest:
    """Set once a SIGTERM has arrived; a loop may poll ``requested`` to stop at a clean point
    even where user code swallowed the :class:`Terminated` exception."""

    requested: bool = False


def exit_code(interruption: KeyboardInterrupt) -> int:
    """The process exit status after ``interruption``: 143 for SIGTERM, 130 for Ctrl-C."""
    return EXIT_TERMINATED if isinstance(interruption, Terminated) else EXIT_INTERRUPTED


def _on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextmanager
def terminate_as_interrupt() -> Iterator[StopRequest]:
    """While inside, the first SIGTERM raises :class:`Terminated` (later ones only keep
    ``requested`` set, so the clean-up they interrupt is not cut short); the previous handler
    is restored on exit."""
    stop = StopRequest()
    if not _on_main_thread():
        yield stop
        return

    def on_term(signum: int, frame: FrameType | None) -> None:
        first = not stop.requested
        stop.requested = True
        if first:
            raise Terminated

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGTERM, previous)


@contextmanager
def hold_signals() -> Iterator[None]:
    """Let Ctrl-C and SIGTERM wait until the block is done, then deliver them to the handlers
    that were in place (a second Ctrl-C while waiting breaks through at once): a
    :class:`StepGuard` holding for the whole block."""
    with StepGuard() as guard:
        guard.holding = True
        yield


class StepGuard:
    """Ctrl-C and SIGTERM between steps, never inside one, at almost no cost per step.

    Inside ``with StepGuard() as guard:`` (on the main thread; elsewhere it changes nothing)
    the two signals go to the handlers that were in place, except while ``guard.holding`` is
    true: then they wait, and :meth:`release` (or leaving the block) delivers them. A loop sets
    ``holding`` around the part of a step that must be whole and calls ``release`` after it;
    setting a flag costs far less than swapping handlers every step (:func:`hold_signals`).
    A second Ctrl-C while holding breaks through at once, as in :func:`hold_signals`.
    """

    def __init__(self) -> None:
        self.holding = False
        self._pending: list[int] = []
        self._previous: dict[int, object] = {}

    def __enter__(self) -> StepGuard:
        if _on_main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                self._previous[s] = signal.signal(s, self._on_signal)
        return self

    def __exit__(self, *exc: object) -> None:
        self.holding = False
        for s, handler in self._previous.items():
            if handler is not None:  # None: a handler not set from Python, left as it is
                signal.signal(s, handler)  # type: ignore[arg-type]
        self._previous = {}
        pending, self._pending = self._pending, []
        for signum in dict.fromkeys(pending):
            signal.raise_signal(signum)

    def release(self) -> None:
        """End the hold; a signal that came during it is handled now."""
        self.holding = False
        if self._pending:
            pending, self._pending = self._pending, []
            for signum in dict.fromkeys(pending):
                self._pass_on(signum, None)

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        if self.holding and not (signum == signal.SIGINT and signal.SIGINT in self._pending):
            self._pending.append(signum)
            return
        self._pass_on(signum, frame)

    def _pass_on(self, signum: int, frame: FrameType | None) -> None:
        handler = self._previous.get(signum)
        if callable(handler):
            handler(signum, frame)
        elif signum == signal.SIGINT:  # the default: Ctrl-C interrupts
            raise KeyboardInterrupt
        elif handler == signal.SIG_DFL:  # the default end of the process, as it would have
            signal.signal(signum, signal.SIG_DFL)
            signal.raise_signal(signum)
