"""Pursuit and evasion: the thesis's two-robot case study (section 7.1).

Two robots in a walled square. The pursuer (red) is faster but turns slower: it drives at the
target, and when the bearing to the target is off by more than ``reorient_rad`` (pi/8 in the
thesis) it stops and turns towards it. The evader (blue) turns faster: it wanders, and when the
pursuer comes within ``alert_distance_m`` it turns towards the side of the square with the
most free space and flees. Both keep off the walls with their range sensors (the thesis's
green rangers). Each knows the other's pose through ``obs.others`` (the scenario's
``knows:``), as the thesis fed the distance and angle between the robots to both.
Their scenario configs and builders (``pursue``, ``evade``) are in :mod:`agvsim.behaviours`.

Both are plain per-robot controllers (``reset()``, ``step(obs)``, ``state_name``) that ask
for body twists through ``command_for``, so they drive any model in either control mode.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.control.api import LaserScan, Observation, command_for


def _clip(v: float, limit: float) -> float:
    return min(max(v, -limit), limit)


def _other(obs: Observation, name: str, role: str) -> np.ndarray:
    """The pose of robot ``name`` from ``obs.others``, with a clear error when not known."""
    pose = obs.others.get(name)
    if pose is None:
        raise KeyError(
            f"the {role} of robot {obs.name!r} is {name!r}, but {obs.name!r} does not know "
            f"where it is (knows: {sorted(obs.others)}); add it to the robot's 'knows' list"
        )
    return pose


def _scan(obs: Observation, sensor: str) -> LaserScan:
    scan = obs.scans.get(sensor)
    if scan is None:
        raise KeyError(f"robot {obs.name!r} has no sensor {sensor!r} (it has {sorted(obs.scans)})")
    return scan


def _readings(scan: LaserScan) -> tuple[np.ndarray, np.ndarray]:
    """(angles rad in the robot frame, ranges m): no return reads range_max, too close 0."""
    ranges = np.nan_to_num(scan.ranges, posinf=scan.range_max_m, neginf=0.0)
    angles = scan.robot_angle_min_rad + scan.angle_increment_rad * np.arange(len(ranges))
    return angles, ranges


def _sector_min(scan: LaserScan, centre_rad: float, half_width_rad: float = 0.35) -> float:
    """Smallest reading (m) within +-half_width of a direction in the robot frame (the nearest
    beam when none is that close, as for the thesis's four single-beam rangers)."""
    angles, ranges = _readings(scan)
    off = np.abs(np.angle(np.exp(1j * (angles - centre_rad))))
    sel = off <= half_width_rad
    return float(ranges[sel].min() if sel.any() else ranges[np.argmin(off)])


class FreeSpace:
    """The free region around a robot, read from one scan of a range sensor.

    Between two neighbouring beams that both return, the obstacle is taken to be the straight
    segment joining the two hit points: exact for a straight wall, and on the safe side in a
    convex room (a corner lies beyond the segment). Next to a beam with no return, the wall
    seen by the other beam is taken to be square to it; with no return on either, the region
    reaches ``range_max``. Returns from inside the circle ``ignore`` (x, y, radius in the
    robot frame: a robot we mean to reach) are left out.
    """

    def __init__(
        self,
        scan: LaserScan,
        mount_xy_m: tuple[float, float] = (0.0, 0.0),
        ignore: tuple[float, float, float] | None = None,
    ):
        ranges = np.where(scan.ranges == -np.inf, 0.0, scan.ranges)
        n = len(ranges)
        self.mount = (float(mount_xy_m[0]), float(mount_xy_m[1]))
        self.a0, self.inc = scan.robot_angle_min_rad, scan.angle_increment_rad
        self.r_max = scan.range_max_m
        self.full = n > 1 and abs(n * self.inc - 2 * math.pi) < 1e-6
        angles = self.a0 + self.inc * np.arange(n)
        self.u = np.stack([np.cos(angles), np.sin(angles)], -1)  # (B, 2) beam directions
        self.hit = np.isfinite(ranges)
        self.r = np.where(self.hit, ranges, self.r_max)
        if ignore is not None:
            cx, cy, radius = ignore[0] - self.mount[0], ignore[1] - self.mount[1], ignore[2]
            pts = self.r[:, None] * self.u
            self.hit &= np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) > radius
            self.r = np.where(self.hit, self.r, self.r_max)

    def clearance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points (robot frame) from the border; > 0 is free."""
        x, y = x - self.mount[0], y - self.mount[1]
        n, u, r = len(self.r), self.u, self.r
        if n < 2 or self.inc <= 0:
            return np.where(self.hit[0], r[0] - (x * u[0, 0] + y * u[0, 1]), np.inf)
        rel = np.mod(np.arctan2(y, x) - self.a0, 2 * math.pi)
        k1 = np.floor(rel / self.inc).astype(np.int64)
        outside = k1 >= (n if self.full else n - 1)  # beyond a partial fan: not seen, free
        k1 = np.minimum(k1, n - 1)
        k2 = (k1 + 1) % n
        x1, y1 = r[k1] * u[k1, 0], r[k1] * u[k1, 1]
        ex, ey = r[k2] * u[k2, 0] - x1, r[k2] * u[k2, 1] - y1
        chord = (ex * (y - y1) - ey * (x - x1)) / np.maximum(np.hypot(ex, ey), 1e-9)
        square1 = r[k1] - (x * u[k1, 0] + y * u[k1, 1])
        square2 = r[k2] - (x * u[k2, 0] + y * u[k2, 1])
        h1, h2 = self.hit[k1], self.hit[k2]
        out = np.where(h1 & h2, chord, np.where(h1, square1, square2))
        out = np.where(h1 | h2, out, self.r_max - np.hypot(x, y))
        return np.where(outside, np.inf, out)


def corridor_lengths(scan: LaserScan, half_width_m: float, every: int = 1) -> np.ndarray:
    """(D, 2): for every ``every``-th beam direction (robot frame, rad), how far a body
    ``2 half_width_m`` wide could drive that way before meeting a return (capped at
    range_max)."""
    angles, ranges = _readings(scan)
    hit = np.isfinite(scan.ranges) | (scan.ranges == -np.inf)
    dirs = angles[::every]
    rel = angles[None, :] - dirs[:, None]
    along, lateral = ranges * np.cos(rel), np.abs(ranges * np.sin(rel))
    blocked = hit[None, :] & (along > 0.0) & (lateral < half_width_m)
    length = np.where(blocked, along, scan.range_max_m).min(axis=1)
    return np.stack([dirs, length], -1)


class WallGuard:
    """Keeps a robot's body off obstacles: the asked-for twist is kept if the body outline,
    driven by it for ``horizon_s``, stays ``margin_m`` inside the free space; otherwise the
    first safe one of: slower, turning on the spot, backing off or creeping forwards a little
    (``escape_m_s``), or standing still. Points already closer than the margin must get no
    closer."""

    def __init__(
        self,
        half_length_m: float = 0.3,
        half_width_m: float = 0.225,
        offset_x_m: float = 0.0,
        margin_m: float = 0.12,
        horizon_s: float = 0.5,
        escape_m_s: float = 0.15,
    ):
        hl, hw = half_length_m, half_width_m
        xs = offset_x_m + np.array([hl, hl, -hl, -hl, hl, -hl, 0.0, 0.0])
        ys = np.array([hw, -hw, hw, -hw, 0.0, 0.0, hw, -hw])
        self.outline = np.stack([xs, ys])  # (2, P) corners and edge midpoints, robot frame
        self.half_width_m = hw
        self.margin, self.escape = margin_m, escape_m_s
        self.times = horizon_s * np.arange(1, 5)[:, None] / 4.0  # (4, 1)

    @classmethod
    def for_robot(cls, spec: object, **kw) -> WallGuard:
        """A guard shaped like a RobotSpec's body."""
        hl, hw = spec.footprint_half_m  # type: ignore[attr-defined]
        return cls(hl, hw, spec.body_offset_x_m, **kw)  # type: ignore[attr-defined]

    def clearance(self, spaces: Sequence[FreeSpace], vx: float, omega: float) -> np.ndarray:
        """(T, P) clearance of the outline points over the horizon, driving (vx, omega)."""
        th = omega * self.times
        if abs(omega) < 1e-9:
            dx, dy = vx * self.times, 0.0 * self.times
        else:
            dx, dy = vx / omega * np.sin(th), vx / omega * (1.0 - np.cos(th))
        c, s = np.cos(th), np.sin(th)
        x, y = self.outline
        px, py = dx + c * x - s * y, dy + s * x + c * y
        return np.min([f.clearance(px, py) for f in spaces], axis=0)

    def apply(
        self, spaces: Sequence[FreeSpace], vx: float, omega: float
    ) -> tuple[float, float, bool]:
        """(vx, omega, changed): the first safe twist among the asked-for one and its
        fallbacks."""
        now = self.clearance(spaces, 0.0, 0.0)[0]
        floor = np.minimum(now - 1e-3, self.margin)
        e = self.escape
        options = [(vx, omega), (0.5 * vx, omega), (0.2 * vx, omega), (0.0, omega)]
        options += [(-e, 0.0), (e, 0.0), (-e, omega), (e, omega)]
        for k, (v, w) in enumerate(options):
            if np.all(self.clearance(spaces, v, w) >= floor):
                return v, w, k > 0
        return 0.0, 0.0, True


