"""State machines for controllers: what the thesis's users drew as Stateflow charts, in Python.

States have entry, during and exit actions; transitions have guards, priorities, actions and
events; ``after``/``before`` are timers; ``vars`` is the chart's local data. A complete example
and the reference are in docs/controllers.md.

The machine is a controller (``reset()``, ``step(obs) -> command``, ``state_name``). One step,
like one wake-up of a Stateflow chart:

1. The first step after ``reset()`` enters the initial state (its entry action runs) and tests
   no transition.
2. Every later step takes the pending events (``send``) as this step's events, then tests the
   transitions leaving the active state in priority order (lower number first, ties in the
   order they were declared). A transition fires when its event, if it has one, is among this
   step's events and its guard, if it has one, is true. The first that fires runs the exit
   action of the old state, the transition's action and the entry action of the new state,
   whose timer (``time_in_state``) starts at 0. At most one transition fires per step.
3. The during action of the active state runs and returns the command. ``None``, or a state
   without a during action, holds the previous command (a stop before the first command).
4. This step's events are consumed, used or not; events sent during the step (by an action)
   are pending for the next step.

Angles are never compared with ``==``: a robot turning in discrete steps steps over the exact
target (the thesis's Stateflow charts stalled on that). Use ``reached``, ``near`` and ``wrap``.
"""

from __future__ import annotations

import copy as _copy
import difflib
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.control.api import Observation, command_for

Action = Callable[["Context"], Any]
Guard = Callable[["Context"], Any]
PoseSource = Literal["true_pose", "odometry"]


class ChartError(ValueError):
    """A state machine that is not well formed (unknown state, no initial state, ...)."""


class ActionError(RuntimeError):
    """An action, guard or input of a chart raised; the message names the chart and state."""


# ------------------------------------------------------------------------------ helpers
def wrap(angle: float) -> float:
    """``angle`` in rad wrapped to (-pi, pi] (:func:`agvsim.angles.wrap_scalar`)."""
    return float(wrap_scalar(float(angle)))


def reached(angle: float, target: float, tol: float = 0.01) -> bool:
    """True when ``angle`` is within ``tol`` rad of ``target``, across the +-pi seam."""
    return abs(wrap(angle - target)) <= tol


def near(x: float, target: float, tol: float) -> bool:
    """True when ``|x - target| <= tol``: the tolerant ``==`` for distances, speeds, times."""
    return abs(float(x) - float(target)) <= tol


def _eps(dt_s: float) -> float:
    """Slack on timers: float time accumulated over many steps must not cost a whole step."""
    return 1e-6 * dt_s


def after(duration_s: float) -> Callable[[Context], bool]:
    """Guard: the active state has been active for at least ``duration_s`` of simulated time."""
    return _timer(duration_s, True)


def before(duration_s: float) -> Callable[[Context], bool]:
    """Guard: the active state has been active for less than ``duration_s``."""
    return _timer(duration_s, False)


def _timer(duration_s: float, is_after: bool) -> Callable[[Context], bool]:
    def guard(ctx: Context) -> bool:
        return ctx.after(duration_s) == is_after

    guard.__name__ = guard.__qualname__ = f"{'after' if is_after else 'before'}({duration_s:g} s)"
    return guard


