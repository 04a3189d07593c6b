"""How much of a maze one robot covered: cells its body centre visited, cells its lidar saw, and
whether (and when) it came back to where it started.

The cells counted are the **free cells reachable from the start cell**: the start cell's
4-connected region of free cells (a robot cannot reach the other regions; diagonal gaps
between two wall cells are not passages). They are split, for the report, into the
**wall-side cells** (a wall among their 8 neighbours: the corridor cells a wall follower runs
through) and the **open cells** (room interiors at least one cell away from every wall).

A cell is *seen* when a beam of the latest scan passed through it, or ended on the wall at its
edge; beams are walked over the grid with an exact cell traversal every time the sensor fired.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from pydantic import BaseModel, ConfigDict, Field
from scipy import ndimage

from agvsim.angles import wrap_scalar
from agvsim.world.grid import OccupancyGrid


class CorridorCoverage:
    """Metric: coverage of the maze by robot ``robot_index``.

    ``sensor_slot``: the simulation's sensor slot whose beams count as seeing (None: the
    robot's sensor with the most beams; no sensor: no seen cells). ``stop_on_return``: end the
    run when the robot is back at the start. Back means within ``return_radius_m`` of the start
    position after having been more than ``leave_radius_m`` away from it, and, when
    ``return_heading_tol_rad`` is given, heading within that of the start heading (a wall
    follower passes its start in the other lane of a corridor on its way out: that is not
    back at the start).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        robot_index: int,
        sensor_slot: int | None = None,
        stop_on_return: bool = True,
        return_radius_m: float = 1.0,
        leave_radius_m: float = 3.0,
        return_heading_tol_rad: float | None = None,
    ):
        self.grid, self.robot = grid, int(robot_index)
        self.sensor_slot = sensor_slot
        self.stop_on_return = stop_on_return
        self.return_radius_m, self.leave_radius_m = return_radius_m, leave_radius_m
        self.heading_tol = return_heading_tol_rad
        self.reachable = np.zeros(grid.occupied.shape, dtype=bool)
        self.wall_side = np.zeros_like(self.reachable)
        self.visited = np.zeros_like(self.reachable)
        self.seen = np.zeros_like(self.reachable)
        self.start_xy: np.ndarray | None = None
        self.start_heading = 0.0
        self.left = False  # has been further than leave_radius_m from the start
        self.return_time_s: float | None = None
        self._stamp = -math.inf
        self._table = np.ascontiguousarray(grid.occupied.astype(np.uint8))

    # ------------------------------------------------------------------ the metric protocol
    def update(self, sim) -> bool:
        """Record the current step; True asks the run to end (back at the start)."""
        st, i = sim.state, self.robot
        centre = self._centre(sim)
        if self.start_xy is None:
            self._begin(sim)
        row, col = self.grid.cell_of(centre[0], centre[1])
        if 0 <= row < self.grid.rows and 0 <= col < self.grid.cols:
            self.visited[row, col] = True
        self._look(sim)
        away = float(np.hypot(*(st.poses[i, :2] - self.start_xy)))
        if away > self.leave_radius_m:
            self.left = True
        elif self.left and self.return_time_s is None and away <= self.return_radius_m:
            turn = abs(wrap_scalar(float(st.poses[i, 2]) - self.start_heading))
            if self.heading_tol is None or turn <= self.heading_tol:
                self.return_time_s = float(st.t_s)
        return self.stop_on_return and self.return_time_s is not None

    def result(self) -> dict:
        n = int(self.reachable.sum())
        open_cells = self.reachable & ~self.wall_side

        def frac(done: np.ndarray, of: np.ndarray) -> float:
            total = int(of.sum())
            return round(float((done & of).sum()) / total, 4) if total else 0.0

        return {
            "reachable_cells": n,
            "wall_side_cells": int(self.wall_side.sum()),
            "visited_cells": int((self.visited & self.reachable).sum()),
            "visited_fraction": frac(self.visited, self.reachable),
            "wall_side_visited_fraction": frac(self.visited, self.wall_side),
            "open_visited_fraction": frac(self.visited, open_cells),
            "seen_cells": int((self.seen & self.reachable).sum()),
            "seen_fraction": frac(self.seen, self.reachable),
            "returned_to_start": self.return_time_s is not None,
            "return_time_s": self.return_time_s,
        }

    # ------------------------------------------------------------------ internals
    def _centre(self, sim, pose: np.ndarray | None = None) -> np.ndarray:
        """The body centre (the footprint's centre, ahead of P on car-like models)."""
        x, y, th = sim.state.poses[self.robot] if pose is None else pose
        off = sim.robots[self.robot].body_offset_x_m
        return np.array([x + off * math.cos(th), y + off * math.sin(th)])

    def _begin(self, sim) -> None:
        """The start is the robot's initial pose (the first update may come after a step)."""
        start = np.asarray(sim.robots[self.robot].initial_pose, dtype=np.float64)
        self.start_xy, self.start_heading = start[:2].copy(), float(start[2])
        centre = self._centre(sim, start)
        row, col = self.grid.cell_of(centre[0], centre[1])
        free = ~self.grid.occupied
        if not (0 <= row < self.grid.rows and 0 <= col < self.grid.cols) or not free[row, col]:
            raise ValueError(f"robot {self.robot} does not start on a free cell of the map")
        labels, _ = ndimage.label(free)  # 4-connectivity
        self.reachable = labels == labels[row, col]
        self.visited[row, col] = True
        near_wall = ndimage.binary_dilation(
            self.grid.occupied, structure=np.ones((3, 3), dtype=bool), border_value=1
        )
        self.wall_side = self.reachable & near_wall
        if self.sensor_slot is None:
            slots = sim.sensors.slots_of[self.robot]
            if slots:
                self.sensor_slot = max(slots, key=lambda k: sim.sensors.specs[k].num_beams)

    def _look(self, sim) -> None:
        """Walk the beams of the sensor's scan when it has fired since the last look."""
        slot = self.sensor_slot
        if slot is None or sim.state.scan_stamp[slot] == self._stamp:
            return
        self._stamp = float(sim.state.scan_stamp[slot])
        scan = sim.scan(slot)
        spec = sim.sensors.specs[slot]
        x, y, th = sim.state.poses[self.robot]
        mx, my = spec.mount_xy_m
        ox = x + math.cos(th) * mx - math.sin(th) * my
        oy = y + math.sin(th) * mx + math.cos(th) * my
        angles = (
            th + scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(scan.ranges.size)
        )
        r = scan.ranges
        length = np.where(np.isfinite(r), r, np.where(r > 0, scan.range_max_m, scan.range_min_m))
        gx, gy = self.grid.origin_xy_m
        _mark_beams(
            self._table,
            self.seen,
            ox,
            oy,
            np.ascontiguousarray(angles),
            np.ascontiguousarray(length),
            gx,
            gy,
            self.grid.resolution_m,
        )


