"""Go to a goal (PID), for every kinematic model.

``GoToGoal`` thinks in body twists and leaves the wheels to ``command_for`` (see
:mod:`agvsim.control.mobility` for how each kind of model moves). Car-like models back up to a
goal close behind, and drive straight away from a goal too close beside them for any arc until
one reaches it (they could only orbit it otherwise).

Poses come from the ground truth (``pose_source="true_pose"``) or from wheel odometry.

The waypoint follower (``PurePursuit``, ``PathTracker``) lives in
:mod:`agvsim.control.pure_pursuit` and the shared motion primitives (``Mobility``,
``SteeringGuard``, ``pursuit_twist``, ``wrap``, ...) in :mod:`agvsim.control.mobility`; both are
re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvsim.control.api import Observation, command_for
from agvsim.control.mobility import (
    Mobility,
    PoseSource,
    SteeringGuard,
    check_pose_source,
    pose_of,
    pursuit_twist,
    wrap,
)
from agvsim.control.pure_pursuit import PathTracker, PurePursuit

__all__ = [
    "PID",
    "GoToGoal",
    "Mobility",
    "PathTracker",
    "PoseSource",
    "PurePursuit",
    "SteeringGuard",
    "check_pose_source",
    "pose_of",
    "pursuit_twist",
    "wrap",
]


# ------------------------------------------------------------------------------------ PID
@dataclass
class PID:
    """PID controller with an output limit and anti-windup by conditional integration: the
    integral does not grow while the output is saturated in the direction of the error, and
    ``ki * integral`` alone never exceeds the limit. No derivative kick on the first step."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    limit: float = math.inf  # |output| <= limit

    def __post_init__(self) -> None:
        if min(self.kp, self.ki, self.kd) < 0 or not self.limit > 0:
            raise ValueError(f"PID gains must be >= 0 and the limit > 0, got {self}")
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        self.prev_error: float | None = None

    def step(self, error: float, dt_s: float) -> float:
        deriv = 0.0 if self.prev_error is None else (error - self.prev_error) / dt_s
        self.prev_error = error
        trial = self.integral + error * dt_s
        out = self.kp * error + self.ki * trial + self.kd * deriv
        if abs(out) > self.limit and out * error > 0:  # saturated: do not wind up
            out = self.kp * error + self.ki * self.integral + self.kd * deriv
        else:
            self.integral = trial
            if self.ki > 0:
                cap = self.limit / self.ki
                self.integral = min(max(self.integral, -cap), cap)
        return min(max(out, -self.limit), self.limit)


