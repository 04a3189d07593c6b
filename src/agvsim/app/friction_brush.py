"""The world editor's floor-friction brush: a click paints one map cell with its own
friction coefficient. The cell becomes a ``world.floor.regions`` rectangle (a later one
wins where they overlap, so repainting a cell works), kept in the scenario the session
saves and restarts from; robots with dynamics feel it from the next step
(docs/dynamics.md; kinematic robots ignore friction).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from agvsim.dynamics import FloorFriction, FrictionRegion

if TYPE_CHECKING:
    from agvsim.app.session import Session


def paint_friction(session: Session, row: int, col: int, mu: float) -> FrictionRegion:
    """Give map cell (row, col) the friction coefficient ``mu``; returns its region.
    Raises ValueError for a cell off the map or a ``mu`` that is not positive."""
    with session.lock:
        grid = session.sim.world.grid
        if not (0 <= row < grid.rows and 0 <= col < grid.cols):
            raise ValueError(f"cell ({row}, {col}) is outside the {grid.rows} x {grid.cols} map")
        cx, cy = grid.cell_center(row, col)
        half = 0.5 * grid.resolution_m
        x, y = float(cx), float(cy)
        region = FrictionRegion(
            x - half, y - half, x + half, y + half, float(mu), f"brush {row},{col}"
        )
        old = session.sim.world.floor
        session.sim.set_floor(FloorFriction(old.mu, (*old.regions, region)))
        world = dict(session.config["world"])
        floor = dict(world.get("floor") or {})
        floor["regions"] = [
            *floor.get("regions", []),
            {
                "name": region.name,
                "x_min_m": region.x_min_m,
                "y_min_m": region.y_min_m,
                "x_max_m": region.x_max_m,
                "y_max_m": region.y_max_m,
                "mu": region.mu,
            },
        ]
        world["floor"] = floor
        session.config = {**session.config, "world": world}
        return region
