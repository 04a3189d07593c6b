"""Other robots, as a robot's lidar sees them: what every built-in behaviour uses to keep clear.

The behaviours already keep off the walls they know (the map) or sense (rangers, lidar). Other
robots move, and the thesis's single front ranger misses a robot that comes in at an angle. So
each behaviour reads its lidar through a ``RobotSight``:

1. **Returns that the map does not explain.** A beam's end point (world frame, from the pose
   the robot localises with) lying more than ``static_tol_m`` from every wall and box of the
   known map is a *moving* obstacle: another robot. The distance to the nearest wall or box
   comes from a ``StaticMap`` (a distance transform of the map on a 5 cm raster, built once).
2. **The room ahead, in the direction of travel.** The robot's footprint translated along the
   commanded velocity direction meets such a point after ``free_m`` metres (``inf`` if no point
   lies in the swept corridor): ``along - lead`` for points whose offset across the direction is
   under the body's half extent across it plus ``side_margin_m``.
3. **A speed that can stop in time** (``limit``): the linear speed falls linearly from full at
   ``stop_gap_m + slow_band_m`` of room to zero at ``stop_gap_m``; the turn rate of a car-like
   command falls with it (its path keeps its curvature), a robot that turns on the spot keeps
   its turn rate. Reversing looks behind, sideways looks sideways.

How a behaviour reacts to a robot in its way is its own: the thesis's obstacle avoidance treats
it like a wall ahead (turns right), the wall follower and the path followers wait for the room
to clear. ``limit`` is the safety net under all of them.

Walls edited into a running simulation (the app's maze editor) are not on the map a sight was
built with: they read as robots, so the robot stops before them instead of driving into them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

from agvsim.control.api import Observation, Twist, WheelCommand
from agvsim.world.grid import OccupancyGrid

RASTER_M = 0.05  # resolution of the static map's distance field
MAX_RASTER_CELLS = 4_000_000  # a larger map is rastered coarser (memory stays ~200 MB)
HORIZON_SAMPLES = 8  # instants checked along a commanded motion


@dataclass(frozen=True)
class StaticMap:
    """Distance (m) from a world point to the nearest wall cell or static box."""

    dist_m: np.ndarray  # (rows, cols) on a fine raster, row 0 = south
    origin_xy_m: tuple[float, float]
    resolution_m: float

    @classmethod
    def of(
        cls, grid: OccupancyGrid, boxes: np.ndarray | None = None, resolution_m: float = RASTER_M
    ) -> StaticMap:
        """The distance field of ``grid`` plus ``boxes`` ((K, 5) cx, cy, theta, half_length,
        half_width), sampled every ``resolution_m`` (outside the grid counts as wall); a map
        that would take more than ``MAX_RASTER_CELLS`` samples is sampled coarser."""
        xmin, xmax, ymin, ymax = grid.extent_m
        area_m2 = (xmax - xmin) * (ymax - ymin)
        resolution_m = max(resolution_m, math.sqrt(area_m2 / MAX_RASTER_CELLS))
        nx = int(math.ceil((xmax - xmin) / resolution_m))
        ny = int(math.ceil((ymax - ymin) / resolution_m))
        xs = xmin + (np.arange(nx) + 0.5) * resolution_m
        ys = ymin + (np.arange(ny) + 0.5) * resolution_m
        gx, gy = np.meshgrid(xs, ys)  # (ny, nx), row 0 = south
        solid = np.asarray(grid.is_occupied_at(gx, gy), dtype=bool)
        for cx, cy, th, hl, hw in np.asarray(boxes if boxes is not None else []).reshape(-1, 5):
            c, s = math.cos(th), math.sin(th)
            u = (gx - cx) * c + (gy - cy) * s
            v = -(gx - cx) * s + (gy - cy) * c
            solid |= (np.abs(u) <= hl) & (np.abs(v) <= hw)
        # pad with wall so that the map's edge counts as a wall
        padded = np.pad(solid, 1, constant_values=True)
        dist = distance_transform_edt(~padded)[1:-1, 1:-1] * resolution_m
        dist = np.maximum(dist - 0.5 * resolution_m, 0.0)  # to the solid cell's edge, roughly
        return cls(dist.astype(np.float64), (float(xmin), float(ymin)), float(resolution_m))

    def distance_m(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance to the nearest static surface at world points (0 outside the map)."""
        ix = np.floor((x - self.origin_xy_m[0]) / self.resolution_m).astype(np.int64)
        iy = np.floor((y - self.origin_xy_m[1]) / self.resolution_m).astype(np.int64)
        ny, nx = self.dist_m.shape
        inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        out = np.zeros(np.shape(x))
        out[inside] = self.dist_m[iy[inside], ix[inside]]
        return out


