"""Map-less maze exploring: ``TremauxExplorer`` (wall follower + Tremaux marks + Bug1).

It sees only its lidar and its wheel odometry; see the class docstring for the rules.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from agvsim.angles import wrap_angle
from agvsim.control.api import LaserScan, Observation, command_for
from agvsim.control.mobility import wrap


def sector_min(scan: LaserScan, center_rad: float, half_rad: float) -> float:
    """Smallest reading of the beams within +-half_rad of center_rad (robot frame); no return
    counts as range_max + 1, too close as 0. The nearest beam if none falls inside."""
    ang = scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(len(scan.ranges))
    off = np.abs(wrap_angle(ang - center_rad))
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
        ang = scan.robot_angle_min_rad + scan.angle_increment_rad * np.flatnonzero(hit) - bearing
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
