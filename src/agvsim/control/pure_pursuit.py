"""Follow waypoints by pure pursuit, for every kinematic model.

``PathTracker`` keeps the robot's progress along a polyline; ``PurePursuit`` chases a carrot
``lookahead_m`` ahead of it with :func:`agvsim.control.mobility.pursuit_twist`. Holonomic models
translate at the carrot (and may face along the path), models that turn on the spot turn
towards it, car-like models clip the curvature to their lock.

Poses come from the ground truth (``pose_source="true_pose"``) or from wheel odometry.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from agvsim.control.api import Observation, command_for
from agvsim.control.mobility import (
    Mobility,
    PoseSource,
    SteeringGuard,
    check_pose_source,
    pose_of,
    pursuit_twist,
)


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
