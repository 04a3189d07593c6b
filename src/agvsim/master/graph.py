"""The layout as a routing graph for one vehicle type: directed edges with lengths and times.

An edge's time is its length over the slower of the edge's speed limit and the vehicle's top
speed (trajectories: the sampled NURBS length). ``astar`` is a small A* over a binary heap
(``heapq``): networkx is not a dependency. The shortest times to a goal from every node (the
route planner's heuristic, the dispatcher's cost) come from SciPy's compiled Dijkstra
(``scipy.sparse.csgraph``) on the reversed graph: on a 5,000-node layout a pure-Python
Dijkstra took ~0.1 s a goal.

A car-like vehicle (``turn_radius_m`` > 0: Ackermann, a tricycle with less than 90 deg of
steering lock) cannot turn round on a node nor take a sharp corner: ``exits(arc)`` lists the
arcs it can drive on after arriving by ``arc``. A turn of angle theta, driven as a circular arc
of radius R tangent to both edges, starts R tan(theta / 2) before the node and ends as far
after it; it is allowed when that fits in half of each edge (the other half is kept for the
turn at the edge's other end). A U-turn (theta = pi) never fits: such a vehicle turns round
only by driving a loop of the layout.
"""

from __future__ import annotations

import heapq
import math
from array import array
from collections import OrderedDict
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from agvsim.world.lif import Layout


class Times:
    """Shortest times (s) to one goal by node id; ``get`` gives ``default`` (inf) for a node
    that cannot reach it."""

    def __init__(self, index: dict[str, int], times: np.ndarray):
        # by node index (RoadGraph.index): a C array of doubles (its items are plain floats,
        # the planner's look-ups) and a NumPy view of the same memory (the dispatcher's)
        self._index = index
        self.by_index = array("d")
        self.by_index.frombytes(np.ascontiguousarray(times, dtype=np.float64).tobytes())
        self.array = np.frombuffer(self.by_index, dtype=np.float64)

    def get(self, node: str, default: float = math.inf) -> float:
        k = self._index.get(node)
        t = math.inf if k is None else self.by_index[k]
        return default if t == math.inf else t

    def __getitem__(self, node: str) -> float:
        t = self.get(node)
        if t == math.inf:
            raise KeyError(node)
        return t

    def __contains__(self, node: object) -> bool:
        return isinstance(node, str) and self.get(node) != math.inf


@dataclass(frozen=True)
class Arc:
    edge_id: str
    start: str
    end: str
    length_m: float
    time_s: float
    heading_start_rad: float = 0.0  # the direction of travel leaving ``start``
    heading_end_rad: float = 0.0  # ... and arriving at ``end``


@dataclass(frozen=True)
class ArcArrays:
    """A ``RoadGraph`` as index arrays for the route search (``agvsim.master.sipp``): the
    arcs out of each node in ``out_k`` order (CSR: ``out_off``, ``out_end``, ``out_time_s``),
    and for a car-like vehicle the arcs it may take after each arc (``exit_off``,
    ``exit_arc``: positions in the same order). ``arc_pos``: an arc's position."""

    out_off: np.ndarray
    out_end: np.ndarray
    out_time_s: np.ndarray
    exit_off: np.ndarray
    exit_arc: np.ndarray
    arc_pos: dict[Arc, int]
    no_arcs: np.ndarray


def turn_fits(turn_radius_m: float, heading_in_rad: float, arc_out: Arc, room_in_m: float) -> bool:
    """Can a vehicle of minimum turning radius ``turn_radius_m`` arriving at ``arc_out.start``
    heading ``heading_in_rad`` drive on along ``arc_out``? ``room_in_m``: the length of the edge
    it arrives by (its half is the room before the node)."""
    if turn_radius_m <= 0:
        return True
    theta = abs(math.remainder(arc_out.heading_start_rad - heading_in_rad, math.tau))
    if theta > math.radians(170.0):
        return False
    need_m = turn_radius_m * math.tan(theta / 2)
    return need_m <= 0.5 * min(room_in_m, arc_out.length_m) + 1e-9


def _headings(pts: list[tuple[float, float]]) -> tuple[float, float]:
    (ax, ay), (bx, by) = pts[0], pts[1]
    (cx, cy), (dx, dy) = pts[-2], pts[-1]
    return math.atan2(by - ay, bx - ax), math.atan2(dy - cy, dx - cx)


