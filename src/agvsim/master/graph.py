"""The layout as a routing graph for one vehicle type: directed edges with lengths and times.

An edge's time is its length over the slower of the edge's speed limit and the vehicle's top
speed (trajectories: the sampled NURBS length). Shortest times come from Dijkstra / A* over a
binary heap (``heapq``); networkx is not a dependency and the graph is small and plain.
"""

from __future__ import annotations

import heapq
import math
from collections import OrderedDict
from dataclasses import dataclass

from agvsim.world.lif import Layout


@dataclass(frozen=True)
class Arc:
    edge_id: str
    start: str
    end: str
    length_m: float
    time_s: float


class RoadGraph:
    """Directed arcs of ``layout`` that ``vehicle_type`` may use (every arc when None)."""

    CACHED_GOALS = 256  # shortest-time tables kept (stations and homes repeat)

    def __init__(self, layout: Layout, vehicle_type: str | None, max_speed_m_s: float):
        self._times: OrderedDict[str, dict[str, float]] = OrderedDict()
        if max_speed_m_s <= 0:
            raise ValueError(f"max_speed_m_s {max_speed_m_s}: must be > 0")
        self.layout = layout
        self.out: dict[str, list[Arc]] = {n: [] for n in layout.nodes}
        self.into: dict[str, list[Arc]] = {n: [] for n in layout.nodes}
        for e in sorted(layout.edges.values(), key=lambda e: e.edge_id):
            props = e.types.get(vehicle_type) if vehicle_type is not None else None
            if vehicle_type is not None and props is None:
                continue
            if props is not None and props.trajectory is not None:
                pts = props.trajectory.sample(64)
                length = float(sum(math.dist(a, b) for a, b in zip(pts[:-1], pts[1:], strict=True)))
            else:
                length = math.dist(layout.node_xy(e.start), layout.node_xy(e.end))
            limit = props.max_speed_m_s if props is not None else None
            speed = max_speed_m_s if limit is None else min(limit, max_speed_m_s)
            arc = Arc(e.edge_id, e.start, e.end, length, length / speed)
            self.out[e.start].append(arc)
            self.into[e.end].append(arc)

    def arc(self, start: str, end: str) -> Arc:
        for a in self.out[start]:
            if a.end == end:
                return a
        raise KeyError(f"no edge {start} -> {end}")

    def times_to(self, goal: str) -> dict[str, float]:
        """Shortest time (s) from every node that can reach ``goal`` (Dijkstra, reversed;
        the last ``CACHED_GOALS`` tables are kept). Do not modify the table returned."""
        if goal in self._times:
            self._times.move_to_end(goal)
            return self._times[goal]
        best = self._dijkstra_to(goal)
        self._times[goal] = best
        if len(self._times) > self.CACHED_GOALS:
            self._times.popitem(last=False)
        return best

    def _dijkstra_to(self, goal: str) -> dict[str, float]:
        best = {goal: 0.0}
        heap = [(0.0, goal)]
        while heap:
            t, n = heapq.heappop(heap)
            if t > best[n]:
                continue
            for a in self.into[n]:
                nt = t + a.time_s
                if nt < best.get(a.start, math.inf):
                    best[a.start] = nt
                    heapq.heappush(heap, (nt, a.start))
        return best

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
