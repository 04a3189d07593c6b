"""The actions a simulated vehicle performs, and the order they run in (VDA 5050 6.12).

``ACTION_TYPES`` is the registry: each type, the scopes it may be given in (INSTANT, NODE,
EDGE) and how long it takes once running. ``schedule`` starts the actions of one node or edge in
list order by their blocking types: NONE and SOFT run in parallel with the others, a HARD one
waits for every earlier action to end and holds back every later one until it ends itself.
``drive_blocked`` is true while a SOFT or HARD action has not ended (the vehicle must not
drive), or while any action of the list has not yet started.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from agvsim.fleet.order import Action

ENDED = ("FINISHED", "FAILED")
ACTIVE = ("INITIALIZING", "RUNNING", "PAUSED")


@dataclass(frozen=True)
class ActionType:
    scopes: frozenset[str]
    duration_s: float  # time RUNNING before FINISHED (0: at once)
    description: str


def _t(scopes: str, duration_s: float, description: str) -> ActionType:
    return ActionType(frozenset(scopes.split()), duration_s, description)


ACTION_TYPES: dict[str, ActionType] = {
    "startPause": _t("INSTANT", 0.0, "stop driving; actions pause; the order is kept"),
    "stopPause": _t("INSTANT", 0.0, "resume driving and paused actions"),
    "cancelOrder": _t("INSTANT", 0.0, "stop at once, fail waiting and running actions"),
    "initPosition": _t("INSTANT", 0.0, "set lastNodeId (the pose must match the vehicle's)"),
    "stateRequest": _t("INSTANT", 0.0, "publish a state now"),
    "factsheetRequest": _t("INSTANT", 0.0, "publish the factsheet now"),
    "startCharging": _t("INSTANT NODE", 1.0, "start charging (on a charging node only)"),
    "stopCharging": _t("INSTANT NODE", 0.5, "stop charging"),
    "pick": _t("NODE EDGE", 3.0, "take a load onto the load handling device"),
    "drop": _t("NODE EDGE", 3.0, "put the load down"),
    "finePositioning": _t("NODE", 1.0, "align on the station (simulated as a wait)"),
    "detectObject": _t("NODE EDGE", 1.0, "look for an object (simulated as a wait)"),
}


def supported_scopes() -> dict[str, frozenset[str]]:
    """action type -> scopes, for ``parse_order``."""
    return {name: t.scopes for name, t in ACTION_TYPES.items()}


def _hard(a: Action) -> bool:
    return a.blocking in ("HARD", "SINGLE")


def schedule(actions: Sequence[Action], start: Callable[[Action], None]) -> None:
    """Start the actions that may start now (``start`` sets them RUNNING, FINISHED or
    FAILED)."""
    for k, a in enumerate(actions):
        if a.status in ENDED:
            continue
        if a.status in ACTIVE:
            if _hard(a):
                return
            continue
        # WAITING: a HARD one starts only when everything before it has ended
        if _hard(a):
            if any(b.status not in ENDED for b in actions[:k]):
                return
            start(a)
            if a.status not in ENDED:
                return
        else:
            start(a)


def drive_blocked(actions: Sequence[Action]) -> bool:
    return any(
        a.status == "WAITING" or (a.status not in ENDED and a.blocking != "NONE") for a in actions
    )
