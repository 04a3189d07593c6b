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

import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

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


@dataclass
class Reservations:
    """Pending visits per node, in planned order."""

    margin_s: float = 0.5
    visits: dict[str, list[Visit]] = field(default_factory=dict)

    def add(self, v: Visit) -> None:
        q = self.visits.setdefault(v.node, [])
        q.append(v)
        q.sort(key=Visit.key)

    def remove(self, v: Visit) -> None:
        q = self.visits.get(v.node, [])
        for k, x in enumerate(q):
            if x is v:
                del q[k]
                return

    def first(self, node: str) -> Visit | None:
        q = self.visits.get(node)
        return q[0] if q else None

    def safe_intervals(self, node: str, serial: str) -> list[tuple[float, float]]:
        """The gaps between other vehicles' visits of ``node`` (with the margin)."""
        out, lo = [], -INF
        for v in self.visits.get(node, []):
            if v.serial == serial:
                continue
            # a granted visit holds its node from now on, whatever its planned start: a
            # vehicle ahead of its plan may be there already
            a = -INF if v.granted else v.start_s - self.margin_s
            b = v.end_s + self.margin_s
            if a > lo:
                out.append((lo, a))
            lo = max(lo, b)
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
) -> list[Step]:
    """The quickest route from ``start`` (at ``t0_s``) through ``stops`` that fits the gaps
    of ``table``, ending parked on the last stop. The vehicle has held ``start`` since
    ``held_since_s`` (default ``t0_s``): the gap it starts in must cover that too.
    ``stop_at_start`` False: a stop on ``start`` needs leaving and coming back (an order
    update cannot add actions to its first node). ``avoid``: nodes never to enter (other
    vehicles' parking places). A car-like ``graph`` (a minimum turning radius) plans over
    (node, the arc it arrived by): only turns its steering lock allows, and it parks only where
    it can drive off again; ``arrived_by`` is how it reaches ``start`` (None: it stands there,
    facing ``heading_rad``). Raises NoRoute."""
    if not stops:
        raise ValueError("a route needs at least one stop")
    to_stop = [graph.times_to(s.node) for s in stops]
    rest = [0.0] * len(stops)  # from stop k to the end: legs between stops and dwells
    for k in range(len(stops) - 2, -1, -1):
        leg = to_stop[k + 1].get(stops[k].node, INF)
        rest[k] = stops[k].dwell_s + leg + rest[k + 1]
    if rest[0] == INF or start not in to_stop[0]:
        raise NoRoute(f"no path from {start} through {[s.node for s in stops]}")
    cache: dict[str, list[tuple[float, float]]] = {}

    def gaps(n: str) -> list[tuple[float, float]]:
        got = cache.get(n)
        if got is None:
            got = cache[n] = table.safe_intervals(n, serial)
        return got

    car = graph.car_like
    held = t0_s if held_since_s is None else min(held_since_s, t0_s)
    i0 = next((i for i, (a, b) in enumerate(gaps(start)) if a <= held and t0_s < b), None)
    if i0 is None:
        raise NoRoute(f"{start} is not free for {serial} at t={t0_s:.1f} s")
    a0 = arrived_by if car else None
    # a state: (node, the arc it arrived by (car-like only), safe interval, stops done)
    Key = tuple[str, Arc | None, int, int]
    k0: Key = (start, a0, i0, 0)
    best: dict[Key, float] = {k0: t0_s}
    parent: dict[Key, tuple[Key, float] | None] = {k0: None}
    # ties of f (many equally quick ways on a grid; f rounded to the microsecond so that sums
    # in another order tie too) go to the state furthest along: -g; then by name, push order
    heap: list[tuple[float, float, str, int, int, int, Key]] = [
        (round(t0_s + to_stop[0][start] + rest[0], 6), -t0_s, start, i0, 0, 0, k0)
    ]
    pushed = 1
    closed: set[Key] = set()
    expansions = 0
    goal: Key | None = None
    last = len(stops) - 1
    while heap:
        _, neg_a, *_, key = heapq.heappop(heap)
        if key in closed:
            continue
        closed.add(key)
        expansions += 1
        if expansions > max_expansions:
            break
        a = -neg_a
        u, came, i, k = key
        hi = gaps(u)[i][1]
        exits = graph.exits(came, u, heading_rad) if car else graph.out[u]
        if u == stops[k].node and (stop_at_start or parent[key] is not None):
            if k == last:
                if hi == INF and (exits or not graph.out[u]):
                    goal = key
                    break
            else:
                a2 = a + stops[k].dwell_s
                nk: Key = (u, came, i, k + 1)
                if a2 < hi and a2 < best.get(nk, INF):
                    best[nk], parent[nk] = a2, (key, -1.0)
                    h = to_stop[k + 1].get(u, INF) + rest[k + 1]
                    heapq.heappush(heap, (round(a2 + h, 6), -a2, u, i, k + 1, pushed, nk))
                    pushed += 1
        tk = to_stop[k]
        for arc in exits:
            v = arc.end
            if v in avoid:
                continue
            h = tk.get(v, INF)
            if h == INF:
                continue
            for j, (lo, hi2) in enumerate(gaps(v)):
                if hi2 <= a:
                    continue
                d = a if a > lo else lo
                arrive = d + arc.time_s
                if arrive >= hi:
                    break  # cannot hold u until then (later gaps start later still)
                if arrive >= hi2:
                    continue
                nk = (v, arc if car else None, j, k)
                if arrive < best.get(nk, INF):
                    best[nk], parent[nk] = arrive, (key, d)
                    f = round(arrive + h + rest[k], 6)
                    heapq.heappush(heap, (f, -arrive, v, j, k, pushed, nk))
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
        steps.append(Step(key_k[0], best[key_k], depart))
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
