"""Dispatching policies: which available vehicle takes a transport order.

A policy is a function ``(transport, candidates, costs) -> serial | None``; ``costs(node)`` is
an array, over the candidates in order, of each one's quickest time (s) from where it can next
decide to ``node`` on the empty graph (inf: it cannot get there). It comes from one Dijkstra
towards ``node`` per vehicle type, cached, not one search per candidate. Candidates are sorted
by serial and are idle (or on their way back home), not broken, not charging and charged
above the low threshold.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from agvsim.master.orders import Transport

Costs = Callable[[str], np.ndarray]
Policy = Callable[[Transport, Sequence[str], Costs], str | None]


def nearest_idle(transport: Transport, candidates: Sequence[str], costs: Costs) -> str | None:
    """The candidate quickest to reach the pick-up (ties: the lower serial)."""
    if not candidates:
        return None
    c = costs(transport.source)
    k = int(np.argmin(c))  # the first of equal minima: the lower serial
    return candidates[k] if np.isfinite(c[k]) else None


POLICIES: dict[str, Policy] = {"nearest_idle": nearest_idle}