class Pursuer:
    """Drives at ``target``; stops and turns towards it when the bearing error exceeds
    ``reorient_rad`` (and drives again once it is below half of that).

    States: ``chase`` (full speed, steering at the target within ``turn_rate_rad_s``),
    ``reorient`` (turning at ``turn_rate_rad_s``, on the spot or at ``reorient_speed_m_s``),
    ``avoid`` (the wall guard changed the command). ``mounts_xy_m`` gives the sensors'
    positions on the robot (default: at the reference point).
    """

    def __init__(
        self,
        target: str,
        reorient_rad: float = math.pi / 8,
        speed_m_s: float = 1.0,
        turn_rate_rad_s: float = 1.0,
        reorient_speed_m_s: float = 0.0,
        heading_gain: float = 3.0,
        sensor: str = "rangers",
        guard: WallGuard | None = None,
        mounts_xy_m: Mapping[str, tuple[float, float]] | None = None,
        target_radius_m: float = 0.45,
    ):
        if not (0.0 < reorient_rad < math.pi):
            raise ValueError(f"reorient_rad must be in (0, pi), got {reorient_rad}")
        if speed_m_s <= 0 or turn_rate_rad_s <= 0:
            raise ValueError("speed_m_s and turn_rate_rad_s must be > 0")
        self.target, self.reorient_rad = target, reorient_rad
        self.speed, self.rate = speed_m_s, turn_rate_rad_s
        self.reorient_speed, self.gain = reorient_speed_m_s, heading_gain
        self.sensor, self.guard = sensor, guard or WallGuard()
        self.mount = (mounts_xy_m or {}).get(sensor, (0.0, 0.0))
        self.target_radius_m = target_radius_m
        self.reset()

    def reset(self) -> None:
        self.state_name = "chase"
        self._reorienting = False

    def step(self, obs: Observation):
        x, y, th = obs.true_pose
        tx, ty, _ = _other(obs, self.target, "target")
        err = wrap_scalar(math.atan2(ty - y, tx - x) - th)
        if self._reorienting and abs(err) < 0.5 * self.reorient_rad:
            self._reorienting = False
        elif not self._reorienting and abs(err) > self.reorient_rad:
            self._reorienting = True
        if self._reorienting:
            vx, omega = self.reorient_speed, math.copysign(self.rate, err)
        else:
            vx, omega = self.speed, _clip(self.gain * err, self.rate)
        # the target's body is no wall to keep off: its returns are left out
        c, s = math.cos(th), math.sin(th)
        target = (c * (tx - x) + s * (ty - y), c * (ty - y) - s * (tx - x), self.target_radius_m)
        free = FreeSpace(_scan(obs, self.sensor), self.mount, ignore=target)
        vx, omega, acted = self.guard.apply([free], vx, omega)
        self.state_name = "avoid" if acted else ("reorient" if self._reorienting else "chase")
        return command_for(obs, vx, 0.0, omega)


