"""Odometry's translation scale measured scan to scan, free of the map tracking drew
(:class:`PairScale`).

:class:`~.fusion.OdometryFusion` estimated the scale from matches against the submap. Those
agree with whatever odometry drew the submap with: over the first metres, where odometry alone
draws it (the warm-up) and the fusion trusts it, a wheel 5 % long draws corridors 5 % long and
the matches confirm them (docs/slam.md, "A scale error in the first metres"). Two raw scans a
metre apart know nothing of the map: the second scan matched against the first measures the
motion between them wherever the scene pins it down.

Each pair is two scans ``pair_m`` of odometry path apart (the second starts the next pair, so
pairs share no scan). The second scan is matched against a likelihood field of the first
(neighbouring returns joined, as in a submap) from the *unscaled* odometry increment, and the
first against the second's (what either scan sees that the other does not pulls the two
matches opposite ways; the pair takes their mean). Only points both scans see are used: a
point is kept where the other scan's beam in its direction returned within ``covisible_m`` of
it, on a surface drawn as a ridge (no points past the other scan's range, behind what hid them
from it, or on a wall so far off and edge-on that its returns lie metres apart: bumps, which
would hold the match on the other scan's beam pattern). The matches give the motion ``m``
along odometry's direction of travel ``d``; the information there, ``I = sum (n . d)^2`` over
the matched points with ``n`` the normal of the surface each lies on, weighs it: a corridor's
side walls give none, however noisy their returns, and a match with under ``min_facing`` is
dropped. The scale is the weighted least-squares ``k`` of ``d . m ~ k |o|``, robust (pairs off
by more than three robust deviations left out), with its standard error from the pairs' own
scatter; it is taken (:meth:`PairScale.decided`) once the pairs hold ``min_path_m`` of
odometry path and ``k`` lies more than three standard errors, and more than odometry's noise
floor, from 1.

A direction the scene does not pin down can only pull ``k`` towards 1, the unscaled odometry
the search starts from, never towards a scale estimated before: nothing feeds back."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import densify_surface
from agvsim.slam.mapping import gaussian_kernel, stamp_points
from agvsim.slam.se2 import between, inverse

__all__ = ["PairScale", "PairScaleConfig"]

F64 = NDArray[np.float64]
_NORMAL_BEAMS = 6  # a beam's normal from neighbours up to this many beams away each way
_NORMAL_SPAN_M = 0.6  # ... no farther apart than this (a corner nearby stays out)
_NORMAL_MIN_SPAN_M = 0.15  # ... and no nearer: over a shorter chord range noise turns it


@dataclass
class _Scan:
    """A scan as a pair keeps it, and what is worked out from it once (a scan ends one pair
    and starts the next, so it is matched on twice)."""

    odom: F64  # odometry pose as given
    ranges: F64  # raw beams, laser frame
    angles: F64
    mount: F64  # the laser's pose on the robot
    ends: NDArray[np.float32]  # map rays, robot frame (GraphSlam.scan_points)
    hits: NDArray[np.bool_]
    points: F64  # matching points, robot frame
    joined: NDArray[np.bool_] | None = None  # PairScale._surface
    normals: F64 | None = None
    field: tuple[NDArray[np.float32], float, float] | None = None  # PairScale._field


@dataclass(frozen=True)
class PairScaleConfig:
    """Settings of :class:`PairScale` (lengths m, angles rad)."""

    pair_m: float = 1.0  # odometry path between a pair's two scans
    covisible_m: float = 0.3  # a point is used where the other scan's beam returned this near
    max_turn_rad: float = math.radians(60.0)  # a pair that turned more is dropped
    min_points: int = 30  # fewer points both scans see: the pair is dropped
    min_score: float = 0.6  # a pair whose match fits worse is dropped
    # a match with less information along the direction of travel is dropped: sum (n . d)^2
    # over its points (a dozen points on a wall square to the motion)
    min_facing: float = 12.0
    heading_window_rad: float = math.radians(6.0)  # search +- around odometry's heading
    min_path_m: float = 5.0  # pairs' odometry path before a scale is decided
    max_pairs: int = 500  # pairs kept (the newest), about this many metres of path
    scale_range: tuple[float, float] = (0.8, 1.25)  # a decided scale is clamped to it


class PairScale:
    """Collects scale pairs from a stream of scans (:meth:`observe`) and estimates odometry's
    translation scale from them (:meth:`estimate`, :meth:`decided`)."""

    def __init__(
        self,
        resolution_m: float,
        sigma_m: float,
        surface_gap_m: float,
        max_range_m: float,
        config: PairScaleConfig | None = None,
        noise_floor: float = 0.0,
    ) -> None:
        self.cfg = config or PairScaleConfig()
        # a scale within this of 1 is left to odometry's noise (TrackingConfig.odom_floor_m_per_m)
        self.noise_floor = noise_floor
        self.res, self.gap, self.max_range_m = resolution_m, surface_gap_m, max_range_m
        self.kernel = gaussian_kernel(sigma_m, resolution_m)
        # the pair's first scan (_Scan)
        self._ref: _Scan | None = None
        self._path = 0.0  # odometry path since the first scan
        self._last: F64 | None = None
        # per pair: motion measured along the odometry direction, odometry's length, weight
        self.pairs: deque[tuple[float, float, float]] = deque(maxlen=self.cfg.max_pairs)
        self.n_dropped = 0
        self.scale = 1.0  # decided() as of the last pair

    def observe(
        self,
        odom: F64,
        ranges: F64,
        angles: F64,
        mount: F64,
        points: F64,
        ends: NDArray[np.float32],
        hits: NDArray[np.bool_],
    ) -> None:
        """One scan: ``odom`` its odometry pose as given (unscaled), ``ranges``/``angles`` the
        raw beams (laser frame; inf: no return), ``mount`` the laser's pose on the robot,
        ``points`` the matching points (robot frame), ``ends``/``hits`` the map rays (robot
        frame, :meth:`~.graph_slam.GraphSlam.scan_points`). Beams must be evenly spaced, in
        either order (a scan whose are not takes no part in a pair)."""
        odom = np.asarray(odom, np.float64)
        if not _even(np.asarray(angles, np.float64)):
            self._ref, self._last = None, None
            return
        if self._last is not None:
            self._path += math.hypot(odom[0] - self._last[0], odom[1] - self._last[1])
        self._last = odom.copy()
        here = _Scan(
            odom.copy(),
            np.asarray(ranges, np.float64),
            np.asarray(angles, np.float64),
            np.asarray(mount, np.float64),
            ends,
            hits,
            points,
        )
        if self._ref is None:
            self._ref, self._path = here, 0.0
            return
        o = between(self._ref.odom, odom)
        if abs(o[2]) > self.cfg.max_turn_rad:
            self._ref, self._path = here, 0.0  # turned too far: little overlap, start again
            self.n_dropped += 1
            return
        if self._path < self.cfg.pair_m:
            return
        pair = self._pair(here, o, points)
        if pair is None:
            self.n_dropped += 1
        else:
            self.pairs.append(pair)
            self.scale = self.decided()
        self._ref, self._path = here, 0.0

    def _pair(self, here: _Scan, o: F64, points: F64) -> tuple[float, float, float] | None:
        """The pair's ``(d . m, |o|, I)``: the second scan matched on the first and the first
        on the second, averaged; None when either cannot be measured."""
        length = math.hypot(o[0], o[1])
        if length < 0.5 * self.cfg.pair_m or self._ref is None:
            return None  # drove there and back: odometry's direction means little
        d = o[:2] / length
        fwd = self._match(self._ref, o, points, d)
        # the backward match places the first scan in the second's frame: the motion is its
        # inverse, and the direction of travel in that frame is d turned back by the heading
        c, s = math.cos(o[2]), math.sin(o[2])
        d_back = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        back = self._match(here, inverse(o), self._ref.points, d_back)
        if fwd is None or back is None:
            return None
        along = 0.5 * (float(d @ fwd[0][:2]) + float(d @ inverse(back[0])[:2]))
        return along, length, 0.5 * (fwd[1] + back[1])

    def _match(self, ref: _Scan, o: F64, points: F64, d: F64) -> tuple[F64, float] | None:
        """``points`` (robot frame) of one scan matched on the scan ``ref`` from ``o`` (the
        scan's odometry pose in ``ref``'s frame): the pose found and the information along
        the direction of travel ``d`` (unit, ``ref``'s frame); None for a poor match, or one
        with under ``min_facing`` of that information."""
        pts, beam = self._covisible(points, o, ref)
        if len(pts) < self.cfg.min_points:
            return None
        c, s = math.cos(ref.mount[2]), math.sin(ref.mount[2])
        d_laser = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        _, normals = self._surface(ref)
        info = float(np.nansum((normals[beam] @ d_laser) ** 2))
        if not info >= self.cfg.min_facing:
            return None
        field, ox, oy = self._field(ref)
        res = self.res
        far = float(np.percentile(np.hypot(pts[:, 0], pts[:, 1]), 98))
        step = sm.angular_step(res, max(far, 3.0))
        # odometry may be off by as much as the clamp allows, along its direction
        lo, hi = self.cfg.scale_range
        win = max(hi - 1.0, 1.0 - lo) * math.hypot(o[0], o[1]) + 2.0 * res
        pose, _ = sm.correlative_search(
            field, ox, oy, res, pts, o, win, self.cfg.heading_window_rad, step, 0.0, 0.0
        )
        refined, _, _ = sm.gauss_newton(field, ox, oy, res, pts, pose, 20, 0.0)
        if np.all(np.abs(refined[:2] - pose[:2]) < res):
            pose = refined
        if sm.score_pose(field, ox, oy, res, pts, pose) < self.cfg.min_score:
            return None
        return pose, info

    def _covisible(self, points: F64, o: F64, ref: _Scan) -> tuple[F64, NDArray[np.int64]]:
        """The points (robot frame) that, placed at ``o`` in ``ref``'s robot frame, lie within
        ``covisible_m`` of where its beam in their direction returned, on a surface it drew as
        a ridge (:meth:`_surface`); and that beam's index for each (beams evenly spaced:
        :meth:`observe`)."""
        a_ref, mount = ref.angles, ref.mount
        c, s = math.cos(o[2]), math.sin(o[2])
        x = o[0] + c * points[:, 0] - s * points[:, 1] - mount[0]
        y = o[1] + s * points[:, 0] + c * points[:, 1] - mount[1]
        dist = np.hypot(x, y)
        bearing = np.arctan2(y, x) - mount[2]
        n = len(a_ref)
        inc = (a_ref[-1] - a_ref[0]) / (n - 1)
        step = abs(inc)
        rel = np.mod(math.copysign(1.0, inc) * (bearing - a_ref[0]) + 0.5 * step, 2.0 * math.pi)
        idx = np.rint((rel - 0.5 * step) / step).astype(np.int64)
        inside = (idx >= 0) & (idx < n)
        r = np.full(len(points), np.inf)
        r[inside] = ref.ranges[idx[inside]]
        ok = np.abs(dist - r) <= self.cfg.covisible_m
        ok[inside] &= self._surface(ref)[0][idx[inside]]
        return np.ascontiguousarray(points[ok]), idx[ok]

    def _surface(self, scan: _Scan) -> tuple[NDArray[np.bool_], F64]:
        """Which beams lie on one surface with both neighbours (a ridge in the field), and
        each beam's surface normal (laser frame, unit; nan where unknown); worked out once a
        scan.

        Neighbouring returns lie on one surface when within ``surface_gap_m``. A wall seen
        edge-on far off is sampled metres apart: its returns are bumps, which hold a match on
        the other scan's beam pattern along the wall. The normal is across the chord to the
        farthest neighbours, up to ``_NORMAL_BEAMS`` beams each way, on one surface with the
        beam and no more than ``_NORMAL_SPAN_M`` apart; unknown where that chord is under
        ``_NORMAL_MIN_SPAN_M`` (range noise would turn it)."""
        if scan.joined is None or scan.normals is None:
            r, a = scan.ranges, scan.angles
            n = len(r)
            ok = np.isfinite(r) & (r > 0.0) & (r <= self.max_range_m)
            rr = np.where(ok, r, 0.0)
            p = np.column_stack([rr * np.cos(a), rr * np.sin(a)])
            link = ok[:-1] & ok[1:] & (np.hypot(*np.diff(p, axis=0).T) <= self.gap)
            joined = np.zeros(n, bool)
            joined[1:-1] = link[:-1] & link[1:]
            broken = np.concatenate([[0], np.cumsum(~link)])  # broken links before each beam
            tangent = np.full((n, 2), np.nan)
            for k in range(1, _NORMAL_BEAMS + 1):
                if n <= 2 * k:
                    break
                i = np.arange(k, n - k)
                chord = p[i + k] - p[i - k]
                span = np.hypot(chord[:, 0], chord[:, 1])
                use = (broken[i + k] == broken[i - k]) & (span <= _NORMAL_SPAN_M)
                use &= span >= _NORMAL_MIN_SPAN_M
                tangent[i[use]] = chord[use] / span[use, None]
            scan.joined = joined
            scan.normals = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        return scan.joined, scan.normals

    def _field(self, scan: _Scan) -> tuple[NDArray[np.float32], float, float]:
        """The likelihood field of the scan's returns, neighbouring ones joined (robot frame),
        and its corner; worked out once a scan."""
        if scan.field is None:
            res = self.res
            surface = densify_surface(scan.ends, scan.hits, self.gap, 0.5 * res)
            pad = self.kernel.shape[0] * res
            ox = math.floor((float(surface[:, 0].min()) - pad) / res) * res
            oy = math.floor((float(surface[:, 1].min()) - pad) / res) * res
            w = int(math.ceil((float(surface[:, 0].max()) + pad - ox) / res)) + 1
            h = int(math.ceil((float(surface[:, 1].max()) + pad - oy) / res)) + 1
            field = np.zeros((h, w), np.float32)
            stamp_points(field, ox, oy, res, surface, self.kernel)
            scan.field = (field, ox, oy)
        return scan.field

    def estimate(self) -> tuple[float, float, float]:
        """``(k, standard error, path m)`` from the pairs kept; ``(1, inf, path)`` with too
        few."""
        if len(self.pairs) < 3:
            return 1.0, math.inf, 0.0
        arr = np.asarray(self.pairs)
        a, b, w = arr[:, 0], arr[:, 1], arr[:, 2]
        keep = np.ones(len(a), bool)
        for _ in range(2):
            k = float(np.sum(w[keep] * a[keep] * b[keep]) / np.sum(w[keep] * b[keep] ** 2))
            r = (a - k * b) * np.sqrt(w)
            sd = 1.4826 * float(np.median(np.abs(r[keep])))
            if sd <= 0.0:
                break
            keep = np.abs(r) <= 3.0 * sd
        k = float(np.sum(w[keep] * a[keep] * b[keep]) / np.sum(w[keep] * b[keep] ** 2))
        n = int(keep.sum())
        if n < 3:
            return 1.0, math.inf, 0.0
        r = (a[keep] - k * b[keep]) * np.sqrt(w[keep])
        var = float(np.sum(r * r)) / (n - 1)
        se = math.sqrt(var / float(np.sum(w[keep] * b[keep] ** 2)))
        return k, se, float(np.sum(b[keep]))

    def decided(self) -> float:
        """The scale to drive with: :meth:`estimate`'s ``k`` once its pairs hold
        ``min_path_m`` and it lies more than three standard errors and more than
        ``noise_floor`` from 1 (clamped to ``scale_range``), else 1. The floor: a scale error
        that small is within what the fusion allows odometry anyway, and a pair's match is
        not free of bias (on a simulated floor whose odometry's scale is 1 to 1e-4 the pairs
        said 0.998 with a standard error of 0.0004)."""
        k, se, path = self.estimate()
        if path < self.cfg.min_path_m or not abs(k - 1.0) > max(3.0 * se, self.noise_floor):
            return 1.0
        lo, hi = self.cfg.scale_range
        return min(max(k, lo), hi)


def _even(a: F64) -> bool:
    """Whether the beam angles ``a`` are evenly spaced (increasing or decreasing)."""
    if len(a) < 2:
        return False
    inc = (a[-1] - a[0]) / (len(a) - 1)
    return inc != 0.0 and bool(np.all(np.abs(np.diff(a) - inc) <= 1e-6 + 1e-3 * abs(inc)))
