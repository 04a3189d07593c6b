"""Maze solving: A* on the known map, and a map-less wall follower.

``AStarMazeSolver`` plans once on the world's occupancy grid and follows the path by pure
pursuit (:mod:`agvsim.control.goal`):

1. **Clearance map.** The walls are rasterised at ``fine_resolution_m`` and a Euclidean distance
   transform gives every point's distance to the nearest wall (the map's edge counts as wall).
2. **A*** runs on a lattice of ``plan_resolution_m`` cells (8- or 4-connected, no corner
   cutting). A cell closer to a wall than the robot's half width + ``clearance_m`` is blocked;
   a free cell costs ``1 + clearance_weight * max(0, 1 - d / preferred_clearance_m)`` per metre,
   so the path keeps to the middle of corridors. The heuristic is the straight-line distance
   (admissible: no metre costs less than 1).
3. **Following.** Pure pursuit on the path (lightly smoothed). The robot's footprint (grown
   by ``clearance_m``) is swept 0.25 m along the commanded motion and tested against the grid
   before moving. Models that turn on the spot and holonomic models shorten the lookahead
   (1, 1/2, 1/4) when the sweep touches a wall (a carrot across a tight corner), else turn on
   the spot. Car-like models (Ackermann, tricycle with limited steering) use a lookahead of at
   least 1.2 times their minimum turning radius and switch to a **K-turn** when the carrot is
   more than ``kturn_above_deg`` off their heading or the sweep touches a wall: full lock
   forward, then full opposite lock in reverse, changing gear whenever the sweep touches, until
   the carrot is within 30 deg ahead. Steered wheels are let reach their angle standing still
   (``SteeringGuard``) before the robot drives on; a car with no room either way stands
   ("stuck").

The robot is localised by the ground truth (``pose_source="true_pose"``, standing in for a map
localiser such as AMCL) or by its wheel odometry. It replans when it strays more than a metre
from the path or makes no progress for ``stuck_s`` seconds.

``TremauxExplorer`` knows no map: see its docstring.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator
from scipy import ndimage

from agvsim.control.api import ControllerContext, LaserScan, Observation, command_for
from agvsim.control.goal import (
    Mobility,
    PathTracker,
    PoseSource,
    SteeringGuard,
    check_pose_source,
    pose_of,
    pursuit_twist,
    wrap,
)
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
    start_xy: Sequence[float],
    goal_xy: Sequence[float],
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


# ------------------------------------------------------------------------------------ A* solver
class AStarMazeSolver:
    """Plan with A* on the known grid, then drive the path (see the module docstring).

    ``goal_cell`` is a (row, col) of ``grid``; or give ``goal_xy_m``. The body (``body_length_m``,
    ``body_width_m``, ``body_offset_x_m`` ahead of the reference point) sets the clearance and the
    swept-footprint checks. ``state_name``: "plan", "follow", "kturn_forward",
    "kturn_reverse", "steer" (waiting for the steering), "stuck" (a car with no room to move
    either way), "reached" or "no_path".
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        goal_cell: tuple[int, int] | None = None,
        goal_xy_m: Sequence[float] | None = None,
        body_length_m: float = 0.6,
        body_width_m: float = 0.45,
        body_offset_x_m: float = 0.0,
        speed_m_s: float = 0.8,
        lookahead_m: float = 0.8,
        connectivity: int = 8,
        clearance_m: float = 0.05,
        preferred_clearance_m: float = 1.0,
        plan_resolution_m: float = 0.25,
        goal_tolerance_m: float = 0.3,
        max_turn_rate_rad_s: float = 1.5,
        kturn_above_deg: float = 100.0,
        kturn_speed_m_s: float = 0.3,
        stuck_s: float = 8.0,
        pose_source: PoseSource = "true_pose",
    ):
        if (goal_cell is None) == (goal_xy_m is None):
            raise ValueError("give exactly one of goal_cell (row, col) or goal_xy_m (x, y)")
        check_pose_source(pose_source)
        if goal_cell is not None:
            r, c = (int(v) for v in goal_cell)
            if not (0 <= r < grid.rows and 0 <= c < grid.cols):
                raise ValueError(
                    f"goal_cell {goal_cell} is outside the {grid.rows}x{grid.cols} grid"
                )
            if grid.occupied[r, c]:
                raise ValueError(f"goal_cell {goal_cell} is a wall")
            gx, gy = grid.cell_center(r, c)
            goal_xy_m = (float(gx), float(gy))
        self.grid = grid
        self.goal = np.asarray(goal_xy_m, dtype=np.float64).reshape(2)
        self.half_width = body_width_m / 2
        self.speed, self.lookahead = speed_m_s, lookahead_m
        self.connectivity, self.clearance = connectivity, clearance_m
        self.preferred = preferred_clearance_m
        self.tolerance, self.max_turn = goal_tolerance_m, max_turn_rate_rad_s
        self.kturn_above = math.radians(kturn_above_deg)
        self.kturn_speed, self.stuck_s = kturn_speed_m_s, stuck_s
        self.pose_source = pose_source
        self.cmap = ClearanceMap(grid, plan_resolution_m)
        spacing = min(0.05, grid.resolution_m / 2)
        self.footprint = Footprint(
            body_length_m, body_width_m, body_offset_x_m, clearance_m, spacing
        )
        self.reset()

    def reset(self) -> None:
        self.state_name = "plan"
        self.tracker: PathTracker | None = None
        self.path: np.ndarray | None = None
        self.replans = 0
        self.gear = 0  # K-turn gear: +1 forward, -1 reverse, 0 not turning
        self.guard = SteeringGuard()
        self.best_progress = (-math.inf, 0.0)  # (progress, time)

    # ---------------------------------------------------------------- helpers
    def plan(self, xy: np.ndarray, t_s: float) -> bool:
        self.path = plan_path(
            self.cmap,
            xy,
            self.goal,
            self.half_width,
            self.clearance,
            self.preferred,
            connectivity=self.connectivity,
        )
        self.tracker = None if self.path is None else PathTracker(self.path)
        self.best_progress = (-math.inf, t_s)
        return self.path is not None

    def _blocked_along(self, pose: np.ndarray, curvature: float, gear: int, dist_m: float) -> bool:
        for s in (0.5 * dist_m, dist_m):
            if self.footprint.hits(self.grid, arc_pose(pose, curvature, gear * s)):
                return True
        return False

    # ---------------------------------------------------------------- the step
    def step(self, obs: Observation):
        pose = pose_of(obs, self.pose_source)
        if self.state_name in ("reached", "no_path"):
            return command_for(obs, 0.0, 0.0, 0.0)
        if math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1]) < self.tolerance:
            self.state_name = "reached"
            return command_for(obs, 0.0, 0.0, 0.0)
        if self.tracker is None and not self.plan(pose[:2], obs.t_s):
            self.state_name = "no_path"
            return command_for(obs, 0.0, 0.0, 0.0)
        mob = Mobility.of(obs.model)
        v, vy, w = self.guard(*self._drive(pose, mob, obs.t_s), mob, obs.dt_s)
        if self.guard.waiting:
            self.state_name = "steer"
        return command_for(obs, v, vy, w)

    def _drive(self, pose: np.ndarray, mob: Mobility, t_s: float) -> tuple[float, float, float]:
        tr = self.tracker
        assert tr is not None
        ld = max(self.lookahead, 1.2 * mob.min_radius_m)
        tr.project(pose[:2], window_m=ld + 0.5)
        if tr.offset_m > 1.0 or t_s - self.best_progress[1] > self.stuck_s:
            self.replans += 1
            if not self.plan(pose[:2], t_s):
                self.state_name = "no_path"
                return 0.0, 0.0, 0.0
            tr = self.tracker
            assert tr is not None
            tr.project(pose[:2], window_m=ld + 0.5)
        if tr.s > self.best_progress[0] + 0.05:
            self.best_progress = (tr.s, t_s)
        target, heading = tr.point_at(tr.s + ld)
        speed = self.speed
        to_goal = math.hypot(self.goal[0] - pose[0], self.goal[1] - pose[1])
        if tr.remaining_m() < ld:
            target = self.goal
            speed = min(speed, max(0.15, to_goal))
        if mob.car_like:
            return self._drive_car(pose, mob, target, speed)
        self.state_name = "follow"
        # a carrot across a tight corner would take the body into the wall: shorten the
        # lookahead until the swept footprint is clear, else turn on the spot / stop
        for shrink in (1.0, 0.5, 0.25):
            if shrink < 1.0:
                target, heading = tr.point_at(tr.s + shrink * ld)
            twist = pursuit_twist(
                pose,
                target,
                speed,
                mob,
                travel_heading_rad=heading,
                max_turn_rate_rad_s=self.max_turn,
            )
            if not self._twist_blocked(pose, twist):
                return twist
        if mob.holonomic:
            return 0.0, 0.0, twist[2]
        return 0.0, 0.0, math.copysign(self.max_turn, twist[2])

    def _twist_blocked(self, pose: np.ndarray, twist: tuple[float, float, float]) -> bool:
        """Whether the footprint, moved 0.25 m along the twist's path, would touch a wall."""
        vx, vy, w = twist
        speed = math.hypot(vx, vy)
        if speed < 1e-9:
            return False
        if abs(vy) < 1e-12:
            return self._blocked_along(pose, w / vx, 1 if vx > 0 else -1, 0.25)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        ux, uy = (c * vx - s * vy) / speed, (s * vx + c * vy) / speed
        for d in (0.125, 0.25):
            if self.footprint.hits(self.grid, pose + np.array([ux * d, uy * d, 0.0])):
                return True
        return False

    def _drive_car(
        self, pose: np.ndarray, mob: Mobility, target: np.ndarray, speed: float
    ) -> tuple[float, float, float]:
        alpha = wrap(math.atan2(target[1] - pose[1], target[0] - pose[0]) - pose[2])
        kmax = mob.max_curvature_1_m
        probe = 0.25
        turning = self.state_name in ("kturn_forward", "kturn_reverse") or (
            self.state_name == "steer" and self.gear != 0
        )
        if not turning:
            v, _, w = pursuit_twist(pose, target, speed, mob)
            k = w / v if abs(v) > 1e-9 else 0.0
            if abs(alpha) <= self.kturn_above and not self._blocked_along(pose, k, 1, probe):
                self.state_name, self.gear = "follow", 0
                return v, 0.0, w
            # start a K-turn: forward if there is room, else reverse
            forward_free = not self._blocked_along(pose, math.copysign(kmax, alpha), 1, probe)
            self.gear = 1 if forward_free else -1
        elif abs(alpha) < math.radians(30.0) and not self._blocked_along(pose, 0.0, 1, probe):
            self.state_name, self.gear = "follow", 0
            v, _, w = pursuit_twist(pose, target, speed, mob)
            return v, 0.0, w
        # forward: lock towards the carrot; reverse: the opposite lock turns the same way
        k = self.gear * math.copysign(kmax, alpha)
        if self._blocked_along(pose, k, self.gear, probe):
            if self._blocked_along(pose, -k, -self.gear, probe):
                self.state_name = "stuck"  # no room either way: stand still
                return 0.0, 0.0, 0.0
            self.gear, k = -self.gear, -k
        self.state_name = "kturn_forward" if self.gear > 0 else "kturn_reverse"
        v = self.gear * min(self.kturn_speed, speed)
        return v, 0.0, v * k