@njit(cache=True, error_model="numpy")
def _mark_beams(occ, seen, ox, oy, angles, lengths, gx, gy, res) -> None:
    """Mark in ``seen (rows, cols)`` every free cell that beams from (ox, oy) pass through, up
    to their length or the first wall cell (Amanatides-Woo traversal; row 0 is north)."""
    rows, cols = occ.shape
    fx, fy = (ox - gx) / res, (oy - gy) / res  # in cells, y up from the south edge
    for b in range(angles.shape[0]):
        dx, dy = math.cos(angles[b]), math.sin(angles[b])
        ix, iy = int(math.floor(fx)), int(math.floor(fy))
        sx = 1 if dx > 0 else -1
        sy = 1 if dy > 0 else -1
        tdx = abs(1.0 / dx) if dx != 0.0 else np.inf
        tdy = abs(1.0 / dy) if dy != 0.0 else np.inf
        tx = ((ix + 1 - fx) if dx > 0 else (fx - ix)) * tdx if dx != 0.0 else np.inf
        ty = ((iy + 1 - fy) if dy > 0 else (fy - iy)) * tdy if dy != 0.0 else np.inf
        t_end = lengths[b] / res
        t = 0.0
        while True:
            if ix < 0 or iy < 0 or ix >= cols or iy >= rows:
                break
            row = rows - 1 - iy
            if occ[row, ix]:
                break
            seen[row, ix] = True
            if t >= t_end:
                break
            if tx < ty:
                t, tx, ix = tx, tx + tdx, ix + sx
            else:
                t, ty, iy = ty, ty + tdy, iy + sy
            if t > t_end + 1e-9:
                break


class CoverageConfig(BaseModel):
    """``metrics: {coverage: {robot: agv1}}``: cells visited and seen, return to the start."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    robot: str = Field(min_length=1, description="robot name")
    sensor: str | None = Field(None, description="sensor whose beams see (default: most beams)")
    end_run: bool = Field(True, description="stop the run when back at the start")
    return_radius_m: float = Field(1.0, gt=0, le=1000)
    leave_radius_m: float = Field(3.0, gt=0, le=1000)
    return_heading_tol_deg: float | None = Field(
        None, gt=0, le=180, description="also back to the start heading, within this"
    )


def build_coverage(cfg: CoverageConfig, sim) -> CorridorCoverage:
    """The metric for a built simulation (it needs the map and the robot's sensors)."""
    names = [r.name for r in sim.robots]
    if cfg.robot not in names:
        raise ValueError(f"metrics.coverage.robot: no robot named {cfg.robot!r}; robots: {names}")
    i = names.index(cfg.robot)
    slot = None
    if cfg.sensor is not None:
        own = {sim.sensors.specs[k].name: k for k in sim.sensors.slots_of[i]}
        if cfg.sensor not in own:
            raise ValueError(
                f"metrics.coverage.sensor: robot {cfg.robot!r} has no sensor {cfg.sensor!r}; "
                f"it has {sorted(own)}"
            )
        slot = own[cfg.sensor]
    tol = cfg.return_heading_tol_deg
    return CorridorCoverage(
        sim.world.grid,
        i,
        slot,
        stop_on_return=cfg.end_run,
        return_radius_m=cfg.return_radius_m,
        leave_radius_m=cfg.leave_radius_m,
        return_heading_tol_rad=None if tol is None else math.radians(tol),
    )
