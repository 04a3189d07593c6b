"""State-machine diagrams (Mermaid, Graphviz) and finding a chart from a command-line name.

    to_mermaid(sm)   # a ``stateDiagram-v2``: paste into Markdown on GitHub or mermaid.live
    to_dot(sm)       # Graphviz: ``dot -Tpng chart.dot -o chart.png``
    resolve("examples/avoid_statemachine.py:controller")   # or a built-in chart: "avoid"

A transition reads like a Stateflow label, ``(n) event [condition] / action``: n is the order in
which the transitions leaving a state are tested (priority, then declaration order); the
condition is the transition's ``label``, or else its guard's function name.
"""

from __future__ import annotations

import importlib.util
import inspect
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from agvsim.control.api import command_for
from agvsim.control.statemachine import (
    ChartError,
    Context,
    StateMachine,
    Transition,
    after,
    reached,
    wrap,
)

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _name(fn: Callable | None) -> str:
    if fn is None:
        return ""
    name = getattr(fn, "__name__", type(fn).__name__)
    return "lambda" if name == "<lambda>" else name


def transition_label(t: Transition, order: int) -> str:
    """``(order) event [condition] / action``, the parts that exist."""
    parts = [f"({order})"]
    if t.event:
        parts.append(t.event)
    cond = t.label or _name(t.guard)
    if cond:
        parts.append(f"[{cond}]")
    if t.action is not None:
        parts.append(f"/ {_name(t.action)}")
    return " ".join(parts)


def _numbered(sm: StateMachine) -> list[tuple[Transition, int]]:
    sm.validate()
    return [(t, k) for s in sm.states for k, t in enumerate(sm.leaving(s.name), start=1)]


def _actions(sm: StateMachine, state: str) -> list[str]:
    st = next(s for s in sm.states if s.name == state)
    return [
        f"{kind} / {_name(fn)}" for kind in ("entry", "during", "exit") if (fn := getattr(st, kind))
    ]


def to_mermaid(sm: StateMachine) -> str:
    """A Mermaid ``stateDiagram-v2`` of the chart: states with their actions, the initial
    state, every transition with its label."""

    def clean(text: str) -> str:  # ':' ';' '#' end a Mermaid label; keep one line
        return re.sub(r"\s+", " ", text.replace(":", " ").replace(";", ",").replace("#", "no."))

    ids = {}
    lines = ["stateDiagram-v2"]
    for k, s in enumerate(sm.states):
        if _IDENT.fullmatch(s.name):
            ids[s.name] = s.name
        else:
            ids[s.name] = f"s{k}"
            lines.append(f'    state "{s.name.replace(chr(34), "")}" as s{k}')
    pairs = _numbered(sm)
    lines.append(f"    [*] --> {ids[sm.initial]}")  # type: ignore[index]
    for s in sm.states:
        lines += [f"    {ids[s.name]} : {clean(a)}" for a in _actions(sm, s.name)]
    for t, k in pairs:
        lines.append(f"    {ids[t.source]} --> {ids[t.target]} : {clean(transition_label(t, k))}")
    return "\n".join(lines) + "\n"