# ------------------------------------------------------------------------------------ explorer
def sector_min(scan: LaserScan, center_rad: float, half_rad: float) -> float:
    """Smallest reading of the beams within +-half_rad of center_rad (robot frame); no return
    counts as range_max + 1, too close as 0. The nearest beam if none falls inside."""
    ang = scan.angle_min_rad + scan.angle_increment_rad * np.arange(len(scan.ranges))
    off = np.abs((ang - center_rad + np.pi) % (2 * np.pi) - np.pi)
    sel = off <= half_rad
    if not sel.any():
        sel = off == off.min()
    r = scan.ranges[sel]
    r = np.where(np.isposinf(r), scan.range_max_m + 1.0, np.where(np.isneginf(r), 0.0, r))
    return float(r.min())


class TremauxExplorer:
    """Map-less maze explorer for robots that turn on the spot: the wall-follower rule (keep
    one hand on the wall; ``hand="right"`` or "left"), which solves every maze whose walls are
    connected (all perfect mazes), with Trémaux-style marks and the Bug1 rule against looping
    round islands (mazes with loops).

    It sees only its lidar (``sensor``) and its wheel odometry; the goal is a world position. It
    keeps the wall at ``wall_distance_m`` with a PD law on the wall's distance and angle (from
    beams at 90 and 60 deg on the wall side); turns 90 deg away from the wall when the front is
    closer than ``wall_distance_m``; when the wall ends it drives ``wall_distance_m`` on, turns
    90 deg towards the wall side and drives on until it finds the wall again. Each place it
    follows a wall is marked (0.5 m cells by odometry, with the heading's quadrant): coming past
    a mark again in the same direction means it has gone once round a wall that does not lead
    to the goal (an island). Then, as Bug1 does, it goes on round to the place of that lap
    closest to the goal, leaves the wall there straight towards the goal and follows the next
    wall it meets.
    When the goal is within ``homing_range_m`` and the lidar sees a clear corridor to it, it
    drives straight there; it stops within ``goal_tolerance_m`` (by odometry).

    ``state_name``: "seek", "follow", "pass", "reacquire", "turn", "home" or "reached".
    """

    def __init__(
        self,
        goal_xy_m: Sequence[float],
        sensor: str = "lidar",
        hand: Literal["right", "left"] = "right",
        wall_distance_m: float = 0.8,
        speed_m_s: float = 0.5,
        turn_rate_rad_s: float = 1.2,
        goal_tolerance_m: float = 0.3,
        homing_range_m: float = 3.0,
        body_width_m: float = 0.45,
        open_margin_m: float = 0.6,
    ):
        if hand not in ("right", "left"):
            raise ValueError(f"hand must be 'right' or 'left', got {hand!r}")
        self.goal = np.asarray(goal_xy_m, dtype=np.float64).reshape(2)
        self.sensor, self.side = sensor, (-1.0 if hand == "right" else 1.0)
        self.d_wall, self.speed, self.turn_rate = wall_distance_m, speed_m_s, turn_rate_rad_s
        self.tolerance, self.homing_range = goal_tolerance_m, homing_range_m
        self.half_width, self.open_margin = body_width_m / 2, open_margin_m
        self.reset()

    def reset(self) -> None:
        self.state_name = "seek"
        self.after_turn = "follow"
        self.turn_target = 0.0
        self.mark_xy = np.zeros(2)
        self.turns_without_wall = 0
        self.marks: dict[tuple[int, int, int], float] = {}
        self.no_home_until = 0.0
        self.closest_m, self.closest_xy = math.inf, np.zeros(2)  # this lap's nearest place
        self.leave_at: np.ndarray | None = None

    def _turn(self, pose: np.ndarray, angle: float, then: str) -> None:
        self.state_name, self.after_turn = "turn", then
        self.turn_target = wrap(pose[2] + angle)

    def _clear_to_goal(self, scan: LaserScan, bearing: float, dist: float) -> bool:
        """No lidar return within the corridor of the body's width (+15 cm a side) from the
        robot to just past the goal."""
        r = scan.ranges
        hit = np.isfinite(r) | np.isneginf(r)
        if not hit.any():
            return True
        ang = scan.angle_min_rad + scan.angle_increment_rad * np.flatnonzero(hit) - bearing
        rr = np.where(np.isneginf(r[hit]), 0.0, r[hit])
        along, lateral = rr * np.cos(ang), np.abs(rr * np.sin(ang))
        inside = (along > -0.1) & (along < dist + 0.3) & (lateral < self.half_width + 0.15)
        return not bool(inside.any())

    def step(self, obs: Observation):
        scan = obs.scans.get(self.sensor)
        if scan is None:
            raise ValueError(
                f"TremauxExplorer needs the sensor {self.sensor!r}; the robot has "
                f"{sorted(obs.scans)}"
            )
        pose = obs.odom_pose
        if obs.bump and self.state_name == "home":  # the way in was not clear after all
            self.no_home_until = obs.t_s + 10.0
            self._turn(pose, -self.side * math.pi / 2, "follow")
        v, w = self._decide(pose, scan, obs.t_s)
        return command_for(obs, v, 0.0, w)

    def _decide(self, pose: np.ndarray, scan: LaserScan, t_s: float) -> tuple[float, float]:
        dx, dy = self.goal[0] - pose[0], self.goal[1] - pose[1]
        dist = math.hypot(dx, dy)
        if self.state_name == "reached" or dist < self.tolerance:
            self.state_name = "reached"
            return 0.0, 0.0
        bearing = wrap(math.atan2(dy, dx) - pose[2])
        front = sector_min(scan, 0.0, math.radians(20.0))
        if (
            self.state_name not in ("home", "turn")
            and t_s >= self.no_home_until
            and dist < self.homing_range
            and self._clear_to_goal(scan, bearing, dist)
        ):
            self.state_name = "home"
        st = self.state_name
        if st == "home":
            if not self._clear_to_goal(scan, bearing, dist) and front < self.d_wall:
                self._turn(pose, -self.side * math.pi / 2, "follow")
                return 0.0, 0.0
            w = max(-self.turn_rate, min(self.turn_rate, 2.0 * bearing))
            v = min(self.speed, dist) * max(0.0, math.cos(bearing)) ** 2
            return v, w
        if st == "turn":
            err = wrap(self.turn_target - pose[2])
            if abs(err) < math.radians(2.0):
                self.state_name, self.mark_xy = self.after_turn, pose[:2].copy()
                return 0.0, 0.0
            return 0.0, max(-self.turn_rate, min(self.turn_rate, 3.0 * err))
        if st in ("follow", "pass", "reacquire"):
            if dist < self.closest_m:
                self.closest_m, self.closest_xy = dist, pose[:2].copy()
            if self.leave_at is not None and math.hypot(*(pose[:2] - self.leave_at)) < 0.35:
                self.leave_at, self.closest_m = None, math.inf
                self.marks.clear()
                self._turn(pose, bearing, "seek")  # Bug1: leave the island towards the goal
                return 0.0, 0.0
        if front < self.d_wall:  # wall ahead: turn away from the wall side
            self.turns_without_wall = 0
            self._turn(pose, -self.side * math.pi / 2, "follow")
            return 0.0, 0.0
        side = sector_min(scan, self.side * math.pi / 2, math.radians(8.0))
        wall_seen = side < self.d_wall + self.open_margin
        travelled = math.hypot(pose[0] - self.mark_xy[0], pose[1] - self.mark_xy[1])
        if st == "seek":  # straight on until a wall is ahead
            return self.speed, 0.0
        if st == "pass":  # the wall ended: go on to the middle of the opening, then turn
            if travelled >= self.d_wall:
                self._turn(pose, self.side * math.pi / 2, "reacquire")
                return 0.0, 0.0
            return self.speed, 0.0
        if st == "reacquire":
            if wall_seen:
                self.turns_without_wall = 0
                self.state_name = "follow"
            elif travelled > self.d_wall + 1.5:
                self.turns_without_wall += 1
                if self.turns_without_wall >= 3:  # open space: go straight to the next wall
                    self.state_name = "seek"
                else:
                    self._turn(pose, self.side * math.pi / 2, "reacquire")
                    return 0.0, 0.0
            return self.speed, 0.0
        if not wall_seen:
            self.state_name, self.mark_xy = "pass", pose[:2].copy()
            return self.speed, 0.0
        return self._follow(pose, scan, side, t_s)

    def _follow(
        self, pose: np.ndarray, scan: LaserScan, side: float, t_s: float
    ) -> tuple[float, float]:
        self.state_name = "follow"
        key = (
            math.floor(pose[0] / 0.5),
            math.floor(pose[1] / 0.5),
            round(pose[2] / (math.pi / 2)) % 4,
        )
        seen = self.marks.get(key)
        if seen is None:
            self.marks[key] = t_s
        elif t_s - seen > 20.0 and self.leave_at is None:  # once round an island
            self.leave_at = self.closest_xy.copy()
        # wall line through the beams at 90 and 60 deg on the wall side (robot frame)
        a1, a2 = self.side * math.pi / 2, self.side * math.pi / 3
        r2 = sector_min(scan, a2, math.radians(4.0))
        psi, dist = 0.0, side
        if r2 < 2.0 * side:
            p1 = np.array([side * math.cos(a1), side * math.sin(a1)])
            p2 = np.array([r2 * math.cos(a2), r2 * math.sin(a2)])
            u = p2 - p1
            n = float(np.hypot(*u))
            if n > 1e-6:
                psi = math.atan2(u[1], u[0])
                dist = abs(p1[0] * u[1] - p1[1] * u[0]) / n
        w = 1.5 * psi + self.side * 1.5 * (dist - self.d_wall)
        w = max(-self.turn_rate, min(self.turn_rate, w))
        v = self.speed * (1.0 - 0.5 * abs(w) / self.turn_rate)
        return v, w