class Evader:
    """Wanders, and flees once the pursuer is within ``alert_distance_m``.

    The flight heading is the direction a body as wide as the robot could drive furthest
    (from ``space_sensor``, a lidar, or from ``sensor`` when the robot has no such sensor),
    traded against pointing away from the pursuer; it is kept until another direction is
    clearly better. Walls are kept off with both sensors. States: ``wander`` (straight on at
    ``wander_speed_m_s``), ``turn`` (a wall ahead while wandering: turning towards the side
    with more space), ``flee``, ``avoid`` (the wall guard changed the command).
    """

    def __init__(
        self,
        pursuer: str,
        alert_distance_m: float = 4.0,
        speed_m_s: float = 0.8,
        turn_rate_rad_s: float = 2.5,
        wander_speed_m_s: float | None = None,
        heading_gain: float = 4.0,
        sensor: str = "rangers",
        space_sensor: str = "lidar",
        space_cap_m: float = 6.0,
        away_weight: float = 0.7,
        trigger_m: float = 1.2,
        guard: WallGuard | None = None,
        mounts_xy_m: Mapping[str, tuple[float, float]] | None = None,
    ):
        if alert_distance_m <= 0 or speed_m_s <= 0 or turn_rate_rad_s <= 0:
            raise ValueError("alert_distance_m, speed_m_s and turn_rate_rad_s must be > 0")
        self.pursuer, self.alert = pursuer, alert_distance_m
        self.speed, self.rate, self.gain = speed_m_s, turn_rate_rad_s, heading_gain
        self.wander_speed = 0.5 * speed_m_s if wander_speed_m_s is None else wander_speed_m_s
        self.sensor, self.space_sensor = sensor, space_sensor
        self.space_cap, self.away_weight, self.trigger = space_cap_m, away_weight, trigger_m
        self.guard = guard or WallGuard()
        self.mounts = dict(mounts_xy_m or {})
        self.reset()

    def reset(self) -> None:
        self.state_name = self._state = "wander"
        self._heading: float | None = None  # world heading held while turning or fleeing
        self._space: tuple[float, np.ndarray] | None = None  # (scan stamp, world corridors)

    def _corridors(self, obs: Observation) -> np.ndarray:
        """(D, 2) world heading and free corridor length, recomputed once per new scan."""
        scan = obs.scans.get(self.space_sensor)
        scan = scan if scan is not None else _scan(obs, self.sensor)
        if self._space is None or self._space[0] != scan.stamp_s:
            half = self.guard.half_width_m + self.guard.margin
            cor = corridor_lengths(scan, half, every=max(1, len(scan.ranges) // 90))
            cor[:, 0] += obs.true_pose[2]
            self._space = (scan.stamp_s, cor)
        return self._space[1]

    def _flee_heading(self, obs: Observation, away: float) -> float:
        """The direction with the best score: corridor length (up to ``space_cap_m``, as a
        fraction of it) + ``away_weight`` x cos(angle to the way away from the pursuer)."""
        world, length = self._corridors(obs).T
        score = np.minimum(length, self.space_cap) / self.space_cap
        score = score + self.away_weight * np.cos(world - away)
        best = int(np.argmax(score))
        if self._state == "flee" and self._heading is not None:
            held = int(np.argmin(np.abs(np.angle(np.exp(1j * (world - self._heading))))))
            if score[best] < score[held] + 0.15:  # switch only for a clearly better way out
                return self._heading
        return wrap_scalar(float(world[best]))

    def step(self, obs: Observation):
        x, y, th = obs.true_pose
        px, py, _ = _other(obs, self.pursuer, "pursuer")
        scan = _scan(obs, self.sensor)
        front = _sector_min(scan, 0.0)
        if math.hypot(px - x, py - y) < self.alert:
            self._heading = self._flee_heading(obs, math.atan2(y - py, x - px))
            state, speed = "flee", self.speed
        elif self._state in ("wander", "flee") and front >= self.trigger:
            state, speed, self._heading = "wander", self.wander_speed, None
        else:  # a wall ahead: turn towards the side with more space
            if self._state != "turn" or self._heading is None:
                more_left = _sector_min(scan, math.pi / 2) >= _sector_min(scan, -math.pi / 2)
                self._heading = wrap_scalar(th + (math.pi / 2 if more_left else -math.pi / 2))
            state, speed = "turn", self.wander_speed
            if abs(wrap_scalar(self._heading - th)) < 0.1 or front >= 2.0 * self.trigger:
                state, self._heading = "wander", None
        if self._heading is None:
            vx, omega = speed, 0.0
        else:
            err = wrap_scalar(self._heading - th)
            vx = speed * max(math.cos(err), 0.0) ** 2
            omega = _clip(self.gain * err, self.rate)
        names = dict.fromkeys(n for n in (self.sensor, self.space_sensor) if n in obs.scans)
        spaces = [FreeSpace(obs.scans[n], self.mounts.get(n, (0.0, 0.0))) for n in names]
        vx, omega, acted = self.guard.apply(spaces, vx, omega)
        self._state = state
        self.state_name = "avoid" if acted else state
        return command_for(obs, vx, 0.0, omega)