class ScanPoints(NamedTuple):
    """One scan per robot as points in its own frame (``(k, B)`` each); ``ranges`` arguments
    of ``RobotSight`` take these too, so that a step finds them once."""

    x_m: np.ndarray
    y_m: np.ndarray
    moving: np.ndarray  # bool: a return the map does not explain (another robot)
    hit: np.ndarray  # bool: a return at all


@dataclass(frozen=True)
class Footprint:
    """The body rectangle in the robot frame: centre ``offset_x_m`` ahead of the reference
    point, ``half_length_m`` along x, ``half_width_m`` along y (floats, or ``(k,)`` arrays for
    a batch of robots of different sizes)."""

    half_length_m: float | np.ndarray
    half_width_m: float | np.ndarray
    offset_x_m: float | np.ndarray = 0.0

    @classmethod
    def stack(cls, specs: list) -> Footprint:
        """The ``(k,)`` footprints of a batch of ``RobotSpec``."""
        fps = [cls.of(s) for s in specs]
        return cls(
            np.array([f.half_length_m for f in fps]),
            np.array([f.half_width_m for f in fps]),
            np.array([f.offset_x_m for f in fps]),
        )

    @classmethod
    def of(cls, spec: object) -> Footprint:
        """From a ``RobotSpec`` (body length, width, offset)."""
        return cls(
            float(spec.body_length_m) / 2.0,  # type: ignore[attr-defined]
            float(spec.body_width_m) / 2.0,  # type: ignore[attr-defined]
            float(getattr(spec, "body_offset_x_m", 0.0)),
        )


