"""Wall following (thesis 7.2): keep the wall on one side at a set distance, around a maze.

A per-robot controller, a small state machine:

    find_wall    drive straight on until a wall is beside or ahead
    follow       run along the wall on ``side`` at ``distance_m`` from the body centre
    round_corner the wall falls away (its end is behind, beside): curve round it (same law)
    turn_corner  a wall ahead: turn on the spot away from the wall side (car-like models
                 make a K-turn: forward on full lock, then ``reverse`` on the other lock;
                 a robot too close to a wall to spin backs up straight first)
    back_off     after a bump: back away for a moment, then turn_corner

With a lidar the follow law steers by the nearest wall point on the follow side, seen from the
body centre: at distance rho and bearing beta the wall runs along beta - s pi/2 (s = +1 left,
-1 right); the robot steers for that direction plus a correction s * k (rho - d), so it holds
the distance on straight walls, turns away before inner corners and circles wall ends at
radius d. Lidar points are carried along by wheel odometry between frames (the lidar is
slower than the control loop). With the four rangers the wall's direction is not seen: the
follower assumes a square maze (walls along the axes, as the thesis's mazes are) and steers
for the nearest multiple of 90 deg of its heading (odometry or ground truth), and it circles
the last point it saw on the wall when the side ranger loses it.

Turning on the spot, a body sweeps a disc about its reference point P (the rear axle of a
tricycle: its nose swings wide). So the follower keeps that much room from walls abeam on the
other side, and at a corner with too little room on the side it should turn to, it turns the
long way round (or backs up first when too close to turn at all).

Commands go through ``command_for``: a twist in inverse mode, the model's own wheel speeds in
forward mode. A steered model in forward mode drives its wheels for the steering angle the
wheel will really have this step (it turns at a limited rate), not the one asked for.
Ackermann cars work with a lidar (K-turns in dead ends) when their turning circle fits the
corridors; with the four rangers alone a car can get stuck K-turning in a small room (its single
front beam misses the walls its corners meet at an angle).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Literal

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.control.api import LaserScan, Observation, WheelCommand, command_for


class State(StrEnum):
    FIND_WALL = "find_wall"
    FOLLOW = "follow"
    ROUND_CORNER = "round_corner"
    TURN_CORNER = "turn_corner"
    REVERSE = "reverse"
    BACK_OFF = "back_off"


@dataclass(frozen=True)
class WallView:
    """What the follower needs from a scan, in the body-centre frame."""

    front_m: float  # free run ahead of the body centre, in a band as wide as the body
    back_m: float  # the same, behind
    wall_m: float  # distance to the nearest wall point on the follow side (inf: none)
    along_rad: float  # heading change that runs along that wall (0: running along it)
    other_m: float = math.inf  # nearest return abeam on the other side (45-135 deg)
    room_away_m: float = math.inf  # nearest return to P on the side turned to at corners
    room_wall_m: float = math.inf  # nearest return to P on the follow side


class WallFollower:
    """Follows the wall on ``side`` ("left" or "right") at ``distance_m`` from the body centre,
    at up to ``speed_m_s``, reading ``sensor`` (a lidar, or the thesis's four rangers)."""

    MARGIN_M = 0.05  # clearance added to the body's half width when looking ahead

    def __init__(
        self,
        side: Literal["left", "right"] = "left",
        sensor: str = "lidar",
        distance_m: float = 0.6,
        speed_m_s: float = 0.4,
        turn_rate_rad_s: float = 1.0,
        body_length_m: float = 0.6,
        body_width_m: float = 0.45,
        body_offset_x_m: float = 0.0,
        sensor_mount_xy_m: tuple[float, float] = (0.0, 0.0),
        heading_source: Literal["odometry", "true_pose"] = "odometry",
        backoff_s: float = 0.6,
    ):
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {side!r}")
        if heading_source not in ("odometry", "true_pose"):
            raise ValueError(
                f"heading_source must be 'odometry' or 'true_pose', got {heading_source!r}"
            )
        if not (distance_m > 0 and speed_m_s > 0 and turn_rate_rad_s > 0):
            raise ValueError("distance_m, speed_m_s and turn_rate_rad_s must be > 0")
        self.side, self.sensor = side, sensor
        self.s = 1.0 if side == "left" else -1.0
        self.distance_m, self.speed, self.rate = distance_m, speed_m_s, turn_rate_rad_s
        self.half_length, self.half_width = body_length_m / 2.0, body_width_m / 2.0
        self.offset = body_offset_x_m  # body centre ahead of the reference point P
        # turning on the spot (about P) the body sweeps a disc this big; it keeps that much
        # room (+5 cm) from walls abeam on the side away from the wall it follows
        self.sweep_m = math.hypot(abs(body_offset_x_m) + self.half_length, self.half_width)
        self.mount = (float(sensor_mount_xy_m[0]), float(sensor_mount_xy_m[1]))  # from P
        self.heading_source = heading_source
        self.backoff_s = backoff_s
        self.reset()

    # ------------------------------------------------------------------ the controller API
    def reset(self) -> None:
        self.state = State.FIND_WALL
        self._until = 0.0  # end of back_off
        self._back_dir = -1.0
        self._turn_dir = -self.s  # turn_corner: away from the wall, unless there is no room
        self._done_since = math.inf  # turn_corner: since when it could stop turning
        self._stamp = -1.0  # stamp of the scan held in _points
        self._points = np.zeros((0, 2))  # its returns in the P frame at _pose_at_scan
        self._pose_at_scan = np.zeros(3)
        self._mark: np.ndarray | None = None  # rangers: last wall point seen (odometry frame)
        self._steer = 0.0  # forward mode: where the steered wheel is now
        self._model_info: tuple[bool, float] | None = None

    @property
    def state_name(self) -> str:
        return str(self.state)

    def step(self, obs: Observation):
        if self.sensor not in obs.scans:
            raise KeyError(
                f"wall following reads sensor {self.sensor!r}, but the robot has "
                f"{sorted(obs.scans)}"
            )
        can_spin, turn_radius = self._model(obs.model)
        view = self._look(obs)
        self._transition(view, obs, can_spin, turn_radius)
        vx, omega = self._act(view, can_spin)
        return self._command(obs, vx, omega)

    # ------------------------------------------------------------------ the state machine
    def _stop_m(self, turn_radius: float) -> float:
        """Free run ahead (from the body centre) below which the robot turns a corner: its
        follow distance for robots that spin; a car also needs its turning radius."""
        base = max(self.distance_m, self.half_length + 0.15)
        return base + turn_radius

    def _transition(
        self, v: WallView, obs: Observation, can_spin: bool, turn_radius: float
    ) -> None:
        d, s, t = self.distance_m, self.state, obs.t_s
        stop = self._stop_m(turn_radius)
        close = self.half_length + self.MARGIN_M
        lost = max(2.5 * d, d + 1.0)
        ahead = v.front_m + self.offset  # from P, the point it spins about
        if obs.bump and s != State.BACK_OFF:  # back away from the nearer obstacle
            s, self._until = State.BACK_OFF, t + self.backoff_s
            self._back_dir = -1.0 if v.front_m <= v.back_m else 1.0
        elif s == State.BACK_OFF and t >= self._until:
            s = State.TURN_CORNER
        elif s == State.FIND_WALL:
            if v.front_m < stop + 0.1:
                s = State.TURN_CORNER
            elif v.wall_m < 1.2 * d:
                s = State.FOLLOW
        elif s in (State.FOLLOW, State.ROUND_CORNER):
            if v.front_m < stop:
                s = State.TURN_CORNER
            elif v.wall_m > lost:
                s = State.FIND_WALL
            elif s == State.FOLLOW and self.s * v.along_rad > 0.5:
                s = State.ROUND_CORNER  # the wall point drifts behind: the wall ends there
            elif s == State.ROUND_CORNER and abs(v.along_rad) < 0.3:
                s = State.FOLLOW
        elif s == State.TURN_CORNER:
            done = v.front_m > stop + 0.15 and abs(v.along_rad) < 0.35 and v.wall_m < lost
            self._done_since = min(self._done_since, t) if done else math.inf
            if t - self._done_since >= 0.1:  # for 0.1 s: a beam grazing a corner flickers
                s = State.FOLLOW
            elif not can_spin and v.front_m < close:  # car-like: back up on the other lock
                s = State.REVERSE
            elif can_spin and ahead < self.sweep_m + 0.02 and v.back_m > close:
                s = State.REVERSE  # too close to turn on the spot: back up straight first
        elif s == State.REVERSE:
            if v.back_m < close:
                s = State.TURN_CORNER
            elif not can_spin and v.front_m > stop:
                s = State.TURN_CORNER
            elif can_spin and ahead > self.sweep_m + 0.1:
                s = State.TURN_CORNER
        if s == State.TURN_CORNER and self.state != State.TURN_CORNER:
            self._done_since = math.inf
            # turn away from the wall; a robot that spins about a point behind its centre (a
            # tricycle) and finds a wall too close on that side turns the long way round
            roomy = v.room_away_m >= self.sweep_m + 0.05 or v.room_away_m >= v.room_wall_m
            self._turn_dir = -self.s if (roomy or not can_spin) else self.s
        self.state = s

    def _act(self, v: WallView, can_spin: bool) -> tuple[float, float]:
        """(vx, omega) of the active state."""
        s, away = self.state, -self.s  # turning away from the wall: omega sign
        if s == State.FIND_WALL:
            return self.speed, min(max(2.0 * self._keep_clear(v), -self.rate), self.rate)
        if s in (State.FOLLOW, State.ROUND_CORNER):
            return self._follow(v, can_spin)
        if s == State.TURN_CORNER:
            if can_spin:
                return 0.0, self._turn_dir * self.rate
            return 0.4 * self.speed, away * 10.0 * self.rate  # full lock (steering clamps it)
        if s == State.REVERSE:
            return -0.4 * self.speed, 0.0 if can_spin else away * 10.0 * self.rate
        return 0.4 * self.speed * self._back_dir, 0.0  # BACK_OFF

    def _follow(self, v: WallView, can_spin: bool) -> tuple[float, float]:
        """Steer along the wall, plus a correction towards the set distance."""
        error = min(max(1.5 * (v.wall_m - self.distance_m), -0.8), 0.8)
        tau = v.along_rad + self.s * error + self._keep_clear(v)  # heading change wanted, rad
        omega = min(max(2.0 * tau, -self.rate), self.rate)
        slow = min(max((v.front_m - self._stop_m(0.0)) / 0.5, 0.25), 1.0)
        vx = self.speed * slow * max(math.cos(tau), 0.0 if can_spin else 0.3)
        if can_spin and abs(tau) > 1.0:  # far off the wall's direction: turn first
            vx = 0.0
        return vx, omega

    def _keep_clear(self, v: WallView) -> float:
        """Heading change (rad) away from a wall abeam on the other side that is closer than
        the room the robot needs to turn on the spot."""
        short = max(self.sweep_m + 0.05 - v.other_m, 0.0)
        return self.s * min(1.5 * short, 0.8)

    # ------------------------------------------------------------------ sensing
    def _look(self, obs: Observation) -> WallView:
        scan = obs.scans[self.sensor]
        pose = obs.odom_pose if self.heading_source == "odometry" else obs.true_pose
        if scan.stamp_s != self._stamp:  # a new frame: its returns in the P frame
            self._stamp = scan.stamp_s
            self._points = _returns_xy(scan, self.mount)
            self._pose_at_scan = pose.copy()
        pts = _carry(self._points, self._pose_at_scan, pose)  # to where the robot is now
        pts[:, 0] -= self.offset  # body-centre frame
        x, y = pts[:, 0], pts[:, 1]
        # ahead / behind: in a band as wide as the body (+ margin), past its ends (a wall
        # alongside, within the margin, is not in the way)
        band = np.abs(y) < self.half_width + self.MARGIN_M
        ends = 0.8 * self.half_length if scan.ranges.size > 4 else 0.0
        ahead, behind = band & (x > ends), band & (x < -ends)
        front = float(x[ahead].min()) if ahead.any() else math.inf
        back = float(-x[behind].max()) if behind.any() else math.inf
        if scan.ranges.size > 4:
            wall, along = self._nearest_wall(x, y)
        else:  # single beams: a wall met at an angle reaches the body's corner first
            front, back = front - self.half_width, back - self.half_width
            wall, along = self._ranger_wall(x, y, pose)
        bearing = np.arctan2(-self.s * y, x)  # > 0 on the other side
        abeam = (bearing > math.pi / 4) & (bearing < 3 * math.pi / 4)
        other = float(np.hypot(x[abeam], y[abeam]).min()) if abeam.any() else math.inf
        r_p = np.hypot(x + self.offset, y)  # from P, the point the robot spins about
        away, toward = self.s * y < 0.0, self.s * y > 0.0
        room_away = float(r_p[away].min()) if away.any() else math.inf
        room_wall = float(r_p[toward].min()) if toward.any() else math.inf
        return WallView(front, back, wall, along, other, room_away, room_wall)

    def _nearest_wall(self, x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
        """Nearest return on the follow side: its distance and the direction along it. Only
        returns up to 30 deg behind abeam count (the wall just left behind at an inner corner
        is not the one to follow), except when rounding a wall's end, which falls behind."""
        reach = math.pi if self.state == State.ROUND_CORNER else 2.0 * math.pi / 3.0
        on_side = (self.s * y > 0.0) & (np.arctan2(self.s * y, x) <= reach)
        if not on_side.any():
            return math.inf, 0.0
        r = np.hypot(x[on_side], y[on_side])
        k = int(np.argmin(r))
        bearing = math.atan2(y[on_side][k], x[on_side][k])
        return float(r[k]), wrap_scalar(bearing - self.s * math.pi / 2)

    def _ranger_wall(self, x: np.ndarray, y: np.ndarray, pose: np.ndarray) -> tuple[float, float]:
        """Rangers: the side beam's return if it has one (square walls: run along the nearest
        axis), else the last wall point seen, circled like a wall end."""
        side = (self.s * y > 0.5 * np.abs(x)) & (self.s * y > 0.0)
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        if side.any():
            k = int(np.argmin(np.abs(y[side])))
            px, py = x[side][k] + self.offset, y[side][k]
            self._mark = np.array([pose[0] + c * px - sn * py, pose[1] + sn * px + c * py])
            square = round(pose[2] / (math.pi / 2)) * (math.pi / 2)
            return float(abs(y[side][k])), wrap_scalar(square - pose[2])
        if self._mark is None:
            return math.inf, 0.0
        dx, dy = self._mark[0] - pose[0], self._mark[1] - pose[1]
        mx, my = c * dx + sn * dy - self.offset, -sn * dx + c * dy
        return math.hypot(mx, my), wrap_scalar(math.atan2(my, mx) - self.s * math.pi / 2)

    # ------------------------------------------------------------------ commanding
    def _model(self, model: object) -> tuple[bool, float]:
        """(turns on the spot, minimum turning radius m of the reference point)."""
        if self._model_info is None:
            if not getattr(model, "has_steering", False):
                self._model_info = (True, 0.0)
            else:
                max_steer = float(np.min(model.steering_limits()[0]))  # type: ignore[attr-defined]
                if max_steer >= math.pi / 2 - 1e-9:
                    self._model_info = (True, 0.0)
                else:
                    wheelbase = float(np.max(model.wheelbase_m))  # type: ignore[attr-defined]
                    self._model_info = (False, wheelbase / math.tan(max_steer))
        return self._model_info

    def _command(self, obs: Observation, vx: float, omega: float):
        cmd = command_for(obs, vx, 0.0, omega)
        model = obs.model
        if obs.mode != "forward" or not getattr(model, "has_steering", False):
            return cmd
        # the steered wheel turns at a limited rate: drive for the angle it will have
        max_angle, max_rate = (float(np.min(v)) for v in model.steering_limits())  # type: ignore[attr-defined]
        target = self._steer if vx == 0.0 and omega == 0.0 else cmd.steering  # type: ignore[union-attr]
        target = min(max(target, -max_angle), max_angle)
        step = max_rate * obs.dt_s
        self._steer += min(max(target - self._steer, -step), step)
        twist = np.array([vx, 0.0, omega])
        drive = model.drive_for(twist, np.asarray(self._steer))  # type: ignore[attr-defined]
        return WheelCommand(tuple(float(w) for w in np.ravel(drive)), target)


def _returns_xy(scan: LaserScan, mount_xy: tuple[float, float]) -> np.ndarray:
    """(K, 2) points of a scan's returns in the robot (P) frame; -inf (too close) counts as
    a return at range_min."""
    r = np.where(scan.ranges == -np.inf, scan.range_min_m, scan.ranges)
    a = scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(r.size)
    ok = np.isfinite(r)
    r, a = r[ok], a[ok]
    return np.column_stack([mount_xy[0] + r * np.cos(a), mount_xy[1] + r * np.sin(a)])


def _carry(points: np.ndarray, then: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Points seen in the robot frame at pose ``then``, in the robot frame at pose ``now``."""
    c0, s0 = math.cos(then[2]), math.sin(then[2])
    wx = then[0] + c0 * points[:, 0] - s0 * points[:, 1]
    wy = then[1] + s0 * points[:, 0] + c0 * points[:, 1]
    c1, s1 = math.cos(now[2]), math.sin(now[2])
    dx, dy = wx - now[0], wy - now[1]
    return np.column_stack([c1 * dx + s1 * dy, -s1 * dx + c1 * dy])


# ---------------------------------------------------------------------------------- scenario
