"""Edge following: the released route as one path, driven with the robot's own kinematics.

A ``Leg`` is the stretch from the node the vehicle stands on to the next node it must stop at
(the end of the base, or a node whose actions forbid driving): the edges' NURBS trajectories
(sampled) or straight lines, joined into one polyline, followed by the existing pure-pursuit
controller (``agvsim.control.pure_pursuit``), which knows how each kind of model moves. Each
node keeps its arc length along the leg, so passing it is a comparison with the progress.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agvsim.control.mobility import Mobility
from agvsim.control.pure_pursuit import PurePursuit
from agvsim.fleet.order import OrderEdge, OrderNode

NURBS_SAMPLES = 32


def edge_points(edge: OrderEdge, a: OrderNode, b: OrderNode) -> np.ndarray:
    """(K, 2) points of the edge after its start node, ending on its end node."""
    if edge.trajectory is None:
        return np.array([b.xy])
    pts = edge.trajectory.sample(NURBS_SAMPLES)
    return np.vstack([pts[1:], [b.xy]]) if np.hypot(*(pts[-1] - b.xy)) > 1e-6 else pts[1:]


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
        self.lookahead_m, self.tolerance_m = lookahead_m, tolerance_m
        self.nodes: list[OrderNode] = [nodes[0]]  # the leg's nodes (objects: loops repeat ids)
        self.node_s: list[float] = [0.0]
        self.speeds: list[float] = []
        self._points = [np.array([nodes[0].xy])]
        self._pp: PurePursuit | None = None
        self.extend(nodes, edges, speeds, tolerance_m)

    def extend(
        self,
        nodes: Sequence[OrderNode],
        edges: Sequence[OrderEdge],
        speeds: Sequence[float],
        tolerance_m: float,
    ) -> None:
        """Append edges (``nodes[0]`` is the current end of the leg); progress is kept."""
        for e, a, b, v in zip(edges, nodes[:-1], nodes[1:], speeds, strict=True):
            self._points.append(edge_points(e, a, b))
            self.nodes.append(b)
            self.speeds.append(v)
        pts = np.vstack(self._points)
        keep = np.ones(len(pts), dtype=bool)
        keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-9
        self.points = pts[keep]
        seg = np.hypot(*np.diff(self.points, axis=0).T) if len(self.points) > 1 else np.zeros(0)
        self.cum = np.concatenate([[0.0], np.cumsum(seg)])
        # each node's arc length: the end of its edge's points
        ends = np.cumsum([len(p) for p in self._points]) - 1
        kept_index = np.cumsum(keep) - 1
        self.node_s = [float(self.cum[kept_index[i]]) for i in ends]
        s0 = 0.0 if self._pp is None else self._pp.tracker.s
        self.tolerance_m = tolerance_m
        if len(self.points) > 1:
            self._pp = PurePursuit(
                self.points, self.lookahead_m, max(self.speeds or [0.1]), tolerance_m=tolerance_m
            )
            self._pp.tracker.s = s0
        else:
            self._pp = None

    @property
    def node_ids(self) -> list[str]:
        return [n.node_id for n in self.nodes]

    def index(self, node: OrderNode) -> int | None:
        """Where ``node`` (this very object) is on the leg."""
        return next((k for k, n in enumerate(self.nodes) if n is node), None)

    @property
    def length_m(self) -> float:
        return float(self.cum[-1])

    @property
    def s(self) -> float:
        return 0.0 if self._pp is None else float(self._pp.tracker.s)

    @property
    def reached(self) -> bool:
        return self._pp is None or self._pp.state_name == "reached"

    def speed_here(self) -> float:
        k = int(np.searchsorted(self.node_s, self.s, side="right")) - 1
        return self.speeds[min(max(k, 0), len(self.speeds) - 1)] if self.speeds else 0.0

    def twist(self, pose: np.ndarray, mob: Mobility) -> tuple[float, float, float]:
        if self._pp is None:
            return 0.0, 0.0, 0.0
        self._pp.speed = self.speed_here()
        return self._pp.twist(pose, mob)

    def ahead(self, length_m: float, step_m: float = 0.05) -> np.ndarray:
        """(M, 2) path points from the current progress to ``length_m`` further on."""
        if len(self.points) < 2:
            return self.points.copy()
        s = np.arange(self.s, min(self.s + length_m, self.length_m) + 1e-9, step_m)
        return np.column_stack(
            [np.interp(s, self.cum, self.points[:, 0]), np.interp(s, self.cum, self.points[:, 1])]
        )