# ------------------------------------------------------------------------------------ go to goal
class GoToGoal:
    """Drive to ``goal_xy`` (m, world) and stop within ``tolerance_m``.

    Two PIDs: one on the heading error (bearing of the goal in the robot frame, rad) gives the
    yaw rate, limited to ``max_turn_rate_rad_s``; one on the distance to the goal gives the
    speed, limited to ``max_speed_m_s``. Both have anti-windup (see :class:`PID`). Models that
    turn on the spot scale the speed by ``max(0, cos(bearing))`` (no driving away from the
    goal). Holonomic models drive straight at the goal, **sideways** when it is to the side, and
    hold their heading (or turn to ``goal_heading_rad`` when given). Car-like models (yaw rate
    clipped to |v| / R_min) reverse to a goal less than ``reverse_within_m`` (at least 2.2 R_min)
    behind them, and when the goal is so close beside them that even full lock cannot reach it,
    first drive straight away from it ("straighten") to make room.

    ``state_name``: "drive", "reverse", "straighten" or "reached".
    """

    def __init__(
        self,
        goal_xy: Sequence[float],
        tolerance_m: float = 0.1,
        max_speed_m_s: float = 0.8,
        max_turn_rate_rad_s: float = 1.5,
        heading_gains: tuple[float, float, float] = (2.5, 0.2, 0.05),
        speed_gains: tuple[float, float, float] = (0.8, 0.05, 0.0),
        goal_heading_rad: float | None = None,
        reverse_within_m: float = 1.5,
        pose_source: PoseSource = "true_pose",
    ):
        if not tolerance_m > 0 or not max_speed_m_s > 0 or not max_turn_rate_rad_s > 0:
            raise ValueError("tolerance_m, max_speed_m_s and max_turn_rate_rad_s must be > 0")
        check_pose_source(pose_source)
        self.goal = np.asarray(goal_xy, dtype=np.float64).reshape(2)
        self.tolerance_m, self.max_speed = tolerance_m, max_speed_m_s
        self.max_turn = max_turn_rate_rad_s
        self.goal_heading, self.reverse_within = goal_heading_rad, reverse_within_m
        self.pose_source = pose_source
        self.heading_pid = PID(*heading_gains, limit=max_turn_rate_rad_s)
        self.speed_pid = PID(*speed_gains, limit=max_speed_m_s)
        self.guard = SteeringGuard()
        self.reset()

    def reset(self) -> None:
        self.heading_pid.reset()
        self.speed_pid.reset()
        self.guard.reset()
        self.state_name = "drive"

    @property
    def reached(self) -> bool:
        return self.state_name == "reached"

    def step(self, obs: Observation):
        mob = Mobility.of(obs.model)
        v, vy, w = self.twist(pose_of(obs, self.pose_source), mob, obs.dt_s)
        return command_for(obs, *self.guard(v, vy, w, mob, obs.dt_s))

    def twist(self, pose: np.ndarray, mob: Mobility, dt: float) -> tuple[float, float, float]:
        """The body twist (vx, vy, omega) for this step."""
        x, y, th = (float(p) for p in pose)
        dx, dy = self.goal[0] - x, self.goal[1] - y
        dist = math.hypot(dx, dy)
        if self.reached or dist < self.tolerance_m:
            self.state_name = "reached"
            return 0.0, 0.0, 0.0
        bearing = wrap(math.atan2(dy, dx) - th)
        if mob.holonomic:
            v = self.speed_pid.step(dist, dt)
            w = 0.0
            if self.goal_heading is not None:
                w = self.heading_pid.step(wrap(self.goal_heading - th), dt)
            return v * math.cos(bearing), v * math.sin(bearing), w
        if mob.can_spin:
            w = self.heading_pid.step(bearing, dt)
            return self.speed_pid.step(dist, dt) * max(0.0, math.cos(bearing)), 0.0, w
        # car-like: pick the gear, forward unless the goal is near and behind; a goal so close
        # beside the car that no arc reaches it (the arc through it, tangent to the heading,
        # is tighter than full lock) is first given room by driving straight away from it
        bx, by = dist * math.cos(bearing), dist * math.sin(bearing)
        kmax = mob.max_curvature_1_m
        near = dist < max(self.reverse_within, 2.2 * mob.min_radius_m)
        need_k = abs(2.0 * by) / (dist * dist)
        if near and need_k > (0.9 if self.state_name == "straighten" else 1.0) * kmax:
            state, gear = "straighten", (-1.0 if bx > 0 else 1.0)
        elif near and (bx < -0.05 or (self.state_name == "reverse" and bx < 0.05)):
            state, gear = "reverse", -1.0
        else:
            state, gear = "drive", 1.0
        if state != self.state_name:
            self.heading_pid.reset()  # the error changes meaning with the gear
        self.state_name = state
        v = gear * max(self.speed_pid.step(dist, dt), 0.1 * self.max_speed)
        if state == "straighten":
            w = 0.0
        elif gear < 0:  # the rear leads: turn the rear towards the goal
            w = self.heading_pid.step(wrap(bearing - math.pi), dt)
        else:
            w = self.heading_pid.step(bearing, dt)
        wmax = abs(v) * kmax
        return v, 0.0, max(-wmax, min(wmax, w))
