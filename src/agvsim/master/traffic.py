"""Traffic control: a reservation table of node visits, planned with Safe Interval Path
Planning and executed in the order of an action dependency graph.

Planning (prioritized, one vehicle at a time, as orders come): each vehicle's route is a
sequence of node visits in time. A visit occupies its node from the moment the vehicle heads
for it (leaves the previous node) until it arrives at the next one; the last visit (where it
parks) never ends until the vehicle's next plan. A new route is searched by SIPP (Phillips and
Likhachev, ICRA 2011) in the gaps between the visits of every other vehicle (the reservation
table of Silver's cooperative pathfinding, AIIDE 2005), so no two visits of a node overlap in
planned time.

Execution: the planned times are not trusted (vehicles are late or early); only their order
is. Every node keeps its pending visits sorted by planned start; a vehicle is released the
edge into a node only when its visit is the first there, i.e. every earlier visitor has
already reached the node after it. This is the action dependency graph of Hönig et al.
("Persistent and robust execution of MAPF schedules in warehouses", RA-L 2019): every
dependency points to a visit planned strictly earlier, so the graph has no cycle and the
vehicle with the earliest pending visit can always move - no deadlock, whatever the delays.
A visit is released (removed) as the vehicle passes the following node. Vehicles may run
ahead of their plan, so a granted visit counts as holding its node from the start of time:
a new route can only be placed after it, never before.
"""

from __future__ import annotations

import math
from bisect import insort
from collections.abc import Sequence
from dataclasses import dataclass, field
from heapq import heappop, heappush

from agvsim.master.graph import Arc, RoadGraph

INF = math.inf


@dataclass
class Visit:
    serial: str
    node: str
    index: int  # position in the vehicle's route (its VDA 5050 sequenceId is 2 * index)
    start_s: float  # planned: heads for the node
    end_s: float  # planned: reaches the next node (inf: parks here)
    granted: bool = False  # released to the vehicle (it may be there already)

    def key(self) -> tuple[float, str, int]:
        return (self.start_s, self.serial, self.index)


FREE: list[tuple[float, float]] = [(-INF, INF)]  # the gaps of a node nobody visits


@dataclass
class Reservations:
    """Pending visits per node, in planned order. The gaps between them are kept per node
    until the node's visits change: change a visit only through ``grant`` and
    ``hold_forever``."""

    margin_s: float = 0.5
    visits: dict[str, list[Visit]] = field(default_factory=dict)
    _gaps: dict[str, list[tuple[float, float]]] = field(default_factory=dict, repr=False)

    def add(self, v: Visit) -> None:
        insort(self.visits.setdefault(v.node, []), v, key=Visit.key)
        self._gaps.pop(v.node, None)

    def remove(self, v: Visit) -> None:
        q = self.visits.get(v.node, [])
        for k, x in enumerate(q):
            if x is v:
                del q[k]
                self._gaps.pop(v.node, None)
                if not q:
                    del self.visits[v.node]
                return

    def grant(self, v: Visit) -> None:
        """``v`` is released to its vehicle: it holds its node from now on."""
        v.granted = True
        self._gaps.pop(v.node, None)

    def hold_forever(self, v: Visit) -> None:
        """``v``'s vehicle never leaves (a breakdown)."""
        v.end_s = INF
        self._gaps.pop(v.node, None)

    def first(self, node: str) -> Visit | None:
        q = self.visits.get(node)
        return q[0] if q else None

    def safe_intervals(self, node: str, serial: str) -> list[tuple[float, float]]:
        """The gaps between other vehicles' visits of ``node`` (with the margin). Do not
        modify the list returned."""
        q = self.visits.get(node)
        if not q:
            return FREE
        for v in q:
            if v.serial == serial:
                return self._between(q, serial)
        got = self._gaps.get(node)
        if got is None:
            got = self._gaps[node] = self._between(q, "")
        return got

    def _between(self, q: list[Visit], serial: str) -> list[tuple[float, float]]:
        out, lo, m = [], -INF, self.margin_s
        for v in q:
            if v.serial == serial:
                continue
            # a granted visit holds its node from now on, whatever its planned start: a
            # vehicle ahead of its plan may be there already
            a = -INF if v.granted else v.start_s - m
            b = v.end_s + m
            if a > lo:
                out.append((lo, a))
            if b > lo:
                lo = b
        if lo < INF:
            out.append((lo, INF))
        return out


@dataclass(frozen=True)
class Stop:
    """A node the route must visit, in order, and how long the vehicle stays (s)."""

    node: str
    dwell_s: float = 0.0


@dataclass
class Step:
    node: str
    arrive_s: float
    depart_s: float  # inf on the last step
    stop: int | None = None  # the index of the stop done here


class NoRoute(Exception):
    pass


def plan_route(
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
    """The quickest route from ``start`` (at ``t0_s``) through ``stops`` that fits the gaps
    of ``table``, ending parked on the last stop. The vehicle has held ``start`` since
    ``held_since_s`` (default ``t0_s``): the gap it starts in must cover that too.
    ``stop_at_start`` False: a stop on ``start`` needs leaving and coming back (an order
    update cannot add actions to its first node). ``avoid``: nodes never to enter unless they
    are stops (vehicles' parking places). A car-like ``graph`` (a minimum turning radius) plans over
    (node, the arc it arrived by): only turns its steering lock allows, and it parks only where
    it can drive off again; ``arrived_by`` is how it reaches ``start`` (None: it stands there,
    facing ``heading_rad``). ``weight`` > 1: weighted A* (f = g + weight h), a route at most
    ``weight`` times slower than the quickest that fits, found after far fewer states (the
    quickest one costs a search over every state that could beat it). Raises NoRoute."""
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
        (round(t0_s + weight * (h_to[0][s0] + rest[0]), 6), -t0_s, s0, i0, 0, 0, k0)
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
                    heappush(heap, (round(a2 + weight * h, 6), -a2, u, i, k + 1, pushed, nk))
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
                    f = round(arrive + weight * (h + rk), 6)
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


def visits_of(serial: str, steps: Sequence[Step], index0: int, t0_s: float) -> list[Visit]:
    """The node visits of a route whose first step is route position ``index0``."""
    out = []
    for k, s in enumerate(steps):
        start = t0_s if k == 0 else steps[k - 1].depart_s
        end = steps[k + 1].arrive_s if k + 1 < len(steps) else INF
        out.append(Visit(serial, s.node, index0 + k, start, end))
    return out
