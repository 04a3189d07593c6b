"""Planning on a known occupancy grid: clearance map, A*, and footprint checks.

1. **Clearance map.** The walls are rasterised at ``fine_resolution_m`` and a Euclidean distance
   transform gives every point's distance to the nearest wall (the map's edge counts as wall).
2. **A*** runs on a lattice of ``plan_resolution_m`` cells (8- or 4-connected, no corner
   cutting). A cell closer to a wall than the robot's half width + ``clearance_m`` is blocked;
   a free cell costs ``1 + clearance_weight * max(0, 1 - d / preferred_clearance_m)`` per metre,
   so the path keeps to the middle of corridors. The heuristic is the straight-line distance
   (admissible: no metre costs less than 1).
3. **Footprint.** Points on the robot's rectangle (grown by a margin) are tested against the
   grid at poses along an arc (``arc_pose``), to check a motion before making it.

Used by :class:`agvsim.control.maze_solver.AStarMazeSolver`.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from agvsim.world.grid import OccupancyGrid


# ------------------------------------------------------------------------------------ planning
class ClearanceMap:
    """Distance to the nearest wall (m) on a fine raster of ``grid``, and the coarser planning
    lattice sampled from it. Cells are indexed like the grid: row 0 north."""

    def __init__(
        self, grid: OccupancyGrid, plan_resolution_m: float = 0.25, fine_resolution_m: float = 0.05
    ):
        up = max(1, math.ceil(grid.resolution_m / fine_resolution_m - 1e-9))
        occ = np.repeat(np.repeat(grid.occupied, up, axis=0), up, axis=1)
        self.fine_m = grid.resolution_m / up
        padded = np.pad(occ, 1, constant_values=True)  # outside the map is wall
        edt = ndimage.distance_transform_edt(~padded)[1:-1, 1:-1]
        # centre-to-centre distance -> distance to the wall cell's edge
        self.fine = np.maximum(edt * self.fine_m - 0.5 * self.fine_m, 0.0)
        self.stride = max(1, round(plan_resolution_m / self.fine_m))
        self.res_m = self.stride * self.fine_m
        rows = math.ceil(occ.shape[0] / self.stride)
        cols = math.ceil(occ.shape[1] / self.stride)
        ri = np.minimum(np.arange(rows) * self.stride + self.stride // 2, occ.shape[0] - 1)
        ci = np.minimum(np.arange(cols) * self.stride + self.stride // 2, occ.shape[1] - 1)
        self.dist = self.fine[np.ix_(ri, ci)]  # (rows, cols) m
        self.origin = grid.origin_xy_m
        self.height_m = grid.height_m
        self.grid = grid

    @property
    def shape(self) -> tuple[int, int]:
        return self.dist.shape  # type: ignore[return-value]

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        col = math.floor((x - self.origin[0]) / self.res_m)
        row = math.floor((self.origin[1] + self.height_m - y) / self.res_m)
        r, c = self.shape
        return min(max(row, 0), r - 1), min(max(col, 0), c - 1)

    def center(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(K, 2) world x, y of lattice cells (rows, cols)."""
        x = self.origin[0] + (np.asarray(cols) + 0.5) * self.res_m
        y = self.origin[1] + self.height_m - (np.asarray(rows) + 0.5) * self.res_m
        return np.stack([x, y], axis=-1)


def astar(
    cost: np.ndarray, start: tuple[int, int], goal: tuple[int, int], connectivity: int = 8
) -> list[tuple[int, int]] | None:
    """Cheapest lattice path from ``start`` to ``goal`` (both (row, col)), or None.

    ``cost (R, C)``: cost per metre of entering a cell (>= 1; inf = blocked). A step costs its
    length (1 or sqrt 2 cells) times the cost of the cell it enters; diagonal steps may not cut
    a blocked corner. Heuristic: Euclidean distance in cells (admissible as cost >= 1)."""
    if connectivity not in (4, 8):
        raise ValueError(f"connectivity must be 4 or 8, got {connectivity}")
    rows, cols = cost.shape
    moves = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0)]
    if connectivity == 8:
        r2 = math.sqrt(2.0)
        moves += [(-1, -1, r2), (-1, 1, r2), (1, -1, r2), (1, 1, r2)]
    free = np.isfinite(cost)
    cost_l = cost.tolist()
    free_l = free.tolist()
    gr, gc = goal
    g_best = {start: 0.0}
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    heap = [(math.hypot(start[0] - gr, start[1] - gc), 0.0, start)]
    closed = set()
    while heap:
        _, g, node = heapq.heappop(heap)
        if node in closed:
            continue
        if node == goal:
            path = [node]
            while node in parent:
                node = parent[node]
                path.append(node)
            return path[::-1]
        closed.add(node)
        r, c = node
        for dr, dc, step in moves:
            nr, nc = r + dr, c + dc
            if not (0 <= nr < rows and 0 <= nc < cols) or not free_l[nr][nc]:
                continue
            if dr and dc and not (free_l[r][nc] and free_l[nr][c]):
                continue
            ng = g + step * cost_l[nr][nc]
            nxt = (nr, nc)
            if ng < g_best.get(nxt, math.inf):
                g_best[nxt] = ng
                parent[nxt] = node
                heapq.heappush(heap, (ng + math.hypot(nr - gr, nc - gc), ng, nxt))
    return None


