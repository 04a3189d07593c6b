"""Dispatching policies: which available vehicle takes a transport order.

A policy is a function ``(transport, candidates, cost) -> serial | None``; ``cost(serial,
node)`` is the vehicle's quickest time (s) from where it can next decide to ``node``, on the
empty graph. Candidates are sorted by serial and are idle (or on their way back home), not
broken, not charging and charged above the low threshold.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from agvsim.master.orders import Transport

Policy = Callable[[Transport, Sequence[str], Callable[[str, str], float]], str | None]


def nearest_idle(
    transport: Transport, candidates: Sequence[str], cost: Callable[[str, str], float]
) -> str | None:
    """The candidate quickest to reach the pick-up (ties: the lower serial)."""
    best, best_cost = None, float("inf")
    for s in candidates:
        c = cost(s, transport.source)
        if c < best_cost:
            best, best_cost = s, c
    return best


POLICIES: dict[str, Policy] = {"nearest_idle": nearest_idle}
