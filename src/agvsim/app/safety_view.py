"""The safety scanners' field sets in the 3D view: under each robot with a scanner, the
active set's protective polygon (solid) and warning polygon (thinner), all in the status
colour (agvsim.sim.safety.STATUS_RGB: green clear, yellow warning, red protective). Drawn in
the robot's frame node, so they move with it; redrawn only when the set or status changes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import viser

from agvsim.sim.safety import STATUS_RGB, set_polygons
from agvsim.sim.spec import RobotSpec

FIELD_Z_M = 0.015  # just above the floor, under the body


def polygon_segments(polygon: Sequence[Sequence[float]], z_m: float = FIELD_Z_M) -> np.ndarray:
    """(n, 2, 3) float32 segments of a closed polygon's outline at height ``z_m``."""
    p = np.asarray(polygon, dtype=np.float32)
    p3 = np.column_stack([p, np.full(len(p), z_m, np.float32)])
    return np.stack([p3, np.roll(p3, -1, axis=0)], axis=1)


class FieldsView:
    """Keeps the field drawings of a scene's robots in step with the simulation."""

    def __init__(self) -> None:
        self._drawn: dict[int, tuple[tuple[int, int], list[Any]]] = {}

    def clear(self) -> None:
        """Forget the drawings (the robots' frames were rebuilt, taking them along)."""
        self._drawn = {}

    def update(
        self,
        server: viser.ViserServer,
        robots: Sequence[RobotSpec],
        active_set: np.ndarray,
        status: np.ndarray,
    ) -> None:
        for i, spec in enumerate(robots):
            if spec.safety is None or i >= len(active_set):
                continue
            now = (int(active_set[i]), int(status[i]))
            old = self._drawn.get(i)
            if old is not None and old[0] == now:
                continue
            for node in old[1] if old is not None else []:
                node.remove()
            r, g, b = (int(round(255 * c)) for c in STATUS_RGB[now[1]])
            rgb = (r, g, b)
            nodes = [
                server.scene.add_line_segments(
                    f"/robots/r{i}/safety_{kind}",
                    polygon_segments(poly),
                    colors=rgb,
                    thickness=4.0 if kind == "protective" else 2.0,
                    thickness_units="screen",
                )
                for kind, poly in set_polygons(spec.safety, now[0])
            ]
            self._drawn[i] = (now, nodes)