def to_dot(sm: StateMachine) -> str:
    """A Graphviz ``digraph`` of the chart (rounded boxes listing each state's actions)."""

    def q(text: str) -> str:
        return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'

    pairs = _numbered(sm)
    lines = [
        f"digraph {q(sm.name)} {{",
        "    rankdir=LR;",
        '    node [shape=box, style=rounded, fontname="Helvetica"];',
        '    edge [fontname="Helvetica", fontsize=10];',
        "    __start [shape=point, width=0.15];",
    ]
    for s in sm.states:
        body = "\\n".join([s.name, *_actions(sm, s.name)]).replace('"', '\\"')
        lines.append(f'    {q(s.name)} [label="{body}"];')
    lines.append(f"    __start -> {q(sm.initial or '')};")
    for t, k in pairs:
        lines.append(f"    {q(t.source)} -> {q(t.target)} [label={q(transition_label(t, k))}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------ resolving
def avoid_chart(
    sensor: str = "rangers",
    front_beams: tuple[int, ...] = (0,),
    back_beams: tuple[int, ...] = (2,),
    trigger_m: float = 0.8,
    speed_m_s: float = 0.5,
    turn_rate_rad_s: float = 1.0,
    tolerance_rad: float = 0.01,
    backoff_s: float = 0.6,
    can_spin: bool = True,
) -> StateMachine:
    """The built-in ``avoid`` controller (``agvsim.control.avoid``) drawn as a chart, with the
    same states, transitions and defaults. The simulator runs the numba version; this one
    exists for diagrams (it runs too, one robot per machine, at most one transition a step)."""
    quarter = math.pi / 2
    close = 0.45 * trigger_m
    sm = StateMachine("avoid", initial="drive", data={"target": 0.0, "back_dir": -1.0})

    def nearest(ctx: Context, beams: tuple[int, ...]) -> float:
        r = ctx.ranges(sensor)
        return min((0.0 if r[b] == -math.inf else float(r[b]) for b in beams), default=math.inf)

    @sm.input
    def front(ctx: Context) -> float:
        return nearest(ctx, front_beams)

    @sm.input
    def back(ctx: Context) -> float:
        return nearest(ctx, back_beams)

    def err(ctx: Context) -> float:
        return wrap(ctx.vars["target"] - ctx.heading)

    @sm.entry("drive")
    def hold_heading(ctx: Context) -> None:  # the heading rounded to the maze's axes
        ctx.vars["target"] = wrap(round(ctx.heading / quarter) * quarter)

    @sm.state("drive")
    def straight_on(ctx: Context) -> object:
        w = min(max(2.0 * err(ctx), -turn_rate_rad_s), turn_rate_rad_s)
        return command_for(ctx.obs, speed_m_s, 0.0, w)

    def aim_right(ctx: Context) -> None:
        ctx.vars["target"] = wrap(round((ctx.heading - quarter) / quarter) * quarter)

    @sm.state("turn_right")
    def turn(ctx: Context) -> object:
        if can_spin:  # on the spot, slowing near the target
            return command_for(
                ctx.obs, 0.0, 0.0, -min(max(abs(err(ctx)) * 3.0, 0.2), 1.0) * turn_rate_rad_s
            )
        return command_for(ctx.obs, 0.5 * speed_m_s, 0.0, -10.0 * turn_rate_rad_s)  # full lock

    @sm.state("reverse")
    def back_up(ctx: Context) -> object:  # full left lock backwards: still turning right
        return command_for(ctx.obs, -0.5 * speed_m_s, 0.0, -10.0 * turn_rate_rad_s)

    @sm.entry("back_off")
    def pick_side(ctx: Context) -> None:  # away from the nearer obstacle
        ctx.vars["back_dir"] = -1.0 if ctx.front <= ctx.back else 1.0

    @sm.state("back_off")
    def back_away(ctx: Context) -> object:
        if ctx.obs.bump and ctx.time_in_state > 0:  # blocked that way too: the other way
            ctx.vars["back_dir"] = -ctx.vars["back_dir"]
        return command_for(ctx.obs, 0.5 * speed_m_s * ctx.vars["back_dir"], 0.0, 0.0)

    def bump(ctx: Context) -> bool:
        return ctx.obs.bump

    def heading_reached(ctx: Context) -> bool:
        return reached(ctx.heading, ctx.vars["target"], tolerance_rad)

    for s in ("drive", "turn_right", "reverse"):
        sm.transition(s, "back_off", guard=bump, priority=0)
    sm.transition(
        "drive",
        "turn_right",
        guard=lambda c: c.front < trigger_m,
        priority=1,
        action=aim_right,
        label=f"front < {trigger_m:g} m",
    )
    for s in ("turn_right", "reverse"):
        sm.transition(s, "drive", guard=heading_reached, priority=1)
    sm.transition(
        "turn_right",
        "reverse",
        guard=lambda c: not can_spin and c.front < close,
        priority=2,
        label=f"car-like and front < {close:g} m",
    )
    sm.transition(
        "reverse",
        "turn_right",
        guard=lambda c: c.back < close or c.front > trigger_m,
        priority=2,
        label=f"back < {close:g} m or front > {trigger_m:g} m",
    )
    sm.transition("back_off", "turn_right", guard=after(backoff_s), action=aim_right)
    return sm


BUILTIN_CHARTS: dict[str, Callable[[], StateMachine]] = {"avoid": avoid_chart}


def resolve(spec: str) -> StateMachine:
    """The chart that ``spec`` names: a built-in (``avoid``) or ``path/to/file.py:name``, where
    ``name`` (default ``controller``) is a StateMachine or a class or function called with no
    arguments that returns one. Raises ``ChartError`` naming the file and the name."""
    if spec in BUILTIN_CHARTS:
        return BUILTIN_CHARTS[spec]()
    path_text, sep, name = spec.rpartition(":")
    if not sep or not name.isidentifier():  # no ':name' (or a Windows drive 'C:\...')
        path_text, name = spec, "controller"
    path = Path(path_text)
    if path.suffix != ".py":
        raise ChartError(
            f"{spec!r} is neither a built-in chart ({', '.join(BUILTIN_CHARTS)}) nor "
            "FILE.py:NAME naming a state machine in a Python file"
        )
    if not path.is_file():
        raise ChartError(f"{spec!r}: no such file {str(path)!r}")
    module_spec = importlib.util.spec_from_file_location(f"agvsim_chart_{path.stem}", path)
    module = importlib.util.module_from_spec(module_spec)  # type: ignore[arg-type]
    try:
        module_spec.loader.exec_module(module)  # type: ignore[union-attr]
    except Exception as err:  # noqa: BLE001 - the user's file: report, don't crash
        raise ChartError(f"{path} could not be loaded: {type(err).__name__}: {err}") from err
    defined = {k: v for k, v in vars(module).items() if not k.startswith("_")}
    if name not in defined:
        raise ChartError(f"{path} defines no {name!r}; {_candidates(defined)}")
    return _as_machine(defined[name], f"{path}:{name}", defined)


def _candidates(defined: dict[str, Any]) -> str:
    charts = [k for k, v in defined.items() if isinstance(v, StateMachine)]
    calls = [
        k
        for k, v in defined.items()
        if callable(v)
        and not isinstance(v, StateMachine)
        and _zero_arg(v)
        and getattr(v, "__module__", "").startswith("agvsim_chart_")
    ]
    found = [f"state machines: {', '.join(charts)}"] if charts else []
    found += [f"zero-argument functions or classes: {', '.join(calls)}"] if calls else []
    return "it has " + "; ".join(found) if found else "it defines no state machine"


def _zero_arg(fn: Callable) -> bool:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return False
    return all(
        p.default is not p.empty or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        for p in sig.parameters.values()
    )


def _as_machine(obj: Any, where: str, defined: dict[str, Any]) -> StateMachine:
    if isinstance(obj, StateMachine):
        return obj
    if not callable(obj):
        raise ChartError(
            f"{where} is a {type(obj).__name__}, not a state machine; {_candidates(defined)}"
        )
    if not _zero_arg(obj):
        raise ChartError(
            f"{where} needs arguments (a controller function obs -> command?); give a "
            f"StateMachine or a function or class called with no arguments that returns one; "
            f"{_candidates(defined)}"
        )
    try:
        made = obj()
    except Exception as err:  # noqa: BLE001 - the user's code: report, don't crash
        raise ChartError(f"{where}() raised {type(err).__name__}: {err}") from err
    if not isinstance(made, StateMachine):
        raise ChartError(f"{where}() returned a {type(made).__name__}, not a StateMachine")
    return made