class RoadGraph:
    """Directed arcs of ``layout`` that ``vehicle_type`` may use (every arc when None);
    ``turn_radius_m``: the vehicle's minimum turning radius (0: it turns on the spot)."""

    CACHED_FLOATS = 12_000_000  # the shortest-time tables kept (96 MB; goals repeat)

    def __init__(
        self,
        layout: Layout,
        vehicle_type: str | None,
        max_speed_m_s: float,
        turn_radius_m: float = 0.0,
    ):
        self._times: OrderedDict[str, Times] = OrderedDict()
        self._arrays: ArcArrays | None = None
        self._avoid: tuple[frozenset[str], np.ndarray] | None = None
        if max_speed_m_s <= 0:
            raise ValueError(f"max_speed_m_s {max_speed_m_s}: must be > 0")
        if not turn_radius_m >= 0:
            raise ValueError(f"turn_radius_m {turn_radius_m}: must be >= 0")
        self.layout = layout
        self.turn_radius_m = turn_radius_m
        self.out: dict[str, list[Arc]] = {n: [] for n in layout.nodes}
        self.into: dict[str, list[Arc]] = {n: [] for n in layout.nodes}
        for e in sorted(layout.edges.values(), key=lambda e: e.edge_id):
            props = e.types.get(vehicle_type) if vehicle_type is not None else None
            if vehicle_type is not None and props is None:
                continue
            if props is not None and props.trajectory is not None:
                pts = [(float(x), float(y)) for x, y in props.trajectory.sample(64)]
            else:
                pts = [layout.node_xy(e.start), layout.node_xy(e.end)]
            length = float(sum(math.dist(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)))
            limit = props.max_speed_m_s if props is not None else None
            speed = max_speed_m_s if limit is None else min(limit, max_speed_m_s)
            h0, h1 = _headings(pts)
            arc = Arc(e.edge_id, e.start, e.end, length, length / speed, h0, h1)
            self.out[e.start].append(arc)
            self.into[e.end].append(arc)
        self.ids = sorted(layout.nodes)
        self.index = {n: k for k, n in enumerate(self.ids)}
        fastest: dict[tuple[int, int], float] = {}
        for arcs in self.out.values():
            for a in arcs:
                key = (self.index[a.end], self.index[a.start])  # reversed: towards the goal
                fastest[key] = min(fastest.get(key, math.inf), max(a.time_s, 1e-9))
        n = len(self.ids)
        rows = np.array([k[0] for k in fastest], dtype=np.int64)
        cols = np.array([k[1] for k in fastest], dtype=np.int64)
        self._reversed = csr_matrix(
            (np.array(list(fastest.values()), dtype=np.float64), (rows, cols)), shape=(n, n)
        )

        self._arc: dict[tuple[str, str], Arc] = {}
        for arcs in self.out.values():
            for a in arcs:
                self._arc.setdefault((a.start, a.end), a)  # the first by edge id
        # by node index (the planner's inner loop): (arc, index of its end)
        self.out_k: list[list[tuple[Arc, int]]] = [
            [(a, self.index[a.end]) for a in self.out[nid]] for nid in self.ids
        ]
        # car-like: the arcs it can take after arriving by each arc
        self._exits: dict[Arc, list[tuple[Arc, int]]] = {}
        if turn_radius_m > 0:
            for arcs in self.out.values():
                for a in arcs:
                    self._exits[a] = [
                        (b, self.index[b.end])
                        for b in self.out[a.end]
                        if turn_fits(turn_radius_m, a.heading_end_rad, b, a.length_m)
                    ]

    def arrays(self) -> ArcArrays:
        """The graph as index arrays (built on first use, then kept)."""
        if self._arrays is None:
            arcs = [a for out in self.out_k for a, _ in out]
            pos = {a: k for k, a in enumerate(arcs)}
            off = np.cumsum([0] + [len(out) for out in self.out_k], dtype=np.int64)
            exits = [[pos[b] for b, _ in self._exits.get(a, ())] for a in arcs]
            self._arrays = ArcArrays(
                out_off=off,
                out_end=np.array([self.index[a.end] for a in arcs], np.int64),
                out_time_s=np.array([a.time_s for a in arcs], np.float64),
                exit_off=np.cumsum([0] + [len(x) for x in exits], dtype=np.int64),
                exit_arc=np.array([b for x in exits for b in x], np.int64),
                arc_pos=pos,
                no_arcs=np.empty(0, np.int64),
            )
        return self._arrays

    def avoid_mask(self, avoid: frozenset[str], stops: Iterable[str] = ()) -> np.ndarray:
        """``avoid`` (node ids) as a mask by node index, less the nodes in ``stops``. The
        last mask is kept: the master passes the same set of parking places every time."""
        if self._avoid is None or self._avoid[0] is not avoid:
            mask = np.zeros(len(self.ids), np.bool_)
            mask[[self.index[n] for n in avoid if n in self.index]] = True
            self._avoid = (avoid, mask)
        mask = self._avoid[1]
        clear = [self.index[n] for n in stops if n in avoid and n in self.index]
        if clear:
            mask = mask.copy()
            mask[clear] = False
        return mask

    @property
    def car_like(self) -> bool:
        return self.turn_radius_m > 0

    def exits(
        self, arrived_by: Arc | None, node: str, heading_rad: float | None = None
    ) -> list[Arc]:
        """The arcs out of ``node`` after arriving by ``arrived_by``; standing there (None),
        facing ``heading_rad`` (None: any way, as a vehicle that turns on the spot)."""
        return [a for a, _ in self.exits_k(arrived_by, self.index[node], heading_rad)]

    def exits_k(
        self, arrived_by: Arc | None, node_k: int, heading_rad: float | None = None
    ) -> list[tuple[Arc, int]]:
        """``exits`` by node index, each arc with the index of its end."""
        if not self.car_like:
            return self.out_k[node_k]
        if arrived_by is not None:
            return self._exits[arrived_by]
        if heading_rad is None:
            return self.out_k[node_k]
        r, h = self.turn_radius_m, heading_rad
        return [(b, k) for b, k in self.out_k[node_k] if turn_fits(r, h, b, b.length_m)]

    def arc(self, start: str, end: str) -> Arc:
        a = self._arc.get((start, end))
        if a is None:
            raise KeyError(f"no edge {start} -> {end}")
        return a

    def times_to(self, goal: str) -> Times:
        """Shortest time (s) from every node that can reach ``goal`` (Dijkstra, reversed;
        the last tables, up to ``CACHED_FLOATS`` times in all, are kept). Do not modify the
        table returned."""
        got = self._times.get(goal)
        if got is not None:
            self._times.move_to_end(goal)
            return got
        self.prepare([goal])
        return self._times[goal]

    def prepare(self, goals: Iterable[str]) -> None:
        """Work out the tables to ``goals`` now (the ones not kept yet), in batches: one
        SciPy call for many goals costs far less than one call each."""
        todo = [g for g in dict.fromkeys(goals) if g not in self._times and g in self.index]
        keep = max(256, self.CACHED_FLOATS // max(len(self.ids), 1))
        for k in range(0, len(todo), 64):
            batch = todo[k : k + 64]
            dist = dijkstra(self._reversed, directed=True, indices=[self.index[g] for g in batch])
            for g, row in zip(batch, np.atleast_2d(dist), strict=True):
                self._times[g] = Times(self.index, row)
                if len(self._times) > keep:
                    self._times.popitem(last=False)

    def astar(self, start: str, goal: str) -> tuple[list[str], float] | None:
        """The quickest node path and its time (s), or None when ``goal`` is unreachable.
        The heuristic is the straight-line distance at the fastest arc speed (admissible)."""
        vmax = max((a.length_m / a.time_s for arcs in self.out.values() for a in arcs), default=1)
        gx, gy = self.layout.node_xy(goal)

        def h(n: str) -> float:
            x, y = self.layout.node_xy(n)
            return math.hypot(x - gx, y - gy) / vmax

        best = {start: 0.0}
        came: dict[str, str] = {}
        heap = [(h(start), 0.0, start)]
        while heap:
            _, g, n = heapq.heappop(heap)
            if n == goal:
                path = [n]
                while path[-1] in came:
                    path.append(came[path[-1]])
                return path[::-1], g
            if g > best[n]:
                continue
            for a in self.out[n]:
                ng = g + a.time_s
                if ng < best.get(a.end, math.inf):
                    best[a.end], came[a.end] = ng, n
                    heapq.heappush(heap, (ng + h(a.end), ng, a.end))
        return None
