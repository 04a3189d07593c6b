"""Maze solving: A* on the known map, and a map-less wall follower.

``AStarMazeSolver`` plans once on the world's occupancy grid and follows the path by pure
pursuit (:mod:`agvsim.control.pure_pursuit`):

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

``TremauxExplorer`` knows no map: see its docstring. The planning pieces (``ClearanceMap``,
``astar``, ``plan_path``, ``Footprint``, ``arc_pose``) live in :mod:`agvsim.control.planning`,
the explorer in :mod:`agvsim.control.explorer`; both are re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agvsim.control.api import Observation, command_for
from agvsim.control.explorer import TremauxExplorer, sector_min
from agvsim.control.mobility import (
    Mobility,
    PoseSource,
    SteeringGuard,
    check_pose_source,
    pose_of,
    pursuit_twist,
    wrap,
)
from agvsim.control.planning import ClearanceMap, Footprint, arc_pose, astar, plan_path
from agvsim.control.pure_pursuit import PathTracker
from agvsim.world.grid import OccupancyGrid

__all__ = [
    "AStarMazeSolver",
    "ClearanceMap",
    "Footprint",
    "TremauxExplorer",
    "arc_pose",
    "astar",
    "plan_path",
    "sector_min",
]


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
