"""The one step loop of a run, and what watches it: observers behind one small protocol.

``agvsim run`` (agvsim.runner), a sweep's runs (agvsim.experiments.runs, grading included) and
the browser app (agvsim.app) step a simulation the same way: step, then hand the new state to
each observer in order. An observer is anything with

* ``on_step(sim) -> bool | None``: called after every step; a true result ends the run (a
  metric whose goal is reached); the observers after it are not called for that step;
* ``close()``: called once when the run ends, however it ends (finished, a controller error,
  Ctrl-C), in the observers' order: each finishes its files then.

Ctrl-C and SIGTERM end a run between steps: while the controllers decide (user code, which
may hang) they break in at once and the state is still the last step's; during the rest of
the step and its observers they wait (:class:`~agvsim.signals.StepGuard`), so every step the
summary counts has its trajectory row and recording.

An observer that records the state the run starts from does so when it is made (the MCAP
recorder, the video writer, :class:`Rows`, agvsim.online_slam's ``OnlineSlam``), so the first
``on_step`` sees the state after the first step. The simulation knows nothing of its
observers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Protocol

from agvsim.signals import StepGuard, StopRequest, Terminated
from agvsim.sim.engine import Simulation

__all__ = [
    "Metrics",
    "Observer",
    "Progress",
    "Recording",
    "Rows",
    "Trail",
    "close_all",
    "notify",
    "run_loop",
]


class Observer(Protocol):
    def on_step(self, sim: Simulation) -> bool | None: ...

    def close(self) -> None: ...


def notify(observers: Iterable[Observer], sim: Simulation) -> bool:
    """Hand the state after a step to each observer in order; True when one ends the run
    (the ones after it are not called)."""
    return any(o.on_step(sim) for o in observers)


def run_loop(
    sim: Simulation,
    n_steps: int,
    observers: Sequence[Observer],
    stop: StopRequest | None = None,
) -> str:
    """Step ``sim`` ``n_steps`` times, notifying ``observers`` after each step, with
    ``python`` controllers held to their time limit (agvsim.sim.watchdog). Returns the run's
    status: ``completed``, ``ended_by_metric`` (an observer ended it) or, either way,
    ``completed_with_controller_errors`` when ``on_controller_error: stop_robot`` stopped some
    robots while the others went on. A ``ControllerError`` (``stop_run``) and Ctrl-C propagate;
    ``stop``: a SIGTERM whose exception a controller swallowed raises ``Terminated`` after the
    step. The caller closes the observers (:func:`close_all`)."""
    status = "completed"
    with sim.enforcing_time_limit(), StepGuard() as guard:
        for _ in range(n_steps):
            sim.control()  # user code: Ctrl-C and SIGTERM break in at once
            guard.holding = True  # the rest of the step and its record as one: no half step
            sim.advance()
            ended = notify(observers, sim)
            guard.release()
            if ended:
                status = "ended_by_metric"
                break
            if stop is not None and stop.requested:
                raise Terminated
    return "completed_with_controller_errors" if sim.errors else status


def close_all(observers: Iterable[Observer]) -> None:
    """Close each observer in order."""
    for o in observers:
        o.close()


class Recording:
    """An observer over a recorder with ``record()`` and ``close()`` (agvsim.record's MCAP
    ``Recorder`` and ``SlamMaps``, agvsim.viz's ``VideoRecorder``), which records the start
    itself when it is made."""

    def __init__(self, target: Any):
        self.target = target

    def on_step(self, sim: Simulation) -> None:
        self.target.record()

    def close(self) -> None:
        self.target.close()


class Rows(Recording):
    """The trajectory writer (agvsim.record.outputs.TrajectoryWriter) as an observer: its first
    row is the state the run starts from, written when this is made."""

    def __init__(self, target: Any):
        super().__init__(target)
        target.record()


class Metrics:
    """The scenario's metrics (agvsim.metrics), each updated after every step; the run ends
    when one says so (every metric still sees that step)."""

    def __init__(self, metrics: Mapping[str, Any]):
        self.metrics = dict(metrics)

    def on_step(self, sim: Simulation) -> bool:
        # a list, not a generator: every metric sees every step
        return any([m.update(sim) for m in self.metrics.values()])

    def close(self) -> None:
        pass

    def results(self) -> dict[str, Any]:
        return {name: m.result() for name, m in self.metrics.items()}


class Trail:
    """Each robot's path, a point every ``every`` steps (for a plot)."""

    def __init__(self, sim: Simulation, every: int):
        self.every, self.k = max(1, int(every)), 0
        self.xy: dict[str, list] = {r.name: [] for r in sim.robots}

    def on_step(self, sim: Simulation) -> None:
        if self.k % self.every == 0:
            for i, r in enumerate(sim.robots):
                self.xy[r.name].append(sim.state.poses[i, :2].copy())
        self.k += 1

    def close(self) -> None:
        pass


class Progress:
    """Calls ``report(t_s, total_s)`` every 50 steps and after the last one."""

    def __init__(self, report: Callable[[float, float], None], total_s: float, n_steps: int):
        self.report, self.total_s, self.n_steps, self.k = report, total_s, n_steps, 0

    def on_step(self, sim: Simulation) -> None:
        if self.k % 50 == 0 or self.k == self.n_steps - 1:
            self.report(sim.state.t_s, self.total_s)
        self.k += 1

    def close(self) -> None:
        pass