def _suggest(word: str, options: list[str]) -> str:
    close = difflib.get_close_matches(word, options, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{hint} ({', '.join(options) or 'none defined'})"


# ------------------------------------------------------------------------------ the chart
@dataclass
class State:
    name: str
    entry: Action | None = None
    during: Action | None = None
    exit: Action | None = None


@dataclass(frozen=True)
class Transition:
    source: str
    target: str
    guard: Guard | None = None
    event: str | None = None
    priority: int = 0  # lower is tested first; ties in declaration order
    action: Action | None = None
    label: str | None = None  # shown in diagrams (default: the guard's function name)
    order: int = 0  # declaration index, set by StateMachine.transition

    def __str__(self) -> str:
        return f"transition {self.source!r} -> {self.target!r}"


class Context:
    """What actions, guards and inputs see during one step."""

    def __init__(self, machine: StateMachine, obs: Observation):
        self.machine, self.obs = machine, obs
        self.t: float = float(obs.t_s)  # s, simulated time
        self.dt: float = float(obs.dt_s)  # s, the kinematics step
        self.vars: dict[str, Any] = machine.vars  # the chart's local data
        self.events: frozenset[str] = frozenset()  # this step's events
        self._inputs: dict[str, Any] = {}

    @property
    def state(self) -> str:
        """The active state (the new one once a transition has fired)."""
        return self.machine.state_name

    @property
    def time_in_state(self) -> float:
        """Seconds since the active state was entered (0 in the step that enters it)."""
        return self.t - self.machine._t_entry

    def after(self, duration_s: float) -> bool:
        return self.time_in_state >= duration_s - _eps(self.dt)

    def before(self, duration_s: float) -> bool:
        return not self.after(duration_s)

    @property
    def pose(self) -> np.ndarray:
        """(3,) x, y, theta: ground truth, or dead reckoning with ``pose_source="odometry"``."""
        return self.obs.true_pose if self.machine.pose_source == "true_pose" else self.obs.odom_pose

    @property
    def heading(self) -> float:
        return float(self.pose[2])

    def ranges(self, sensor: str) -> np.ndarray:
        """(B,) latest readings of ``sensor`` in m (inf: no return, -inf: too close)."""
        scans = self.obs.scans
        if sensor not in scans:
            raise KeyError(
                f"robot {self.obs.name!r} has no sensor {sensor!r}" + _suggest(sensor, list(scans))
            )
        return scans[sensor].ranges

    def send(self, event: str) -> None:
        """Queue ``event`` for the next step."""
        self.machine.send(event)

    def __getattr__(self, name: str) -> Any:  # the chart's inputs: ctx.front, ...
        inputs = self.machine._inputs
        if name.startswith("_") or name not in inputs:
            raise AttributeError(
                f"chart {self.machine.name!r} has no input {name!r}" + _suggest(name, list(inputs))
            )
        if name not in self._inputs:
            self._inputs[name] = self.machine._call(inputs[name], self, f"input {name!r}")
        return self._inputs[name]


class StateMachine:
    """A chart of states and transitions that drives one robot (see the module docstring).

    ``data`` holds the initial local data, copied into ``vars`` at every ``reset()``.
    ``pose_source`` picks what ``ctx.pose`` and ``ctx.heading`` read: the ground truth (as the
    thesis's charts read the simulator's pose) or the wheel odometry.
    """

    def __init__(
        self,
        name: str,
        initial: str | None = None,
        *,
        data: dict[str, Any] | None = None,
        pose_source: PoseSource = "true_pose",
    ):
        if pose_source not in ("true_pose", "odometry"):
            raise ChartError(f"pose_source must be 'true_pose' or 'odometry', got {pose_source!r}")
        self.name, self.initial, self.pose_source = name, initial, pose_source
        self.data = dict(data or {})
        self._states: dict[str, State] = {}
        self._transitions: list[Transition] = []
        self._inputs: dict[str, Callable[[Context], Any]] = {}
        self._valid = False
        self.reset()

    # ------------------------------------------------------------------ building
    def add_state(
        self,
        name: str,
        *,
        entry: Action | None = None,
        during: Action | None = None,
        exit: Action | None = None,
    ) -> State:
        """Declare a state (again: add actions to it); each action may be set only once."""
        if not isinstance(name, str) or not name:
            raise ChartError(f"chart {self.name!r}: a state name is a non-empty str, got {name!r}")
        st = self._states.setdefault(name, State(name))
        for kind, fn in (("entry", entry), ("during", during), ("exit", exit)):
            if fn is None:
                continue
            if not callable(fn):
                raise ChartError(f"state {name!r}: the {kind} action must be callable, got {fn!r}")
            if getattr(st, kind) is not None:
                raise ChartError(f"chart {self.name!r}: state {name!r} already has a {kind} action")
            setattr(st, kind, fn)
        self._valid = False
        return st

    def state(self, name: str) -> Callable[[Action], Action]:
        """Decorator: the during action of state ``name`` (returns the command, or None)."""
        return self._decorator(name, "during")

    def entry(self, name: str) -> Callable[[Action], Action]:
        """Decorator: the entry action of state ``name``."""
        return self._decorator(name, "entry")

    def exit(self, name: str) -> Callable[[Action], Action]:
        """Decorator: the exit action of state ``name``."""
        return self._decorator(name, "exit")

    def _decorator(self, name: str, kind: str) -> Callable[[Action], Action]:
        def register(fn: Action) -> Action:
            self.add_state(name, **{kind: fn})
            return fn

        return register

    def input(self, fn: Callable[[Context], Any]) -> Callable[[Context], Any]:
        """Decorator: ``ctx.<function name>`` computes this from the observation, once a step."""
        taken = {"machine", "obs", "t", "dt", "vars", "events"} | set(dir(Context))
        if fn.__name__ in taken or fn.__name__.startswith("_"):
            raise ChartError(f"chart {self.name!r}: ctx.{fn.__name__} exists; rename the input")
        self._inputs[fn.__name__] = fn
        return fn

    def transition(
        self,
        source: str,
        target: str,
        *,
        guard: Guard | None = None,
        event: str | None = None,
        priority: int = 0,
        action: Action | None = None,
        label: str | None = None,
    ) -> Transition:
        """Add a transition (states may be declared later; ``validate`` checks the names)."""
        for what, fn in (("guard", guard), ("action", action)):
            if fn is not None and not callable(fn):
                raise ChartError(
                    f"{source!r} -> {target!r}: the {what} must be callable, got {fn!r}"
                )
        if event is not None and (not isinstance(event, str) or not event):
            raise ChartError(
                f"{source!r} -> {target!r}: an event is a non-empty str, got {event!r}"
            )
        if not isinstance(priority, int) or isinstance(priority, bool):
            raise ChartError(f"{source!r} -> {target!r}: priority must be an int, got {priority!r}")
        tr = Transition(
            source, target, guard, event, priority, action, label, len(self._transitions)
        )
        self._transitions.append(tr)
        self._valid = False
        return tr

    @property
    def states(self) -> tuple[State, ...]:
        return tuple(self._states.values())

    @property
    def transitions(self) -> tuple[Transition, ...]:
        """All transitions, each source's in the order they are tested."""
        return tuple(sorted(self._transitions, key=lambda t: (t.priority, t.order)))

    def leaving(self, state: str) -> tuple[Transition, ...]:
        """The transitions out of ``state``, in the order they are tested."""
        return tuple(t for t in self.transitions if t.source == state)

    def validate(self) -> None:
        """Raise ``ChartError`` naming the first fault: no states, no or an unknown initial
        state, a transition to or from an unknown state."""
        names = list(self._states)
        if not names:
            raise ChartError(f"chart {self.name!r} has no states; add one with @sm.state('name')")
        if self.initial is None:
            raise ChartError(
                f"chart {self.name!r} has no initial state; pass initial=... ({', '.join(names)})"
            )
        if self.initial not in self._states:
            raise ChartError(
                f"chart {self.name!r}: the initial state {self.initial!r} is not a state"
                + _suggest(self.initial, names)
            )
        for t in self._transitions:
            for end in ("source", "target"):
                s = getattr(t, end)
                if s not in self._states:
                    raise ChartError(
                        f"chart {self.name!r}, {t}: unknown {end} state {s!r}" + _suggest(s, names)
                    )
        self._leaving = {s: self.leaving(s) for s in names}
        self._events = {t.event for t in self._transitions if t.event is not None}
        self._valid = True

    # ------------------------------------------------------------------ running
    def reset(self) -> None:
        """Back to before the first step: local data from ``data``, no events, no command."""
        if self._states:
            self.validate()
        self.vars: dict[str, Any] = _copy.deepcopy(self.data)
        self._active: str | None = None
        self._t_entry = 0.0
        self._pending: list[str] = []
        self._last: object = None
        self._robot: str | None = None

    @property
    def state_name(self) -> str:
        """The active state (the initial one before the first step)."""
        return self._active if self._active is not None else (self.initial or "")

    def send(self, event: str) -> None:
        """Queue ``event``; it is seen (and consumed) by the next step."""
        if not self._valid:
            self.validate()
        if event not in self._events:
            raise ChartError(
                f"chart {self.name!r}: no transition waits for event {event!r}"
                + _suggest(event, sorted(self._events))
            )
        self._pending.append(event)

    def step(self, obs: Observation) -> object:
        """One step (see the module docstring); returns the command for this robot."""
        if not self._valid:
            self.validate()
        if self._robot is None:
            self._robot = obs.name
        elif obs.name != self._robot:
            raise ChartError(
                f"chart {self.name!r} drives robot {self._robot!r} and got an observation of "
                f"{obs.name!r}: one machine drives one robot; give each robot sm.copy()"
            )
        ctx = Context(self, obs)
        if self._active is None:
            self._enter(self.initial, ctx)  # type: ignore[arg-type]
        else:
            ctx.events, self._pending = frozenset(self._pending), []
            for t in self._leaving[self._active]:
                if t.event is not None and t.event not in ctx.events:
                    continue
                if t.guard is not None and not self._call(t.guard, ctx, f"guard of {t}"):
                    continue
                self._fire(t, ctx)
                break
        during = self._states[self.state_name].during
        cmd = None if during is None else self._call(during, ctx, "during action")
        if cmd is None:
            cmd = self._last if self._last is not None else command_for(obs, 0.0, 0.0, 0.0)
        self._last = cmd
        return cmd

    def _enter(self, name: str, ctx: Context) -> None:
        self._active, self._t_entry = name, ctx.t
        entry = self._states[name].entry
        if entry is not None:
            self._call(entry, ctx, "entry action")

    def _fire(self, t: Transition, ctx: Context) -> None:
        ex = self._states[t.source].exit
        if ex is not None:
            self._call(ex, ctx, "exit action")
        if t.action is not None:
            self._call(t.action, ctx, f"action of {t}")
        self._enter(t.target, ctx)

    def _call(self, fn: Callable[[Context], Any], ctx: Context, what: str) -> Any:
        try:
            return fn(ctx)
        except ActionError:
            raise
        except Exception as exc:  # noqa: BLE001 - reported with the chart, state and function
            name = getattr(fn, "__name__", "?")
            raise ActionError(
                f"chart {self.name!r}, state {self.state_name!r}, {what} {name}: "
                f"{type(exc).__name__}: {exc}"
            ) from exc

    def copy(self) -> StateMachine:
        """A fresh machine with the same chart (states, transitions, inputs, data)."""
        new = StateMachine(self.name, self.initial, data=self.data, pose_source=self.pose_source)
        new._states = {k: replace(s) for k, s in self._states.items()}
        new._transitions = list(self._transitions)
        new._inputs = dict(self._inputs)
        new.reset()
        return new

    def __repr__(self) -> str:
        return (
            f"StateMachine({self.name!r}, initial={self.initial!r}, states={list(self._states)}, "
            f"transitions={len(self._transitions)})"
        )
