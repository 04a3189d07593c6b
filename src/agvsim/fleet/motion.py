"""Edge following: the released route as one path, driven with the robot's own kinematics.

A ``Leg`` is the stretch from the node the vehicle stands on to the next node it must stop at
(the end of the base, or a node whose actions forbid driving): the edges' NURBS trajectories
(sampled) or straight lines, joined into one polyline. It is followed by pure pursuit, with the
steering law every behaviour shares (``agvsim.control.mobility.pursuit_twist``: holonomic models
translate, models that turn on the spot turn, car-like ones clip the curvature to their lock)
and the progress rules of ``agvsim.control.pure_pursuit.PurePursuit`` (monotone arc-length
progress searched in a window ahead, a carrot ``lookahead_m`` further on, slowing down over the
last lookahead to stop within the tolerance). The progress is tracked here in plain Python:
legs have a handful of segments, and per-call NumPy overhead on such tiny arrays cost more than
the arithmetic, for each of a thousand vehicles every step. Each node keeps its arc length
along the leg, so passing it is a comparison with the progress.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Sequence

import numpy as np

from agvsim.control.mobility import Mobility, pursuit_twist
from agvsim.fleet.order import OrderEdge, OrderNode

NURBS_SAMPLES = 32
MAX_TURN_RATE_RAD_S = 1.5


def edge_points(edge: OrderEdge, b: OrderNode) -> list[tuple[float, float]]:
    """Points of the edge after its start node, ending on its end node ``b``."""
    if edge.trajectory is None:
        return [b.xy]
    pts = [(float(x), float(y)) for x, y in edge.trajectory.sample(NURBS_SAMPLES)[1:]]
    if math.hypot(pts[-1][0] - b.xy[0], pts[-1][1] - b.xy[1]) > 1e-6:
        pts.append(b.xy)
    return pts


class Leg:
    """Follow ``nodes[0] -> nodes[-1]`` over ``edges``; ``speeds`` (m/s) per edge."""

    def __init__(
        self,
        nodes: Sequence[OrderNode],
        edges: Sequence[OrderEdge],
        speeds: Sequence[float],
        lookahead_m: float,
        tolerance_m: float,
    ):
        self.lookahead_m = lookahead_m
        self.nodes: list[OrderNode] = [nodes[0]]  # the leg's nodes (objects: loops repeat ids)
        self.node_s: list[float] = [0.0]
        self.speeds: list[float] = []
        self._where: dict[int, int] = {id(nodes[0]): 0}  # id(node) -> index (nodes live on)
        self.pts: list[tuple[float, float]] = [nodes[0].xy]
        self.cum: list[float] = [0.0]
        self.s = 0.0
        self.reached = False
        self.extend(nodes, edges, speeds, tolerance_m)

    def extend(
        self,
        nodes: Sequence[OrderNode],
        edges: Sequence[OrderEdge],
        speeds: Sequence[float],
        tolerance_m: float,
    ) -> None:
        """Append edges (``nodes[0]`` is the current end of the leg); progress is kept."""
        for e, b, v in zip(edges, nodes[1:], speeds, strict=True):
            for p in edge_points(e, b):
                last = self.pts[-1]
                d = math.hypot(p[0] - last[0], p[1] - last[1])
                if d > 1e-9:
                    self.pts.append(p)
                    self.cum.append(self.cum[-1] + d)
            self._where[id(b)] = len(self.nodes)
            self.nodes.append(b)
            self.node_s.append(self.cum[-1])
            self.speeds.append(v)
        self.tolerance_m = tolerance_m
        self.reached = len(self.pts) < 2

    @property
    def node_ids(self) -> list[str]:
        return [n.node_id for n in self.nodes]

    def index(self, node: OrderNode) -> int | None:
        """Where ``node`` (this very object) is on the leg."""
        return self._where.get(id(node))

    @property
    def length_m(self) -> float:
        return self.cum[-1]

    def speed_here(self) -> float:
        k = bisect_right(self.node_s, self.s) - 1
        return self.speeds[min(max(k, 0), len(self.speeds) - 1)] if self.speeds else 0.0

    def point_at(self, s: float) -> tuple[tuple[float, float], float]:
        """Point and tangent heading at arc length ``s`` (clamped to the leg)."""
        s = min(max(s, 0.0), self.cum[-1])
        i = min(max(bisect_right(self.cum, s) - 1, 0), len(self.pts) - 2)
        (ax, ay), (bx, by) = self.pts[i], self.pts[i + 1]
        ln = self.cum[i + 1] - self.cum[i]
        t = 0.0 if ln <= 0 else (s - self.cum[i]) / ln
        return (ax + t * (bx - ax), ay + t * (by - ay)), math.atan2(by - ay, bx - ax)

    def project(self, x: float, y: float, window_m: float) -> None:
        """Advance the progress to the closest path point within ``window_m`` ahead."""
        s0, cum, pts = self.s, self.cum, self.pts
        best, best_d = s0, math.inf
        i = max(bisect_right(cum, s0) - 1, 0)
        while i < len(pts) - 1 and cum[i] <= s0 + window_m:
            (ax, ay), (bx, by) = pts[i], pts[i + 1]
            dx, dy = bx - ax, by - ay
            ln2 = dx * dx + dy * dy
            t = min(max(((x - ax) * dx + (y - ay) * dy) / ln2, 0.0), 1.0)
            d = math.hypot(ax + t * dx - x, ay + t * dy - y)
            if d < best_d:
                best, best_d = cum[i] + t * (cum[i + 1] - cum[i]), d
            i += 1
        self.s = max(best, s0)

    def twist(self, pose: np.ndarray, mob: Mobility) -> tuple[float, float, float]:
        if self.reached:
            return 0.0, 0.0, 0.0
        x, y = float(pose[0]), float(pose[1])
        ld = max(self.lookahead_m, 1.2 * mob.min_radius_m)
        self.project(x, y, ld + 0.5)
        end = self.pts[-1]
        to_end = math.hypot(end[0] - x, end[1] - y)
        remaining = self.cum[-1] - self.s
        if remaining < ld and to_end < self.tolerance_m:
            self.reached = True
            return 0.0, 0.0, 0.0
        target, heading = self.point_at(self.s + ld)
        speed = self.speed_here()
        if remaining < ld:
            target = end
            speed = min(speed, max(0.1, to_end) * speed)
        return pursuit_twist(
            pose,
            np.asarray(target),
            speed,
            mob,
            travel_heading_rad=heading,
            max_turn_rate_rad_s=MAX_TURN_RATE_RAD_S,
        )

    def ahead(self, length_m: float, step_m: float = 0.05) -> np.ndarray:
        """(M, 2) path points from the current progress to ``length_m`` further on."""
        if len(self.pts) < 2:
            return np.array(self.pts)
        s = np.arange(self.s, min(self.s + length_m, self.cum[-1]) + 1e-9, step_m)
        pts = np.asarray(self.pts)
        return np.column_stack(
            [np.interp(s, self.cum, pts[:, 0]), np.interp(s, self.cum, pts[:, 1])]
        )
