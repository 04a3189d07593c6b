"""Local SLAM: scan-to-submap tracking, the motion filter and submaps.

Everything here lives in the *local* frame, the frame tracking builds as it goes; the pose graph
(:mod:`.graph_slam`) later maps it to the optimised global frame, so tracking never jumps.

* A :class:`Submap` is a rigid piece of map: a log-odds occupancy grid (ray updates, for the loop
  closure field and the final picture) and a live likelihood field stamped at every hit. Two
  submaps are active and overlap (each keyframe goes into both); the older one, always holding
  at least half of ``submap_keyframes`` scans, is the one scans are matched against. When it is
  full it is finished: its likelihood field is recomputed exactly from the occupied cells and it
  becomes a loop-closure target.
* Tracking per scan: odometry prediction ``x_pred = x_prev * (o_prev^-1 * o_now)``, then a
  correlative search in a small window around ``x_pred``, then Gauss-Newton refinement
  (:mod:`.scan_matching`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import NDArray

from agvsim.slam import scan_matching as sm
from agvsim.slam.mapping import gaussian_kernel, likelihood_field, stamp_points, update_log_odds
from agvsim.slam.se2 import between, compose

__all__ = ["MotionFilter", "Submap", "Tracker", "TrackingConfig"]

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]


@dataclass(frozen=True)
class TrackingConfig:
    """Knobs of local SLAM (metres, radians)."""

    resolution_m: float = 0.05  # 20 cells/m, the thesis's map resolution
    sigma_m: float = 0.05  # width of the likelihood field exp(-d^2 / 2 sigma^2)
    window_m: float = 0.15  # correlative search window around the odometry prediction, +-
    window_rad: float = math.radians(6.0)
    prior_lin_weight: float = 2.0  # motion prior: score - w_t |dt|^2 - w_th dth^2 (1/m^2, 1/rad^2)
    prior_ang_weight: float = 2.0
    retry_score: float = 0.6  # below it, search again in the wide window
    wide_window_m: float = 0.4
    wide_window_rad: float = math.radians(40.0)
    gn_iterations: int = 10
    gn_prior_weight: float = 1e-4
    submap_keyframes: int = 40  # keyframes per submap
    submap_half_size_m: float = 45.0  # live submap grid: +- this around its origin
    surface_gap_m: float = 0.5  # neighbouring returns closer than this are joined in the field
    l_hit: float = 0.85
    l_miss: float = -0.4
    l_clamp: float = 4.0


@njit(cache=True)
def densify_surface(
    ends: np.ndarray, hits: np.ndarray, max_gap_m: float, step_m: float
) -> np.ndarray:
    """The hit points ``ends[hits]`` (in beam order) plus points every ``step_m`` on the segment
    between two neighbouring hits closer than ``max_gap_m``: one scan's returns on a wall lie a
    beam spacing apart (13 cm at 5 m for 1.5 degree beams); joined, the wall is a ridge in the
    likelihood field instead of a row of bumps that would pull the next scan back onto the same
    beam pattern (along a corridor whose ends are out of range)."""
    n = ends.shape[0]
    count = 0
    for k in range(n):
        if hits[k]:
            count += 1
            if k + 1 < n and hits[k + 1]:
                gap = math.hypot(ends[k + 1, 0] - ends[k, 0], ends[k + 1, 1] - ends[k, 1])
                if gap <= max_gap_m:
                    count += int(gap / step_m)
    out = np.empty((count, 2))
    j = 0
    for k in range(n):
        if not hits[k]:
            continue
        out[j, 0], out[j, 1] = ends[k, 0], ends[k, 1]
        j += 1
        if k + 1 < n and hits[k + 1]:
            dx, dy = ends[k + 1, 0] - ends[k, 0], ends[k + 1, 1] - ends[k, 1]
            gap = math.hypot(dx, dy)
            if gap <= max_gap_m:
                m = int(gap / step_m)
                for i in range(1, m + 1):
                    f = i / (m + 1)
                    out[j, 0], out[j, 1] = ends[k, 0] + f * dx, ends[k, 1] + f * dy
                    j += 1
    return out[:j]


@dataclass
class Submap:
    """A rigid local map; ``origin`` is its frame in the local tracking frame."""

    index: int
    origin: F64  # (3,) local pose of the first keyframe inserted
    ox: float  # grid corner in the local frame
    oy: float
    logodds: F32
    likelihood: F32  # likelihood field M for matching
    kernel: F32
    nodes: list[int] = field(default_factory=list)
    finished: bool = False

    def insert(
        self, cfg: TrackingConfig, sensor_xy: F64, ends: F64, hits: NDArray[np.bool_], node: int
    ) -> None:
        """Ray-update the log-odds grid and stamp the hits into the live field (local frame)."""
        res = cfg.resolution_m
        update_log_odds(
            self.logodds,
            self.ox,
            self.oy,
            res,
            sensor_xy,
            ends,
            hits,
            cfg.l_hit,
            cfg.l_miss,
            -cfg.l_clamp,
            cfg.l_clamp,
        )
        pts = ends[hits]
        if cfg.surface_gap_m > 0:
            pts = densify_surface(ends, hits, cfg.surface_gap_m, 0.5 * res)
        stamp_points(self.likelihood, self.ox, self.oy, res, pts, self.kernel)
        self.nodes.append(node)

    def finish(self, cfg: TrackingConfig) -> None:
        """Crop to the mapped cells and recompute the field exactly from the occupied cells."""
        known = np.nonzero(self.logodds != 0)
        if known[0].size:
            pad = self.kernel.shape[0]
            y0, x0 = max(known[0].min() - pad, 0), max(known[1].min() - pad, 0)
            y1, x1 = known[0].max() + pad + 1, known[1].max() + pad + 1
            self.logodds = np.ascontiguousarray(self.logodds[y0:y1, x0:x1])
            self.ox += x0 * cfg.resolution_m
            self.oy += y0 * cfg.resolution_m
        self.likelihood = likelihood_field(self.logodds > 0, cfg.sigma_m, cfg.resolution_m)
        self.finished = True


def new_submap(index: int, origin: F64, cfg: TrackingConfig, kernel: F32) -> Submap:
    res, half = cfg.resolution_m, cfg.submap_half_size_m
    n = int(math.ceil(2 * half / res))
    ox = math.floor((origin[0] - half) / res) * res
    oy = math.floor((origin[1] - half) / res) * res
    z = np.zeros((n, n), np.float32)
    return Submap(index, origin.copy(), ox, oy, z, z.copy(), kernel)


@dataclass
class MotionFilter:
    """A scan becomes a keyframe when the robot moved ``distance_m`` or turned ``angle_rad``
    since the last keyframe, or ``time_s`` passed."""

    distance_m: float
    angle_rad: float
    time_s: float
    last_pose: F64 | None = None
    last_time: float = -math.inf

    def is_keyframe(self, pose: F64, timestamp: float) -> bool:
        if self.last_pose is not None:
            d = between(self.last_pose, pose)
            moved = math.hypot(d[0], d[1]) >= self.distance_m or abs(d[2]) >= self.angle_rad
            if not moved and timestamp - self.last_time < self.time_s:
                return False
        self.last_pose, self.last_time = pose.copy(), timestamp
        return True


class Tracker:
    """Local SLAM state: the local pose, the last odometry and the active submaps."""

    def __init__(self, cfg: TrackingConfig) -> None:
        self.cfg = cfg
        self.kernel = gaussian_kernel(cfg.sigma_m, cfg.resolution_m)
        self.pose: F64 | None = None  # local pose of the last scan
        self.odom: F64 | None = None
        self.active: list[Submap] = []
        self.submaps: list[Submap] = []

    def predict(self, odom_pose: F64) -> F64:
        """``x_pred = x_prev * (o_prev^-1 * o_now)``; the first scan starts at its odometry."""
        if self.pose is None or self.odom is None:
            return np.asarray(odom_pose, np.float64).copy()
        return compose(self.pose, between(self.odom, odom_pose))

    def match(self, points: F64, guess: F64, ang_step: float) -> tuple[F64, float]:
        """Correlative search then Gauss-Newton against the older active submap. A poor match
        (score under ``retry_score``: odometry glitch, fast turn) is searched again in the wide
        window. ``ang_step`` (rad) is the angular search step."""
        if not self.active:
            return guess, 0.0
        s, cfg = self.active[0], self.cfg
        res = cfg.resolution_m
        pose, score = sm.correlative_search(
            s.likelihood,
            s.ox,
            s.oy,
            res,
            points,
            guess,
            cfg.window_m,
            cfg.window_rad,
            ang_step,
            cfg.prior_lin_weight,
            cfg.prior_ang_weight,
        )
        if score < cfg.retry_score:
            wide, wide_score = sm.correlative_search(
                s.likelihood,
                s.ox,
                s.oy,
                res,
                points,
                guess,
                cfg.wide_window_m,
                cfg.wide_window_rad,
                2.0 * ang_step,
                0.0,
                0.0,
            )
            if wide_score > score:
                pose, score = sm.correlative_search(
                    s.likelihood,
                    s.ox,
                    s.oy,
                    res,
                    points,
                    wide,
                    res,
                    2.0 * ang_step,
                    ang_step,
                    0.0,
                    0.0,
                )
        refined, score2, _ = sm.gauss_newton(
            s.likelihood, s.ox, s.oy, res, points, pose, cfg.gn_iterations, cfg.gn_prior_weight
        )
        score = sm.score_pose(s.likelihood, s.ox, s.oy, res, points, pose)
        if score2 >= score and np.all(np.abs(refined[:2] - pose[:2]) < res):
            return refined, score2
        return pose, score

    def accept(self, pose: F64, odom_pose: F64) -> None:
        self.pose, self.odom = pose, np.asarray(odom_pose, np.float64).copy()

    def insert(
        self, node: int, pose: F64, sensor_xy: F64, ends: F64, hits: NDArray[np.bool_]
    ) -> list[Submap]:
        """Insert a keyframe (local frame) into the active submaps, starting a new submap every
        half ``submap_keyframes``; returns the submaps that got finished."""
        cfg = self.cfg
        half = max(cfg.submap_keyframes // 2, 1)
        if not self.active or len(self.active[-1].nodes) >= half:
            s = new_submap(len(self.submaps), pose, cfg, self.kernel)
            self.submaps.append(s)
            self.active.append(s)
        for s in self.active:
            s.insert(cfg, sensor_xy, ends, hits, node)
        done = []
        if len(self.active[0].nodes) >= cfg.submap_keyframes:
            first = self.active.pop(0)
            first.finish(cfg)
            done.append(first)
        return done

    def finish_all(self) -> list[Submap]:
        done = [s for s in self.active if s.nodes]
        for s in done:
            s.finish(self.cfg)
        self.active = []
        return done