def plan_path(
    cmap: ClearanceMap,
    start_xy: Sequence[float] | np.ndarray,
    goal_xy: Sequence[float] | np.ndarray,
    half_width_m: float,
    clearance_m: float = 0.05,
    preferred_clearance_m: float = 1.0,
    clearance_weight: float = 4.0,
    connectivity: int = 8,
) -> np.ndarray | None:
    """World path ``(K, 2)`` from start to goal keeping clear of walls (see the module
    docstring), or None. The start and goal cells are never blocked; if no path keeps the full
    clearance, it is retried with the bare half width."""
    d = cmap.dist
    pref = max(preferred_clearance_m, 1e-6)
    base = 1.0 + clearance_weight * np.clip(1.0 - d / pref, 0.0, 1.0)
    s, g = cmap.cell_of(*start_xy), cmap.cell_of(*goal_xy)
    for hard in (half_width_m + clearance_m, half_width_m):
        cost = np.where(d > hard, base, np.inf)
        cost[s], cost[g] = base[s], base[g]
        cells = astar(cost, s, g, connectivity)
        if cells is not None:
            break
    else:
        return None
    rc = np.array(cells)
    pts = cmap.center(rc[:, 0], rc[:, 1])
    pts[0], pts[-1] = start_xy[:2], goal_xy[:2]
    if len(pts) > 4:  # smooth the lattice staircase, ends fixed
        inner = pts.copy()
        for _ in range(3):
            inner[1:-1] = 0.25 * inner[:-2] + 0.5 * inner[1:-1] + 0.25 * inner[2:]
        pts = inner
    return pts


# ------------------------------------------------------------------------------------ footprint
class Footprint:
    """Points on the robot's rectangle grown by ``margin_m``, in the robot frame, to test
    poses against the grid (spaced finer than a grid cell)."""

    def __init__(
        self,
        length_m: float,
        width_m: float,
        offset_x_m: float,
        margin_m: float,
        spacing_m: float,
    ):
        hl, hw = length_m / 2 + margin_m, width_m / 2 + margin_m
        nx = max(2, math.ceil(2 * hl / spacing_m) + 1)
        ny = max(2, math.ceil(2 * hw / spacing_m) + 1)
        xs, ys = np.linspace(-hl, hl, nx), np.linspace(-hw, hw, ny)
        self.points = np.concatenate(
            [
                np.stack([xs, np.full(nx, hw)], -1),
                np.stack([xs, np.full(nx, -hw)], -1),
                np.stack([np.full(ny, hl), ys], -1),
                np.stack([np.full(ny, -hl), ys], -1),
            ]
        ) + np.array([offset_x_m, 0.0])

    def hits(self, grid: OccupancyGrid, pose: np.ndarray) -> bool:
        c, s = math.cos(pose[2]), math.sin(pose[2])
        p = self.points
        return bool(
            grid.is_occupied_at(
                pose[0] + c * p[:, 0] - s * p[:, 1], pose[1] + s * p[:, 0] + c * p[:, 1]
            ).any()
        )


def arc_pose(pose: np.ndarray, curvature_1_m: float, s_m: float) -> np.ndarray:
    """Pose after driving signed arc length ``s_m`` at constant curvature."""
    a = curvature_1_m * s_m
    if abs(a) < 1e-9:
        dx, dy = s_m, 0.0
    else:
        dx, dy = math.sin(a) / curvature_1_m, (1.0 - math.cos(a)) / curvature_1_m
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy, pose[2] + a])
