"""Go to a goal (PID) and follow waypoints (pure pursuit), for every kinematic model.

Both behaviours think in body twists and leave the wheels to ``command_for``: a twist in
inverse mode, the robot's own inverse kinematics (driven wheel speeds + steering) in forward
mode. How each model moves:

* **holonomic** (mecanum, omni3): translate straight at the target, sideways if need be;
  the heading is held (``GoToGoal``) or turned towards the direction of travel
  (``PurePursuit(face_travel=True)``).
* **can turn on the spot** (differential; tricycle with +-90 deg steering): turn towards the
  target, drive when it is roughly ahead.
* **car-like** (Ackermann; tricycle with less steering): the curvature is clipped to
  ``1 / R_min = tan(max_steer) / wheelbase``; the inverse kinematics turns curvature into a
  steering angle. ``GoToGoal`` backs up to a goal close behind, and drives straight away from a
  goal too close beside it for any arc until one reaches it (it could only orbit it otherwise).

Poses come from the ground truth (``pose_source="true_pose"``) or from wheel odometry.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from agvsim.control.api import ControllerContext, Observation, command_for

PoseSource = Literal["true_pose", "odometry"]


def wrap(a: float) -> float:
    """Angle in rad wrapped to [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def pose_of(obs: Observation, source: str) -> np.ndarray:
    """(3,) x, y, theta from the ground truth or from wheel odometry."""
    return obs.true_pose if source == "true_pose" else obs.odom_pose


def check_pose_source(source: str) -> None:
    if source not in ("true_pose", "odometry"):
        raise ValueError(f"pose_source must be 'true_pose' or 'odometry', got {source!r}")


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


# ------------------------------------------------------------------------------------ model
@dataclass(frozen=True)
class Mobility:
    """What a kinematic model can do, as the behaviours need it."""

    holonomic: bool
    can_spin: bool
    max_curvature_1_m: float  # inf for models that turn on the spot
    wheelbase_m: float  # 0 for models without steering
    max_steer_rad: float
    max_steer_rate_rad_s: float

    @classmethod
    def of(cls, model: object) -> Mobility:
        if not getattr(model, "has_steering", False):
            return cls(bool(getattr(model, "holonomic", False)), True, math.inf, 0.0, 0.0, 0.0)
        max_steer = float(np.min(model.max_steer_rad))  # type: ignore[attr-defined]
        rate = float(np.min(model.max_steer_rate_rad_s))  # type: ignore[attr-defined]
        L = float(np.min(model.wheelbase_m))  # type: ignore[attr-defined]
        can_spin = max_steer >= math.pi / 2 - 1e-9
        kmax = math.inf if can_spin else math.tan(max_steer) / L
        return cls(False, can_spin, kmax, L, max_steer, rate)

    @property
    def car_like(self) -> bool:
        return not self.can_spin

    @property
    def min_radius_m(self) -> float:
        return 0.0 if self.can_spin else 1.0 / self.max_curvature_1_m


def pursuit_twist(
    pose: np.ndarray,
    target_xy: np.ndarray,
    speed_m_s: float,
    mob: Mobility,
    *,
    travel_heading_rad: float | None = None,
    max_turn_rate_rad_s: float = 1.5,
    spin_above_rad: float = 1.0,
    curve_slowdown_m: float = 0.5,
) -> tuple[float, float, float]:
    """The pure-pursuit body twist (vx, vy, omega) towards ``target_xy``.

    Curvature ``k = 2 sin(alpha) / d`` for a target at bearing alpha and distance d (the arc
    through the robot and the target, tangent to the heading). The speed drops in curves as
    ``v / (1 + curve_slowdown_m * |k|)``. Models that turn on the spot turn in place while
    ``|alpha| > spin_above_rad``; car-like models clip k to +-1/R_min (full lock when the
    target is behind). Holonomic models translate straight at the target and turn towards
    ``travel_heading_rad`` when given."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    dx, dy = float(target_xy[0]) - x, float(target_xy[1]) - y
    c, s = math.cos(th), math.sin(th)
    bx, by = c * dx + s * dy, -s * dx + c * dy
    dist = math.hypot(bx, by)
    if dist < 1e-9:
        return 0.0, 0.0, 0.0
    if mob.holonomic:
        w = 0.0
        if travel_heading_rad is not None:
            w = max(
                -max_turn_rate_rad_s, min(max_turn_rate_rad_s, 2.0 * wrap(travel_heading_rad - th))
            )
        return speed_m_s * bx / dist, speed_m_s * by / dist, w
    alpha = math.atan2(by, bx)
    k = 2.0 * math.sin(alpha) / dist
    if mob.can_spin:
        if abs(alpha) > spin_above_rad:
            return 0.0, 0.0, math.copysign(max_turn_rate_rad_s, alpha)
        v = speed_m_s / (1.0 + curve_slowdown_m * abs(k))
        if abs(v * k) > max_turn_rate_rad_s:
            v = max_turn_rate_rad_s / abs(k)
        return v, 0.0, v * k
    if abs(alpha) > math.pi / 2:
        k = math.copysign(mob.max_curvature_1_m, alpha)
    k = max(-mob.max_curvature_1_m, min(mob.max_curvature_1_m, k))
    v = speed_m_s / (1.0 + curve_slowdown_m * abs(k))
    return v, 0.0, v * k


class SteeringGuard:
    """Keeps a steered wheel (tricycle, Ackermann) from driving while far from its angle.

    The steering turns at a limited rate, so a command whose angle is far from the present one
    (a tricycle about to turn on the spot, a car changing lock) would drive the wheel while it
    swings. The guard tracks the angle the robot must have (it mirrors the engine: the inverse
    kinematics' angle in (-pi/2, pi/2], clamped, rate limited) and, while the angle a command
    needs is more than ``settle_rad`` away, sends a standing command with that angle instead
    (a speed of 1e-6 m/s along the wanted wheel direction). A turn on the spot gets a tiny
    forward speed so that clockwise turns ask for -90 deg rather than +90 deg."""

    def __init__(self, settle_rad: float = 0.35):
        self.settle_rad = settle_rad
        self.reset()

    def reset(self) -> None:
        self.angle_rad = 0.0
        self.waiting = False

    def _target(self, v: float, w: float, mob: Mobility) -> float:
        if abs(v) < 1e-12 and abs(w) < 1e-12:
            return self.angle_rad
        a = math.atan2(mob.wheelbase_m * w, v)
        if a > math.pi / 2 or a <= -math.pi / 2:
            a = wrap(a + math.pi)
        return max(-mob.max_steer_rad, min(mob.max_steer_rad, a))

    def __call__(
        self, v: float, vy: float, w: float, mob: Mobility, dt_s: float
    ) -> tuple[float, float, float]:
        self.waiting = False
        if mob.wheelbase_m == 0.0:
            return v, vy, w
        if abs(v) < 1e-6 and abs(w) > 1e-9:  # turn on the spot: keep the wheel on w's side
            v = 1e-6
        target = self._target(v, w, mob)
        step = mob.max_steer_rate_rad_s * dt_s
        self.angle_rad += max(-step, min(step, target - self.angle_rad))
        if abs(target - self.angle_rad) > self.settle_rad:
            self.waiting = True
            eps = 1e-6
            return eps * math.cos(target), 0.0, eps * math.sin(target) / mob.wheelbase_m
        return v, vy, w


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


# ------------------------------------------------------------------------------------ pure pursuit
class PathTracker:
    """Progress along a polyline ``(M, 2)`` by arc length, monotone, searched in a window ahead
    (so a path that doubles back past a wall is not skipped). A ``loop`` closes the polyline."""

    def __init__(self, points: np.ndarray, loop: bool = False):
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(pts) == 0:
            raise ValueError("a path needs at least one point")
        if loop and len(pts) > 1:
            pts = np.vstack([pts, pts[:1]])
        self.loop = loop and len(pts) > 2
        self.points = pts
        seg = np.diff(pts, axis=0)
        self.seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length_m = float(self.cum[-1])
        self.s = 0.0
        self.offset_m = 0.0  # distance of the robot from the path at the last projection

    def reset(self) -> None:
        self.s, self.offset_m = 0.0, 0.0

    def point_at(self, s: float) -> tuple[np.ndarray, float]:
        """Point and tangent heading at arc length s (wrapped on a loop, clamped otherwise)."""
        if len(self.seg_len) == 0:
            return self.points[0], 0.0
        s = s % self.length_m if self.loop else min(max(s, 0.0), self.length_m)
        i = int(np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.seg_len) - 1))
        a, ln = self.points[i], self.seg_len[i]
        d = self.points[i + 1] - a
        t = 0.0 if ln == 0 else (s - self.cum[i]) / ln
        return a + t * d, math.atan2(d[1], d[0])

    def project(self, xy: np.ndarray, window_m: float) -> float:
        """Advance the progress to the closest path point within ``window_m`` ahead."""
        if len(self.seg_len) == 0:
            return self.s
        s0 = self.s
        base = 0.0
        if self.loop:
            base = math.floor(s0 / self.length_m) * self.length_m
            s0 -= base
        lo, hi = s0 - 1e-9, s0 + window_m
        idx = np.flatnonzero((self.cum[1:] >= lo) & (self.cum[:-1] <= hi))
        extra = None
        if self.loop and hi > self.length_m:  # the window wraps past the start
            extra = np.flatnonzero(self.cum[:-1] <= hi - self.length_m)
        best, best_d = s0, math.inf
        for ids, shift in ((idx, 0.0), (extra, self.length_m)):
            if ids is None or len(ids) == 0:
                continue
            a = self.points[ids]
            d = self.points[ids + 1] - a
            ln2 = np.maximum(self.seg_len[ids] ** 2, 1e-18)
            t = np.clip(((xy[0] - a[:, 0]) * d[:, 0] + (xy[1] - a[:, 1]) * d[:, 1]) / ln2, 0, 1)
            px, py = a[:, 0] + t * d[:, 0] - xy[0], a[:, 1] + t * d[:, 1] - xy[1]
            dist = np.hypot(px, py)
            k = int(np.argmin(dist))
            sk = self.cum[ids[k]] + t[k] * self.seg_len[ids[k]] + shift
            if dist[k] < best_d:
                best, best_d = sk, float(dist[k])
        self.s = base + max(best, s0)
        self.offset_m = best_d
        return self.s

    def remaining_m(self) -> float:
        return math.inf if self.loop else self.length_m - self.s


class PurePursuit:
    """Follow ``waypoints`` (m, world) at ``speed_m_s`` by pure pursuit with a ``lookahead_m``
    carrot: the target is the path point ``lookahead_m`` further along the path than the
    robot's closest point. The curvature ``2 sin(alpha) / d`` becomes (vx, omega); for car-like
    models the inverse kinematics (via ``command_for``) turns it into the steering angle, clipped
    to the model's lock. Holonomic models translate at the target and, with ``face_travel``,
    turn to face along the path. An open path ends within ``tolerance_m`` of its last point
    (speed ramps down over the last metre); ``loop=True`` goes round for ever.

    ``state_name``: "follow" or "reached".
    """

    def __init__(
        self,
        waypoints: Sequence[Sequence[float]] | np.ndarray,
        lookahead_m: float = 0.8,
        speed_m_s: float = 0.5,
        loop: bool = False,
        tolerance_m: float = 0.15,
        max_turn_rate_rad_s: float = 1.5,
        face_travel: bool = True,
        pose_source: PoseSource = "true_pose",
    ):
        if not lookahead_m > 0 or not speed_m_s > 0 or not tolerance_m > 0:
            raise ValueError("lookahead_m, speed_m_s and tolerance_m must be > 0")
        check_pose_source(pose_source)
        self.tracker = PathTracker(np.asarray(waypoints, dtype=np.float64), loop)
        self.lookahead_m, self.speed = lookahead_m, speed_m_s
        self.tolerance_m, self.max_turn = tolerance_m, max_turn_rate_rad_s
        self.face_travel, self.pose_source = face_travel, pose_source
        self.guard = SteeringGuard()
        self.reset()

    def reset(self) -> None:
        self.tracker.reset()
        self.guard.reset()
        self.state_name = "follow"

    def step(self, obs: Observation):
        mob = Mobility.of(obs.model)
        v, vy, w = self.twist(pose_of(obs, self.pose_source), mob)
        return command_for(obs, *self.guard(v, vy, w, mob, obs.dt_s))

    def twist(self, pose: np.ndarray, mob: Mobility) -> tuple[float, float, float]:
        tr = self.tracker
        ld = max(self.lookahead_m, 1.2 * mob.min_radius_m)
        tr.project(pose[:2], window_m=ld + 0.5)
        end = tr.points[-1]
        to_end = math.hypot(end[0] - pose[0], end[1] - pose[1])
        if self.state_name == "reached" or (
            not tr.loop and tr.remaining_m() < ld and to_end < self.tolerance_m
        ):
            self.state_name = "reached"
            return 0.0, 0.0, 0.0
        target, heading = tr.point_at(tr.s + ld)
        speed = self.speed
        if not tr.loop and tr.remaining_m() < ld:
            target = end
            speed = min(speed, max(0.1, to_end) * self.speed)
        return pursuit_twist(
            pose,
            target,
            speed,
            mob,
            travel_heading_rad=heading if self.face_travel else None,
            max_turn_rate_rad_s=self.max_turn,
        )


# ------------------------------------------------------------------------------------ configs
class GoalConfig(BaseModel):
    """``controller: {type: goto_goal, goal_x_m: 3, goal_y_m: -2}``"""

    model_config = ConfigDict(extra="forbid", frozen=True)
    type: Literal["goto_goal"]
    goal_x_m: float
    goal_y_m: float
    tolerance_m: float = Field(0.1, gt=0, le=100)
    max_speed_m_s: float = Field(0.8, gt=0, le=100)
    max_turn_rate_rad_s: float = Field(1.5, gt=0, le=100)
    heading_kp: float = Field(2.5, ge=0)
    heading_ki: float = Field(0.2, ge=0)
    heading_kd: float = Field(0.05, ge=0)
    speed_kp: float = Field(0.8, ge=0)
    speed_ki: float = Field(0.05, ge=0)
    speed_kd: float = Field(0.0, ge=0)
    goal_heading_deg: float | None = Field(None, description="holonomic models turn to this")
    pose_source: PoseSource = "true_pose"


class WaypointsConfig(BaseModel):
    """``controller: {type: waypoints, points: [[0, 0], [3, 0], [3, 3]], loop: true}``"""

    model_config = ConfigDict(extra="forbid", frozen=True)
    type: Literal["waypoints"]
    points: list[tuple[float, float]] = Field(min_length=1, description="[x_m, y_m] each")
    loop: bool = False
    lookahead_m: float = Field(0.8, gt=0, le=100)
    speed_m_s: float = Field(0.5, gt=0, le=100)
    tolerance_m: float = Field(0.15, gt=0, le=100)
    max_turn_rate_rad_s: float = Field(1.5, gt=0, le=100)
    face_travel: bool = True
    pose_source: PoseSource = "true_pose"


def build(cfg: GoalConfig | WaypointsConfig, ctx: ControllerContext) -> GoToGoal | PurePursuit:
    """The controller a ``goto_goal`` or ``waypoints`` config describes."""
    if isinstance(cfg, GoalConfig):
        heading = None if cfg.goal_heading_deg is None else math.radians(cfg.goal_heading_deg)
        return GoToGoal(
            (cfg.goal_x_m, cfg.goal_y_m),
            tolerance_m=cfg.tolerance_m,
            max_speed_m_s=cfg.max_speed_m_s,
            max_turn_rate_rad_s=cfg.max_turn_rate_rad_s,
            heading_gains=(cfg.heading_kp, cfg.heading_ki, cfg.heading_kd),
            speed_gains=(cfg.speed_kp, cfg.speed_ki, cfg.speed_kd),
            goal_heading_rad=heading,
            pose_source=cfg.pose_source,
        )
    return PurePursuit(
        cfg.points,
        lookahead_m=cfg.lookahead_m,
        speed_m_s=cfg.speed_m_s,
        loop=cfg.loop,
        tolerance_m=cfg.tolerance_m,
        max_turn_rate_rad_s=cfg.max_turn_rate_rad_s,
        face_travel=cfg.face_travel,
        pose_source=cfg.pose_source,
    )
