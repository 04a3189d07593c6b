"""Edge following: the released route as one path, driven with the robot's own kinematics.

A ``Leg`` is the stretch from the node the vehicle stands on to the next node it must stop at
(the end of the base, or a node whose actions forbid driving): the edges' NURBS trajectories
(sampled) or straight lines, joined into one polyline. It is followed by pure pursuit, with the
steering law every behaviour shares (``agvsim.control.mobility.pursuit_twist``, whose numba twin
``agvsim.fleet.bank.pursuit`` is used here: holonomic models translate, models that turn on the
spot turn, car-like ones clip the curvature to their lock) and the progress rules of
``agvsim.control.pure_pursuit.PurePursuit`` (monotone arc-length progress searched in a window
ahead, a carrot ``lookahead_m`` further on, slowing down over the last lookahead to stop within
the tolerance). The geometry and the progress live in a ``VehicleBank`` row (``attach``), where
the fleet's batch tick follows the leg for every quiet vehicle at once and ``twist`` follows it
for one, with the same kernel (``agvsim.fleet.bank.follow``). Each node keeps its arc length
along the leg, so passing it is a comparison with the progress.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agvsim.control.mobility import Mobility
from agvsim.fleet.bank import VehicleBank, follow
from agvsim.fleet.order import OrderEdge, OrderNode

NURBS_SAMPLES = 32


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
        self._bank: VehicleBank | None = None
        self._slot = 0
        self._s = 0.0
        self._reached = False
        self.extend(nodes, edges, speeds, tolerance_m)

    def attach(self, bank: VehicleBank, slot: int) -> None:
        """Put the leg into row ``slot`` of ``bank`` (its progress lives there from now on);
        again after an extension, to re-read the geometry."""
        s, reached = self.s, self.reached
        bank.set_leg(
            slot, self.pts, self.cum, self.node_s, self.speeds, self.lookahead_m, self.tolerance_m
        )
        self._bank, self._slot = bank, slot
        self.s, self.reached = s, reached

    @property
    def s(self) -> float:
        """Progress along the leg (m)."""
        return self._s if self._bank is None else float(self._bank.s[self._slot])

    @s.setter
    def s(self, value: float) -> None:
        if self._bank is None:
            self._s = value
        else:
            self._bank.s[self._slot] = value

    @property
    def reached(self) -> bool:
        return self._reached if self._bank is None else bool(self._bank.reached[self._slot])

    @reached.setter
    def reached(self, value: bool) -> None:
        if self._bank is None:
            self._reached = value
        else:
            self._bank.reached[self._slot] = value

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
        if self._bank is not None:  # the bank's copy of the geometry follows
            self.attach(self._bank, self._slot)

    @property
    def node_ids(self) -> list[str]:
        return [n.node_id for n in self.nodes]

    def index(self, node: OrderNode) -> int | None:
        """Where ``node`` (this very object) is on the leg."""
        return self._where.get(id(node))

    @property
    def length_m(self) -> float:
        return self.cum[-1]

    def twist(self, pose: np.ndarray, mob: Mobility) -> tuple[float, float, float]:
        """The body twist to follow the leg from ``pose``; advances the progress and sets
        ``reached`` within the tolerance of the end (``agvsim.fleet.bank.follow``)."""
        if self.reached:
            return 0.0, 0.0, 0.0
        if self._bank is None:
            self.attach(VehicleBank(1, points=len(self.pts)), 0)
        b, k = self._bank, self._slot
        assert b is not None
        s, vx, vy, w, done = follow(
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            float(b.s[k]),
            int(b.pstart[k]),
            int(b.npts[k]),
            b.px,
            b.py,
            b.cum,
            int(b.nstart[k]),
            int(b.nnodes[k]),
            b.node_s,
            b.speed,
            self.lookahead_m,
            self.tolerance_m,
            mob.holonomic,
            mob.can_spin,
            mob.max_curvature_1_m,
            mob.min_radius_m,
        )
        b.s[k] = s
        if done:
            b.reached[k] = True
            return 0.0, 0.0, 0.0
        return vx, vy, w

    def ahead(self, length_m: float, step_m: float = 0.05) -> np.ndarray:
        """(M, 2) path points from the current progress to ``length_m`` further on."""
        if len(self.pts) < 2:
            return np.array(self.pts)
        s = np.arange(self.s, min(self.s + length_m, self.cum[-1]) + 1e-9, step_m)
        pts = np.asarray(self.pts)
        return np.column_stack(
            [np.interp(s, self.cum, pts[:, 0]), np.interp(s, self.cum, pts[:, 1])]
        )