# ------------------------------------------------------------------------------------ config
class MazeSolverConfig(BaseModel):
    """``controller: {type: maze_solver, goal_cell: [17, 17], method: astar}``"""

    model_config = ConfigDict(extra="forbid", frozen=True)
    type: Literal["maze_solver"]
    method: Literal["astar", "tremaux"] = "astar"
    goal_cell: tuple[int, int] | None = Field(None, description="[row, col] of the map grid")
    goal_x_m: float | None = None
    goal_y_m: float | None = None
    speed_m_s: float = Field(0.8, gt=0, le=100)
    goal_tolerance_m: float = Field(0.3, gt=0, le=100)
    # astar
    lookahead_m: float = Field(0.8, gt=0, le=100)
    connectivity: Literal[4, 8] = 8
    clearance_m: float = Field(0.05, ge=0, le=10, description="extra margin beyond half width")
    preferred_clearance_m: float = Field(1.0, gt=0, le=100)
    plan_resolution_m: float = Field(0.25, gt=0, le=10)
    pose_source: PoseSource = "true_pose"
    # tremaux
    sensor: str = "lidar"
    hand: Literal["right", "left"] = "right"
    wall_distance_m: float = Field(0.8, gt=0, le=100)

    @model_validator(mode="after")
    def _one_goal(self) -> MazeSolverConfig:
        xy = (self.goal_x_m is None, self.goal_y_m is None)
        if xy[0] != xy[1]:
            raise ValueError("give both goal_x_m and goal_y_m, or goal_cell")
        if (self.goal_cell is None) == (self.goal_x_m is None):
            raise ValueError("give exactly one goal: goal_cell [row, col] or goal_x_m + goal_y_m")
        return self


