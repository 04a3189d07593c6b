"""The master's route search (SIPP) written in plain Python over the reservation table's
gap lists: the reference the numba kernel (``agvsim.master.sipp``) is checked against in
``test_master_sipp.py``. Same states, same heap order, same tie-breaking."""

from __future__ import annotations

import math
from collections.abc import Sequence
from heapq import heappop, heappush

from agvsim.master.graph import Arc, RoadGraph
from agvsim.master.traffic import FREE, INF, NoRoute, Reservations, Step, Stop


def quantise(f: float) -> float:
    """As ``agvsim.master.sipp.quantise``: f in whole microseconds (inf stays inf)."""
    return f if f == INF else float(math.floor(f * 1e6 + 0.5))


def plan_route_reference(
    graph: RoadGraph,
    table: Reservations,
    serial: str,
    start: str,
    t0_s: float,
    stops: Sequence[Stop],
    held_since_s: float | None = None,
    stop_at_start: bool = True,
    avoid: frozenset[str] = frozenset(),
    max_expansions: int = 100_000,
    arrived_by: Arc | None = None,
    heading_rad: float | None = None,
    weight: float = 1.0,
) -> list[Step]:
    """The route search in plain Python (the one the master ran before the numba kernel):
    the reference that ``agvsim.master.traffic.plan_route`` must agree with, route for route."""
    if not stops:
        raise ValueError("a route needs at least one stop")
    to_stop = [graph.times_to(s.node) for s in stops]
    rest = [0.0] * len(stops)  # from stop k to the end: legs between stops and dwells
    for k in range(len(stops) - 2, -1, -1):
        leg = to_stop[k + 1].get(stops[k].node, INF)
        rest[k] = stops[k].dwell_s + leg + rest[k + 1]
    if rest[0] == INF or start not in to_stop[0]:
        raise NoRoute(f"no path from {start} through {[s.node for s in stops]}")
    # the search runs on node indices (graph.ids): list look-ups instead of dict ones
    ids, index = graph.ids, graph.index
    h_to = [t.by_index for t in to_stop]
    stop_k = [index[s.node] for s in stops]
    stop_nodes = {s.node for s in stops}
    avoid = frozenset(avoid) - stop_nodes if stop_nodes & avoid else avoid
    gap_cache: list[list[tuple[float, float]] | None] = [None] * len(ids)
    safe, visits = table.safe_intervals, table.visits

    car = graph.car_like
    held = t0_s if held_since_s is None else min(held_since_s, t0_s)
    s0 = index[start]
    g0 = gap_cache[s0] = safe(start, serial)
    i0 = next((i for i, (a, b) in enumerate(g0) if a <= held and t0_s < b), None)
    if i0 is None:
        raise NoRoute(f"{start} is not free for {serial} at t={t0_s:.1f} s")
    a0 = arrived_by if car else None
    # a state: (node, the arc it arrived by (car-like only), safe interval, stops done)
    Key = tuple[int, Arc | None, int, int]
    k0: Key = (s0, a0, i0, 0)
    best: dict[Key, float] = {k0: t0_s}
    parent: dict[Key, tuple[Key, float] | None] = {k0: None}
    # ties of f (many equally quick ways on a grid; f rounded to the microsecond so that sums
    # in another order tie too) go to the state furthest along: -g; then by node (its index
    # follows its name), interval, stops done, push order
    heap: list[tuple[float, float, int, int, int, int, Key]] = [
        (quantise(t0_s + weight * (h_to[0][s0] + rest[0])), -t0_s, s0, i0, 0, 0, k0)
    ]
    pushed = 1
    expansions = 0
    goal: Key | None = None
    last = len(stops) - 1
    out_k = graph.out_k
    while heap:
        item = heappop(heap)
        key = item[6]
        a = -item[1]
        if a > best[key]:
            continue  # a quicker way here was found since (and expanded, or is queued)
        expansions += 1
        if expansions > max_expansions:
            break
        u, came, i, k = key
        gu = gap_cache[u]
        assert gu is not None  # every state's node had its gaps looked up when pushed
        hi = gu[i][1]
        exits = graph.exits_k(came, u, heading_rad) if car else out_k[u]
        if u == stop_k[k] and (stop_at_start or parent[key] is not None):
            if k == last:
                if hi == INF and (exits or not out_k[u]):
                    goal = key
                    break
            else:
                a2 = a + stops[k].dwell_s
                nk: Key = (u, came, i, k + 1)
                if a2 < hi and a2 < best.get(nk, INF):
                    best[nk], parent[nk] = a2, (key, -1.0)
                    h = h_to[k + 1][u] + rest[k + 1]
                    heappush(heap, (quantise(a2 + weight * h), -a2, u, i, k + 1, pushed, nk))
                    pushed += 1
        tk, rk = h_to[k], rest[k]
        for arc, v in exits:
            h = tk[v]
            if h == INF or ids[v] in avoid:
                continue
            gv = gap_cache[v]
            if gv is None:  # (most nodes have no visits: no call for them)
                name = ids[v]
                gv = gap_cache[v] = safe(name, serial) if name in visits else FREE
            dt = arc.time_s
            for j, (lo, hi2) in enumerate(gv):
                if hi2 <= a:
                    continue
                d = a if a > lo else lo
                arrive = d + dt
                if arrive >= hi:
                    break  # cannot hold u until then (later gaps start later still)
                if arrive >= hi2:
                    continue
                nk = (v, arc if car else None, j, k)
                if arrive < best.get(nk, INF):
                    best[nk], parent[nk] = arrive, (key, d)
                    f = quantise(arrive + weight * (h + rk))
                    heappush(heap, (f, -arrive, v, j, k, pushed, nk))
                    pushed += 1
    if goal is None:
        raise NoRoute(
            f"no conflict-free route for {serial} from {start} through "
            f"{[s.node for s in stops]} ({expansions} states searched)"
        )
    # walk back: (key, departure from the previous key's node; -1 marks a stop done there)
    chain: list[tuple[Key, float]] = []
    key_: Key | None = goal
    dep = INF
    while key_ is not None:
        chain.append((key_, dep))
        p = parent[key_]
        if p is None:
            break
        key_, dep = p
    chain.reverse()
    steps: list[Step] = []
    for key_k, depart in chain:
        k = key_k[3]
        if steps and steps[-1].depart_s == -1.0:  # stop k - 1 was done on this very node
            steps[-1].stop, steps[-1].depart_s = k - 1, depart
            continue
        steps.append(Step(ids[key_k[0]], best[key_k], depart))
    steps[-1].depart_s, steps[-1].stop = INF, len(stops) - 1
    return steps
