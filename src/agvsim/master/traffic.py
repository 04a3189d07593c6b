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
from bisect import bisect_right
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from agvsim.master.graph import Arc, RoadGraph
from agvsim.master.sipp import Workspace, search

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
    """Pending visits per node, in planned order (``visits``), mirrored for the numba route
    search as one row of arrays per node (``rows``). Change a visit only through ``add``,
    ``remove``, ``grant`` and ``hold_forever``: each keeps both up to date in O(row)."""

    margin_s: float = 0.5
    visits: dict[str, list[Visit]] = field(default_factory=dict)
    _gaps: dict[str, list[tuple[float, float]]] = field(default_factory=dict, repr=False)
    # the mirror (made on the first ``rows`` call): by node index, each row the node's
    # visits in order: held from ``_va`` (-inf once granted) to ``_vb``, margins included,
    # by vehicle ``_vs`` (``_codes``); ``_vn`` visits a row
    _index: dict[str, int] | None = field(default=None, repr=False)
    _va: np.ndarray = field(default_factory=lambda: np.empty((0, 0)), repr=False)
    _vb: np.ndarray = field(default_factory=lambda: np.empty((0, 0)), repr=False)
    _vs: np.ndarray = field(default_factory=lambda: np.empty((0, 0), np.int64), repr=False)
    _vn: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64), repr=False)
    _codes: dict[str, int] = field(default_factory=dict, repr=False)
    _own: dict[str, Counter[str]] = field(default_factory=dict, repr=False)  # serial: nodes
    _version: Counter[str] = field(default_factory=Counter, repr=False)  # changes by node
    workspace: Workspace | None = field(default=None, repr=False)  # the search's (rows())

    def add(self, v: Visit) -> None:
        q = self.visits.setdefault(v.node, [])
        pos = bisect_right(q, v.key(), key=Visit.key)
        q.insert(pos, v)
        own = self._own.get(v.serial)
        if own is None:
            own = self._own[v.serial] = Counter()
        own[v.node] += 1
        self._gaps.pop(v.node, None)
        self._version[v.node] += 1
        if self._index is not None:
            self._insert(self._index[v.node], pos, v)

    def remove(self, v: Visit) -> None:
        q = self.visits.get(v.node, [])
        for k, x in enumerate(q):
            if x is v:
                del q[k]
                self._gaps.pop(v.node, None)
                self._version[v.node] += 1
                own = self._own[v.serial]
                own[v.node] -= 1
                if not own[v.node]:
                    del own[v.node]
                if not q:
                    del self.visits[v.node]
                if self._index is not None:
                    r, c = self._index[v.node], int(self._vn[self._index[v.node]])
                    for a in (self._va, self._vb, self._vs):
                        a[r, k : c - 1] = a[r, k + 1 : c]
                    self._vn[r] = c - 1
                return

    def grant(self, v: Visit) -> None:
        """``v`` is released to its vehicle: it holds its node from now on."""
        v.granted = True
        self._update(v)

    def hold_forever(self, v: Visit) -> None:
        """``v``'s vehicle never leaves (a breakdown)."""
        v.end_s = INF
        self._update(v)

    def version(self, node: str) -> int:
        """How many times the visits of ``node`` have changed (added, removed, granted...)."""
        return self._version[node]

    def first(self, node: str) -> Visit | None:
        q = self.visits.get(node)
        return q[0] if q else None

    def safe_intervals(self, node: str, serial: str) -> list[tuple[float, float]]:
        """The gaps between other vehicles' visits of ``node`` (with the margin), as a list
        (the route search works them out from ``rows`` itself). Do not modify the list."""
        q = self.visits.get(node)
        if not q:
            return FREE
        if node in self._own.get(serial, ()):
            return self._between(q, serial)
        got = self._gaps.get(node)
        if got is None:
            got = self._gaps[node] = self._between(q, "")
        return got

    def _between(self, q: list[Visit], serial: str) -> list[tuple[float, float]]:
        out, lo = [], -INF
        for v in q:
            if v.serial == serial:
                continue
            a, b = self._held(v)
            if a > lo:
                out.append((lo, a))
            if b > lo:
                lo = b
        if lo < INF:
            out.append((lo, INF))
        return out

    def _held(self, v: Visit) -> tuple[float, float]:
        """When ``v`` holds its node, margins included: a granted visit holds it from now
        on, whatever its planned start (a vehicle ahead of its plan may be there already)."""
        return (-INF if v.granted else v.start_s - self.margin_s), v.end_s + self.margin_s

    def code(self, serial: str) -> int:
        """``serial``'s number in the rows' vehicle column."""
        return self._codes.setdefault(serial, len(self._codes))

    def rows(
        self, ids: list[str], index: dict[str, int]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The table as rows by node index (``index``: node id -> row, for the nodes
        ``ids``): ``(held_from_s, held_until_s, vehicle, count)`` (see the class)."""
        if self._index is not index and self._index != index:
            self._index = index
            self._va = np.empty((len(ids), 8))
            self._vb = np.empty((len(ids), 8))
            self._vs = np.empty((len(ids), 8), np.int64)
            self._vn = np.zeros(len(ids), np.int64)
            self.workspace = Workspace(len(ids))
            for q in self.visits.values():
                for pos, v in enumerate(q):
                    self._insert(index[v.node], pos, v)
        return self._va, self._vb, self._vs, self._vn

    def _insert(self, r: int, pos: int, v: Visit) -> None:
        c = int(self._vn[r])
        if c == self._va.shape[1]:  # a full row: every row twice as long
            pad = ((0, 0), (0, c))
            self._va, self._vb = np.pad(self._va, pad), np.pad(self._vb, pad)
            self._vs = np.pad(self._vs, pad)
        for a in (self._va, self._vb, self._vs):
            a[r, pos + 1 : c + 1] = a[r, pos:c]
        self._va[r, pos], self._vb[r, pos] = self._held(v)
        self._vs[r, pos] = self.code(v.serial)
        self._vn[r] = c + 1

    def _update(self, v: Visit) -> None:
        """``v`` changed in place (granted, held forever): its row follows."""
        self._gaps.pop(v.node, None)
        self._version[v.node] += 1
        if self._index is None:
            return
        q = self.visits.get(v.node, [])
        pos = next((k for k, x in enumerate(q) if x is v), None)
        if pos is not None:
            r = self._index[v.node]
            self._va[r, pos], self._vb[r, pos] = self._held(v)


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


class StartTaken(NoRoute):
    """The vehicle cannot stay on its start as long as it must: others' visits come first."""


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
    time_scale: float = 1.0,
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
    quickest one costs a search over every state that could beat it). ``time_scale``: every
    travel time of the graph (edges, the heuristic's tables) times this, for vehicles that
    take longer than the graph says (``Pace``); dwells are not scaled. The search itself is
    ``agvsim.master.sipp.search`` (numba). Raises NoRoute."""
    if not stops:
        raise ValueError("a route needs at least one stop")
    to_stop = [graph.times_to(s.node) for s in stops]
    rest = [0.0] * len(stops)  # from stop k to the end: legs between stops and dwells
    for k in range(len(stops) - 2, -1, -1):
        leg = to_stop[k + 1].get(stops[k].node, INF) * time_scale
        rest[k] = stops[k].dwell_s + leg + rest[k + 1]
    if rest[0] == INF or start not in to_stop[0]:
        raise NoRoute(f"no path from {start} through {[s.node for s in stops]}")
    ids, index = graph.ids, graph.index
    held = t0_s if held_since_s is None else min(held_since_s, t0_s)
    s0 = index[start]
    car = graph.car_like
    net = graph.arrays()
    if car and arrived_by is None:
        start_exits = np.array(
            [net.arc_pos[a] for a, _ in graph.exits_k(None, s0, heading_rad)], np.int64
        )
    else:
        start_exits = net.no_arcs
    held_from, held_until, vehicle, count = table.rows(ids, index)
    space = table.workspace
    assert space is not None  # made by rows()
    heuristic = np.stack([t.array for t in to_stop])
    arc_times = net.out_time_s
    if time_scale != 1.0:
        heuristic, arc_times = heuristic * time_scale, arc_times * time_scale
    args = (
        net.out_off,
        net.out_end,
        arc_times,
        car,
        net.exit_off,
        net.exit_arc,
        start_exits,
        net.arc_pos[arrived_by] if car and arrived_by is not None else -1,
        held_from,
        held_until,
        vehicle,
        count,
        table.code(serial),
        heuristic,
        np.array(rest, np.float64),
        np.array([index[s.node] for s in stops], np.int64),
        np.array([s.dwell_s for s in stops], np.float64),
        graph.avoid_mask(avoid, [s.node for s in stops]),
        s0,
        float(held),
        float(t0_s),
        stop_at_start,
        float(weight),
        max_expansions,
    )
    while True:
        nodes, arrive, depart, done, expansions = search(
            *args,
            space.gap_at,
            space.gaps,
            space.slots,
            space.s_int,
            space.s_time,
            space.h_int,
            space.h_time,
            space.heap,
            space.c_int,
            space.c_time,
        )
        if expansions != -2:
            break
        space.grow()  # and search again, with room enough
    if expansions == -1:
        raise StartTaken(f"{start} is not free for {serial} at t={t0_s:.1f} s")
    if nodes.size == 0:
        raise NoRoute(
            f"no conflict-free route for {serial} from {start} through "
            f"{[s.node for s in stops]} ({expansions} states searched)"
        )
    steps: list[Step] = []
    for u, a, d, k in zip(
        nodes.tolist(), arrive.tolist(), depart.tolist(), done.tolist(), strict=True
    ):
        if steps and steps[-1].depart_s == -1.0:  # stop k - 1 was done on this very node
            steps[-1].stop, steps[-1].depart_s = k - 1, d
            continue
        steps.append(Step(ids[u], a, d))
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