def build(cfg: MazeSolverConfig, ctx: ControllerContext) -> AStarMazeSolver | TremauxExplorer:
    """The controller a ``maze_solver`` config describes, for robot ``ctx.robot_index``."""
    spec, grid = ctx.spec, ctx.grid
    length = float(getattr(spec, "body_length_m", 0.6))
    width = float(getattr(spec, "body_width_m", 0.45))
    offset = float(getattr(spec, "body_offset_x_m", 0.0))
    goal_xy = None if cfg.goal_x_m is None else (cfg.goal_x_m, cfg.goal_y_m)
    if cfg.method == "tremaux":
        if goal_xy is None:
            x, y = grid.cell_center(*cfg.goal_cell)  # type: ignore[misc,union-attr]
            goal_xy = (float(x), float(y))
        names = [s.name for s in getattr(spec, "sensors", ())]
        if cfg.sensor not in names:
            raise ValueError(f"maze_solver (tremaux) needs the sensor {cfg.sensor!r}; has {names}")
        return TremauxExplorer(
            goal_xy,  # type: ignore[arg-type]
            sensor=cfg.sensor,
            hand=cfg.hand,
            wall_distance_m=cfg.wall_distance_m,
            speed_m_s=cfg.speed_m_s,
            goal_tolerance_m=cfg.goal_tolerance_m,
            body_width_m=width,
        )
    return AStarMazeSolver(
        grid,
        goal_cell=cfg.goal_cell,
        goal_xy_m=goal_xy,
        body_length_m=length,
        body_width_m=width,
        body_offset_x_m=offset,
        speed_m_s=cfg.speed_m_s,
        lookahead_m=cfg.lookahead_m,
        connectivity=cfg.connectivity,
        clearance_m=cfg.clearance_m,
        preferred_clearance_m=cfg.preferred_clearance_m,
        plan_resolution_m=cfg.plan_resolution_m,
        goal_tolerance_m=cfg.goal_tolerance_m,
        pose_source=cfg.pose_source,
    )