class RobotSight:
    """Finds other robots in one lidar's scans and the room they leave ahead (batch first).

    ``beam_angles_rad`` (B,) and ``mount`` describe the lidar in the robot frame; arrays of
    poses are ``(k, 3)`` and scans ``(k, B)``: one robot is a batch of one."""

    def __init__(
        self,
        static: StaticMap,
        sensor: str,
        beam_angles_rad: np.ndarray,
        footprint: Footprint,
        *,
        mount_xy_m: tuple[float, float] = (0.0, 0.0),
        mount_yaw_rad: float = 0.0,
        static_tol_m: float = 0.15,
        side_margin_m: float = 0.12,
        stop_gap_m: float = 0.2,
        slow_band_m: float = 0.5,
        stop_s: float = 0.4,
        slow_s: float = 0.8,
    ):
        self.static = static
        self.sensor = sensor
        a = np.asarray(beam_angles_rad, dtype=np.float64) + mount_yaw_rad
        self._cos, self._sin = np.cos(a), np.sin(a)
        self.mount = (float(mount_xy_m[0]), float(mount_xy_m[1]))
        self.body = footprint
        self.static_tol_m = static_tol_m
        self.side_margin_m = side_margin_m
        self.stop_gap_m = stop_gap_m
        self.slow_band_m = slow_band_m
        self.stop_s, self.slow_s = stop_s, slow_s
        self.horizon_s = stop_s + slow_s
        self._body_k: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def for_robots(
        cls, specs: list, static: object, sensor: str = "lidar", **kw: float
    ) -> RobotSight | None:
        """The sight of the sensor named ``sensor`` on a batch of ``RobotSpec`` (one robot: a
        list of one). None without a map or when a robot lacks that sensor, or the robots'
        sensors differ in their beams or mount (then each robot needs its own sight)."""
        if not isinstance(static, StaticMap) or not specs:
            return None
        found = []
        for spec in specs:
            match = [s for s in getattr(spec, "sensors", ()) if s.name == sensor]
            if not match:
                return None
            found.append(match[0])
        s0 = found[0]
        same = all(
            s.num_beams == s0.num_beams
            and np.allclose(s.beam_angles_rad, s0.beam_angles_rad)
            and tuple(s.mount_xy_m) == tuple(s0.mount_xy_m)
            and s.mount_yaw_rad == s0.mount_yaw_rad
            for s in found
        )
        if not same:
            return None
        return cls(
            static,
            sensor,
            s0.beam_angles_rad,
            Footprint.of(specs[0]) if len(specs) == 1 else Footprint.stack(specs),
            mount_xy_m=tuple(s0.mount_xy_m),  # type: ignore[arg-type]
            mount_yaw_rad=float(s0.mount_yaw_rad),
            **kw,  # type: ignore[arg-type]
        )

    def _body(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The footprint as three ``(k,)`` arrays (kept for the next step)."""
        if self._body_k is None or len(self._body_k[0]) != k:
            self._body_k = tuple(  # type: ignore[assignment]
                np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (k,)))
                for v in (self.body.half_length_m, self.body.half_width_m, self.body.offset_x_m)
            )
        return self._body_k  # type: ignore[return-value]

    def robot_points(self, poses: np.ndarray, ranges: np.ndarray | ScanPoints) -> ScanPoints:
        """Beam end points in the robot frame, ``(k, B)`` x and y, and a ``(k, B)`` mask of
        those the map does not explain (other robots). No return (inf) is never a robot; a
        return closer than the sensor's minimum (-inf) is taken at 0 m."""
        if isinstance(ranges, ScanPoints):
            return ranges
        r = np.ascontiguousarray(ranges, dtype=np.float64)
        k, b = r.shape
        bx, by = np.empty((k, b)), np.empty((k, b))
        moving, hit = np.empty((k, b), dtype=np.bool_), np.empty((k, b), dtype=np.bool_)
        st = self.static
        _scan_points(
            r,
            np.ascontiguousarray(poses, dtype=np.float64),
            self._cos,
            self._sin,
            self.mount[0],
            self.mount[1],
            st.dist_m,
            st.origin_xy_m[0],
            st.origin_xy_m[1],
            st.resolution_m,
            self.static_tol_m,
            bx,
            by,
            moving,
            hit,
        )
        return ScanPoints(bx, by, moving, hit)

    def free_m(
        self,
        poses: np.ndarray,
        ranges: np.ndarray | ScanPoints,
        direction_rad: np.ndarray | float = 0.0,
        *,
        walls_margin_m: float | None = None,
    ) -> np.ndarray:
        """(k,) room (m) before the footprint, moved along ``direction_rad`` (robot frame),
        touches another robot; inf where none is in the way. With ``walls_margin_m``, every
        return counts (walls too) and the corridor is only that much wider than the body: what
        a single front ranger misses, such as a wall corner between two beams."""
        return self.free_m_many(poses, ranges, [(direction_rad, walls_margin_m)])[0]

    def free_m_many(
        self,
        poses: np.ndarray,
        ranges: np.ndarray | ScanPoints,
        queries: list[tuple[np.ndarray | float, float | None]],
    ) -> np.ndarray:
        """(Q, k): :meth:`free_m` for each ``(direction_rad, walls_margin_m)`` of ``queries``,
        in one pass (obstacle avoidance asks four: ahead and behind, robots and walls)."""
        pts = self.robot_points(poses, ranges)
        k, nq = len(poses), len(queries)
        d, margin, use_hit = np.empty((nq, k)), np.empty(nq), np.empty(nq, dtype=np.bool_)
        for q, (direction, walls_margin_m) in enumerate(queries):
            d[q] = direction
            use_hit[q] = walls_margin_m is not None
            margin[q] = self.side_margin_m if walls_margin_m is None else walls_margin_m
        out = np.empty((nq, k))
        _free_along(pts.x_m, pts.y_m, pts.moving, pts.hit, use_hit, d, margin, *self._body(k), out)
        return out

    def time_to_contact_s(
        self, twists: np.ndarray, poses: np.ndarray, ranges: np.ndarray | ScanPoints
    ) -> np.ndarray:
        """(k,) time (s) until the body, moving with the body twist ``twists`` (k, 3) (exactly,
        on SE(2): straight, on an arc or on the spot), comes within ``side_margin_m`` of
        another robot's point: the first of ``HORIZON_SAMPLES`` instants up to ``horizon_s``;
        inf if none. A point already that close counts only once it would touch the body (so
        a robot can always move away from another one)."""
        pts = self.robot_points(poses, ranges)
        k = len(poses)
        out = np.empty(k)
        _time_to_contact(
            pts.x_m,
            pts.y_m,
            pts.moving,
            np.ascontiguousarray(twists, dtype=np.float64),
            *self._body(k),
            self.side_margin_m,
            self.horizon_s,
            HORIZON_SAMPLES,
            out,
        )
        return out

    def speed_factor(self, free_m: np.ndarray) -> np.ndarray:
        """(k,) 1 with room to spare, falling to 0 at ``stop_gap_m`` of room."""
        return np.clip((free_m - self.stop_gap_m) / self.slow_band_m, 0.0, 1.0)

    def limit(
        self, twists: np.ndarray, poses: np.ndarray, ranges: np.ndarray | ScanPoints
    ) -> np.ndarray:
        """``twists`` (k, 3) scaled down so that each robot stops before it meets another: full
        when contact is more than ``stop_s + slow_s`` away at the commanded twist, zero under
        ``stop_s`` (the whole twist is scaled: a path keeps its curvature)."""
        out = np.array(twists, dtype=np.float64, copy=True)
        return out * self.factor(out, poses, ranges)[:, None]

    def factor(
        self, twists: np.ndarray, poses: np.ndarray, ranges: np.ndarray | ScanPoints
    ) -> np.ndarray:
        """(k,) the scale ``limit`` applies: 1 when contact is more than ``stop_s + slow_s``
        away at the commanded twist, 0 under ``stop_s``, linear between."""
        ttc = self.time_to_contact_s(np.asarray(twists, dtype=np.float64), poses, ranges)
        return np.clip((ttc - self.stop_s) / self.slow_s, 0.0, 1.0)


def sight_sensor(spec: object, min_beams: int = 16) -> str | None:
    """The sensor a robot sees other robots with: the one named ``lidar``, else its sensor
    with the most beams (at least ``min_beams``); None if it has none."""
    sensors = list(getattr(spec, "sensors", ()))
    named = [s for s in sensors if s.name == "lidar"]
    if named:
        return "lidar"
    wide = sorted((s for s in sensors if s.num_beams >= min_beams), key=lambda s: -s.num_beams)
    return wide[0].name if wide else None


class KeepClear:
    """A one-robot behaviour whose commands a ``RobotSight`` slows so that the robot stops
    before another one (``RobotSight.limit``). A twist is scaled; wheel speeds are scaled with
    the steering angle kept, which scales the body twist alike (it is linear in the driven
    wheel speeds). Everything else (``reset``, ``state_name``, the behaviour's attributes) is
    the behaviour's own."""

    def __init__(self, behaviour: object, sight: RobotSight):
        self.behaviour = behaviour
        self.sight = sight

    def reset(self) -> None:
        reset = getattr(self.behaviour, "reset", None)
        if reset is not None:
            reset()

    @property
    def state_name(self) -> str:
        name = getattr(self.behaviour, "state_name", "")
        return name if isinstance(name, str) else ""

    def __getattr__(self, name: str) -> object:
        if name in ("behaviour", "sight"):  # not set yet (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.behaviour, name)

    def step(self, obs: Observation) -> object:
        step = getattr(self.behaviour, "step", None)
        cmd = step(obs) if step is not None else self.behaviour(obs)  # type: ignore[operator]
        scan = obs.scans.get(self.sight.sensor)
        if scan is None:
            return cmd
        if isinstance(cmd, Twist):
            twist = np.array([[cmd.vx, cmd.vy, cmd.omega]])
        elif isinstance(cmd, WheelCommand) and obs.model is not None:
            model: Any = obs.model
            drive = np.asarray(cmd.speeds, dtype=np.float64)[None, :]
            steer = np.array([cmd.steering]) if getattr(model, "has_steering", False) else None
            twist = np.asarray(model.forward(drive, steer), dtype=np.float64).reshape(1, 3)
        else:  # a command of another shape: leave it alone
            return cmd
        pose = np.asarray(obs.true_pose, dtype=np.float64)[None, :]
        f = float(self.sight.factor(twist, pose, scan.ranges[None, :])[0])
        if f >= 1.0:
            return cmd
        if isinstance(cmd, Twist):
            return Twist(cmd.vx * f, cmd.vy * f, cmd.omega * f)
        return WheelCommand(tuple(float(v) * f for v in cmd.speeds), cmd.steering)  # type: ignore[union-attr]


# ------------------------------------------------------------------------------ kernels
@njit(cache=True)
def _scan_points(
    ranges, poses, cos_b, sin_b, mx, my, dist, ox, oy, res, tol, bx, by, moving, hit
):  # pragma: no cover - numba
    """Beam end points (robot frame) and which of them the static map does not explain."""
    ny, nx = dist.shape
    for i in range(ranges.shape[0]):
        c, s = np.cos(poses[i, 2]), np.sin(poses[i, 2])
        for j in range(ranges.shape[1]):
            r = ranges[i, j]
            if r == -np.inf:
                r = 0.0
            h = np.isfinite(r)
            if not h:
                r = 0.0
            x, y = mx + r * cos_b[j], my + r * sin_b[j]
            bx[i, j], by[i, j], hit[i, j] = x, y, h
            mv = False
            if h:
                wx = poses[i, 0] + c * x - s * y
                wy = poses[i, 1] + s * x + c * y
                ix = int(np.floor((wx - ox) / res))
                iy = int(np.floor((wy - oy) / res))
                if 0 <= ix < nx and 0 <= iy < ny:
                    mv = dist[iy, ix] > tol
            moving[i, j] = mv


@njit(cache=True)
def _free_along(  # pragma: no cover - numba
    bx, by, moving, hit, use_hit, direction, margin, hl, hw, off, out
):
    """Room before each footprint, moved along ``direction[q]``, meets a point of the mask
    query ``q`` names (``hit`` where ``use_hit[q]``, else ``moving``), for every query."""
    for q in range(out.shape[0]):
        mask = hit if use_hit[q] else moving
        for i in range(bx.shape[0]):
            ux, uy = np.cos(direction[q, i]), np.sin(direction[q, i])
            lead = hl[i] * abs(ux) + hw[i] * abs(uy)
            half = hl[i] * abs(uy) + hw[i] * abs(ux) + margin[q]
            best = np.inf
            for j in range(bx.shape[1]):
                if not mask[i, j]:
                    continue
                qx, qy = bx[i, j] - off[i], by[i, j]
                along = qx * ux + qy * uy
                if along > 0.0 and abs(-qx * uy + qy * ux) < half:
                    best = min(best, along - lead)
            out[q, i] = best


@njit(cache=True)
def _inside(x, y, hl, hw, off, margin):  # pragma: no cover - numba
    return abs(x - off) <= hl + margin and abs(y) <= hw + margin


@njit(cache=True)
def _time_to_contact(
    bx, by, moving, twists, hl, hw, off, margin, horizon, samples, out
):  # pragma: no cover - numba
    """First sampled instant at which each moving footprint comes within ``margin`` of a
    masked point (points already that close: when they would touch the body)."""
    for i in range(bx.shape[0]):
        out[i] = np.inf
        vx, vy, w = twists[i, 0], twists[i, 1], twists[i, 2]
        for n in range(1, samples + 1):
            t = horizon * n / samples
            th = w * t
            if abs(th) < 1e-9:
                a, b = 1.0 - th * th / 6.0, th / 2.0
            else:
                a, b = np.sin(th) / th, (1.0 - np.cos(th)) / th
            dx, dy = (a * vx - b * vy) * t, (b * vx + a * vy) * t
            c, s = np.cos(th), np.sin(th)
            found = False
            for j in range(bx.shape[1]):
                if not moving[i, j]:
                    continue
                px, py = bx[i, j], by[i, j]
                qx, qy = px - dx, py - dy
                lx, ly = c * qx + s * qy, -s * qx + c * qy
                if _inside(lx, ly, hl[i], hw[i], off[i], 0.0) or (
                    _inside(lx, ly, hl[i], hw[i], off[i], margin)
                    and not _inside(px, py, hl[i], hw[i], off[i], margin)
                ):
                    found = True
                    break
            if found:
                out[i] = t
                break


def refresh_static(controllers: Any, static: StaticMap) -> int:
    """Give every :class:`RobotSight` of ``controllers`` (the simulation's bindings or the
    controllers themselves) the map ``static``, after the walls or boxes changed (a maze
    editor): otherwise a new wall would read as a robot. Returns how many were updated."""
    n = 0
    for c in controllers:
        ctrl = getattr(c, "controller", c)
        sight = ctrl.__dict__.get("sight") if hasattr(ctrl, "__dict__") else None
        if isinstance(sight, RobotSight):
            sight.static = static
            n += 1
    return n
