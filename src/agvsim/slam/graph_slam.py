"""Online graph SLAM for 2-D laser scans: :class:`GraphSlam`.

Per scan (:meth:`GraphSlam.update`), in the order of the paper (Hess et al. 2016, after Olson
2009 and Konolige et al. 2010):

1. predict the pose from odometry, match the scan against the active submap and weigh the two
   by their noises, learnt from the run (local SLAM, :mod:`.frontend`; the first scans are
   processed again once the noises are known);
2. keep it as a keyframe when the robot moved or turned enough (motion filter): a graph node
   with edges to the submaps it is inserted in and to the previous keyframe (local SLAM's
   relative pose, firm where the keyframe's match placed it and soft where it did not, along a
   corridor: :func:`local_information`; and odometry's, with its learnt noise);
3. look for loop closures: finished submaps within the search radius, branch-and-bound matching,
   verification (:mod:`.loop_closure`);
4. when a loop closed, optimise the sparse pose graph (Levenberg-Marquardt, :mod:`.posegraph`):
   a Huber kernel on local-SLAM and odometry edges, switchable constraints on loop closures
   (dynamic covariance scaling, :class:`~.robust.RobustKernel`), so a false closure that got
   through verification is switched off instead of bending the map. The switches' prior is
   relaxed first and tightened in stages (graduated non-convexity): a right closure after a
   long loop starts far from the drifted graph and would be switched off at once otherwise.

The graph's variables are the global poses of keyframes and of submap origins. Every scan keeps
its local pose and its keyframe, so its global pose after optimisation is
``g_k = G_kf * (l_kf^-1 * l_k)``; the map is rendered from the optimised keyframes on request
(:meth:`GraphSlam.occupancy_map`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from agvsim.angles import wrap_scalar
from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import MotionFilter, Submap, Tracker, TrackingConfig
from agvsim.slam.loop_closure import (
    LoopClosure,
    LoopConfig,
    LoopDetector,
    TiePlaces,
    drift_bounds,
    step_variances,
)
from agvsim.slam.mapping import OccupancyMap, render_occupancy
from agvsim.slam.memory import release_free_heap
from agvsim.slam.posegraph import PoseGraph, edge_chi2, optimize
from agvsim.slam.posegraph_graduated import graduated_scales
from agvsim.slam.relocalise import global_search
from agvsim.slam.scale_pairs import PairScale, PairScaleConfig
from agvsim.slam.se2 import between, compose, inverse

__all__ = ["GraphSlam", "SlamConfig"]

_MAX_WARMUP_SCANS = 2000  # kept for processing again; a robot standing still longer goes on
_WARMUP_PASSES = 3
_END_UNIT_M = 0.002  # finest step of the keyframes' stored map rays (m)

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class SlamConfig:
    """One configuration for every log (metres, radians). ``max_range_m = None`` derives the
    usable range from the sensor: ``min(sensor max, usable_range_m)``; the angular search step
    follows from the scan's ranges (:meth:`GraphSlam.angular_step`).

    The thesis's knobs: map resolution 20 cells/m is ``tracking.resolution_m``; max range 8 m
    is ``max_range_m`` (its 10 m lidar); the loop-closure threshold is ``loop.min_score`` (a
    mean likelihood in [0, 1]); the search radius 3 m is ``loop.search_radius_m``, widened by
    the uncertainty accumulated on the way back to each old keyframe, over the chain and the
    accepted closures (:func:`~.loop_closure.drift_bounds`)."""

    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    loop: LoopConfig = field(default_factory=LoopConfig)
    max_range_m: float | None = None
    usable_range_m: float = 40.0
    min_range_m: float = 0.1
    keyframe_distance_m: float = 0.2
    keyframe_angle_rad: float = math.radians(5.0)
    keyframe_time_s: float = 10.0
    sigma_local_m: float = 0.02  # std of a local-SLAM relative pose (keyframe chain, submaps)
    sigma_local_rad: float = math.radians(0.5)
    # ... along its best-placed direction: the keyframe's match shapes the rest, its weakest
    # direction's information floored at this fraction (local_information; a keyframe in a
    # corridor is placed along it by odometry, not by the walls); in (0, 1], 1: round, as
    # before
    local_weak_floor: float = 0.05
    huber_scale: float = 3.0  # in standard deviations
    switchable_loops: bool = True  # loop closures as switchable constraints (else Huber)
    switch_scale: float = 3.0  # closures within this many std keep their full weight
    switch_stage_factor: float = 10.0  # graduated prior: chi2 bound divided by this per stage
    odometry_edges: bool = True  # keyframe-to-keyframe odometry edges, weighted by the noise
    odometry_floor_m: float = 0.002  # that tracking estimated (floors of their std per scan)
    odometry_floor_rad: float = math.radians(0.02)
    optimize_every: int = 50  # keyframes at least between two optimisations of small closures
    global_relocalisation: bool = True  # search every finished submap when tracking is lost
    # odometry's scale measured from pairs of raw scans a metre apart, not from matches against
    # the map tracking drew (agvsim.slam.scale_pairs); None: from those matches, as before
    scale_pairs: PairScaleConfig | None = field(default_factory=PairScaleConfig)

    @classmethod
    def point_samples(cls) -> SlamConfig:
        """The defaults, but every return stamped into the live field as a bump, glimpses
        through doors too (``tracking.edge_on_turn_rad`` None): the published logs' figures
        and issue 19's rounds up to the eleventh (``agvsim slam --point-samples``). Along a
        corridor whose ends lie beyond the scanner's reach those bumps hold tracking on its
        last keyframe (docs/slam.md)."""
        return cls(tracking=TrackingConfig(edge_on_turn_rad=None))


def _information(sigma_m: float, sigma_rad: float) -> F64:
    return np.diag([sigma_m**-2, sigma_m**-2, sigma_rad**-2])


def local_information(
    hess: F64 | None, heading: float, sigma_m: float, sigma_rad: float, floor: float
) -> F64:
    """Information (3, 3) of a local-SLAM edge into a keyframe at local ``heading`` (the edge
    error is in the keyframe's frame) from its match's ``J^T J`` ``hess`` (local frame): std
    ``sigma_m`` along the best-placed direction, ``sigma_m / sqrt(max(l / l_max, floor))``
    along the other (``l`` the eigenvalues of the translation block), ``sigma_rad`` in
    heading. Along a corridor whose ends are out of reach the walls do not place a scan, and
    a round 2 cm edge there held a tracking slip of a metre against the loop closures that
    would have mended it (ACES, docs/slam-history.md). ``hess`` None, or no gradient: round."""
    if not 0.0 < floor <= 1.0:
        raise ValueError(f"local_weak_floor must lie in (0, 1], got {floor}")
    info = _information(sigma_m, sigma_rad)
    if hess is None or floor == 1.0:
        return info
    c, s = math.cos(heading), math.sin(heading)
    rot = np.array([[c, s], [-s, c]])  # local -> keyframe frame: R^T
    h = rot @ np.asarray(hess, np.float64)[:2, :2] @ rot.T
    w, v = np.linalg.eigh(h)
    if not w[-1] > 0.0:
        return info
    w = np.maximum(w / w[-1], floor) / sigma_m**2
    block = (v * w) @ v.T
    info[:2, :2] = 0.5 * (block + block.T)  # symmetric to the last bit
    return info


@dataclass
class _Keyframe:
    """What a keyframe keeps for the whole run, compactly (about 5 bytes a beam): its map rays
    as int16 multiples of ``end_unit_m`` (a few mm; the map's cells are 5 cm) and hit flags.
    Its matching points are needed only by its own loop-closure search, right after it is
    added: :class:`GraphSlam` drops them then (``points`` is None after that)."""

    local: F64  # (3,) local tracking pose
    points: F64 | None  # (n, 2) matching points, robot frame; None once its loops were searched
    ends_q: NDArray[np.int16]  # (m, 2) beam end points for the map, robot frame, in end_unit_m
    end_unit_m: float
    hits: NDArray[np.bool_]  # (m,) True: a return; False: the ray only clears space
    ang_step: float  # angular search step for its points (rad)
    odom: F64  # (3,) the robot's odometry pose at the keyframe
    submap: int = -1  # the submap it was matched against (the most complete)

    @property
    def ends(self) -> NDArray[np.float32]:
        """(m, 2) beam end points (m, robot frame), to within half ``end_unit_m``."""
        return self.ends_q.astype(np.float32) * np.float32(self.end_unit_m)

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays (what grows with the number of keyframes)."""
        pts = 0 if self.points is None else self.points.nbytes
        return pts + self.ends_q.nbytes + self.hits.nbytes + self.local.nbytes + self.odom.nbytes


class GraphSlam:
    """Graph SLAM over a stream of scans from one laser mounted at ``laser_offset``
    (``T_robot_laser``) with beam angles ``angles`` (rad) and maximum reading
    ``sensor_max_range_m``."""

    def __init__(
        self,
        sensor_max_range_m: float,
        laser_offset: F64 | None = None,
        config: SlamConfig | None = None,
    ) -> None:
        self.cfg = cfg = config or SlamConfig()
        self.max_range_m = cfg.max_range_m or min(sensor_max_range_m, cfg.usable_range_m)
        self.laser_offset = np.zeros(3) if laser_offset is None else np.asarray(laser_offset, float)
        # keyframes' map rays are kept as int16: 2 mm steps up to 65 m, coarser beyond
        reach = self.max_range_m + float(np.hypot(*self.laser_offset[:2]))
        self.end_unit_m = max(_END_UNIT_M, reach / (np.iinfo(np.int16).max - 1))
        # the first scans, kept to be processed again once odometry's and the matches' noises
        # are known (None after that, or without odometry fusion)
        self._warmup: list[tuple] | None = [] if cfg.tracking.fuse_odometry else None
        tr = cfg.tracking
        self.pair_scale = (
            PairScale(
                tr.resolution_m,
                tr.sigma_m,
                tr.surface_gap_m,
                self.max_range_m,
                cfg.scale_pairs,
                tr.odom_floor_m_per_m,
            )
            if tr.fuse_odometry and cfg.scale_pairs is not None
            else None
        )
        self._reset()

    def _reset(self) -> None:
        cfg = self.cfg
        self.tracker = Tracker(cfg.tracking)
        if self.tracker.fusion is not None:
            self.tracker.fusion.pairs = self.pair_scale
        self.tracker.max_range_m = self.max_range_m
        self.tracker.sensor_xy = self.laser_offset[:2].copy()
        self.motion = MotionFilter(
            cfg.keyframe_distance_m, cfg.keyframe_angle_rad, cfg.keyframe_time_s
        )
        self.loops = LoopDetector(cfg.loop, cfg.tracking.resolution_m)
        self.graph = PoseGraph()
        self.keyframes: list[_Keyframe] = []
        self.node_var: list[int] = []  # graph variable of each keyframe
        self.submap_var: list[int] = []  # graph variable of each submap
        self.scan_times: list[float] = []
        self.scan_local: list[F64] = []
        self.scan_keyframe: list[int] = []
        self.loop_edges: list[LoopClosure] = []
        self._homes = np.zeros(0, np.int64)  # each keyframe's submap
        self._var_t = np.zeros(0)  # drift variance added by the step to each keyframe (m^2)
        self._var_r = np.zeros(0)  # ... in heading (rad^2)
        # each loop closure's keyframe and the first and last keyframes of the submap it tied,
        # and the keyframes those the optimiser kept hold together (drift_bounds)
        self._ties: list[tuple[int, int, int]] = []
        self._places = TiePlaces()
        self.n_optimisations = 0
        self._global_from_local = np.zeros(3)
        # closures added since the last optimisation, and whether one of them moves the graph
        self._unoptimised = 0
        self._moving_closure = False
        self._loop_edge_ids: list[int] = []  # graph edge index of every loop closure
        self._loops_optimised = 0  # closures in the graph at the last optimisation
        self.switches = np.zeros(0)  # switch of every loop closure at the last optimisation
        self._last_optimised_node = 0
        # the last keyframe whose odometry reading was live (not taken while odometry stalled)
        # and the count of scans at it: odometry edges run from there
        self._odom_anchor: tuple[int, int] | None = None
        self._odom = np.zeros(3)  # odometry pose of the scan being processed
        # a scan since the anchor whose match refuted odometry, or that fitted another
        # prediction than scan to scan where no stall explains it (a stall does not count: a
        # frozen odometry is right again from before the stall once it moves)
        self._odom_doubted = False
        # the last scan that fitted (score at least tracking.retry_score): local pose and
        # odometry, and the scans since (a global relocalisation is checked against them)
        self._fit: tuple[F64, F64] | None = None
        self._since_fit = 0
        self._froze = False  # odometry reported standing still at one of those scans
        self._relocated: int | None = None  # submap a global relocalisation found the scan in
        self.n_global_relocalised = 0

    # ------------------------------------------------------------------ the algorithm
    def update(self, timestamp: float, ranges: F64, angles: F64, odom_pose: F64) -> F64:
        """Process one scan (ranges (n,) m, inf = no return; angles (n,) rad in the laser
        frame; odom_pose (3,) robot base pose by odometry); returns its global pose (3,).

        The first scans are tracked by odometry alone while the noises of odometry and of the
        scan matches are learnt from them (matches against a map odometry built show its
        drift); once enough scans taken on the move are in, they are processed again with the
        two fused (their poses and the first submaps are replaced)."""
        scan = None
        if self.pair_scale is not None:
            # once a scan (the warm-up's scans processed again are not observed twice)
            scan = self.scan_points(ranges, angles)
            self.pair_scale.observe(odom_pose, ranges, angles, self.laser_offset, *scan)
        fusion = self.tracker.fusion
        if self._warmup is not None and fusion is not None:
            if fusion.ready() or len(self._warmup) >= _MAX_WARMUP_SCANS:
                scans, self._warmup = self._warmup, None
                for _ in range(_WARMUP_PASSES):
                    # each pass tracks with the noises the one before learnt (the first pass
                    # had odometry alone, which hides part of a drifting odometry's error)
                    if fusion is None or not fusion.ready():
                        break
                    noises, turn_ratio = fusion.learn()
                    self._reset()
                    fusion = self.tracker.fusion
                    if fusion is not None:
                        fusion.preset(noises, turn_ratio)
                        for args in scans:
                            self._step(*args)
            else:
                self._warmup.append((timestamp, ranges, angles, odom_pose))
        return self._step(timestamp, ranges, angles, odom_pose, scan)

    def _step(
        self,
        timestamp: float,
        ranges: F64,
        angles: F64,
        odom_pose: F64,
        scan: tuple[F64, NDArray[np.float32], NDArray[np.bool_]] | None = None,
    ) -> F64:
        """One scan through tracking, mapping and loop closing; ``scan`` its
        :meth:`scan_points` when already worked out."""
        points, ends, hits = self.scan_points(ranges, angles) if scan is None else scan
        self.tracker.view = self._view(angles)
        guesses = self.tracker.predict(odom_pose)
        self._odom = self.tracker.odom_now.copy()  # scale-corrected (odometry edges)
        pose, score = self.tracker.match(points, guesses, self.angular_step(points))
        # a scan that fits poorly is not mapped until it is clear whether the robot entered
        # unmapped space (it goes on) or was carried off (found again in an old submap)
        hold = (
            self.cfg.global_relocalisation and 0 < self.tracker.poor < self.cfg.tracking.lost_scans
        )
        # nor is a lost scan that fits nowhere, until the robot has driven on for a while
        hold = hold or (
            self.tracker.unmatched and self.tracker.poor <= self.cfg.tracking.unmatched_hold_scans
        )
        if self.tracker.lost and self._relocalise_due():
            found = self.relocalise(points, pose, score)
            if found is not None:
                pose, self._relocated = found
                self.tracker.restart(pose)
                self.motion.last_pose = None  # a keyframe here, tied to where it was found
                self.n_global_relocalised += 1
                self._fit = None  # found: odometry counts from here
                hold = False  # and the scan is mapped where it was found
        if score >= self.cfg.tracking.retry_score or self._fit is None:
            self._fit, self._since_fit, self._froze = (pose.copy(), self._odom.copy()), 0, False
        else:
            self._since_fit += 1
            self._froze |= self._odometry_still()
        self.tracker.accept(pose, odom_pose)
        self._odom_doubted |= self.tracker.odom_suspect or (
            self.tracker.doubted and not self.tracker.check.encoder_stall
        )
        if not hold and self.motion.is_keyframe(pose, timestamp):
            node = self.add_keyframe(pose, points, ends, hits)
            closures = self.find_loop_closures(node)
            if self._relocated is not None:
                closures = self.relocation_closure(node, self._relocated) + closures
                self._relocated = None
            for closure in closures:
                self.add_loop_closure(closure)
            self.keyframes[node].points = None  # only its own loop search needed them
            if self.loop_closed():
                self.optimise()
        self.scan_times.append(float(timestamp))
        self.scan_local.append(pose)
        self.scan_keyframe.append(len(self.keyframes) - 1)
        return compose(self._global_from_local, pose)

    # ------------------------------------------------------------------ the stages
    def scan_points(
        self, ranges: F64, angles: F64
    ) -> tuple[F64, NDArray[np.float32], NDArray[np.bool_]]:
        """Matching points (returns within the usable range, robot frame, thinned to one per
        cell) and map rays (end points clipped to the usable range, with their hit flags)."""
        r = np.asarray(ranges, np.float64)
        a = np.asarray(angles, np.float64)
        ok = (r >= self.cfg.min_range_m) & np.isfinite(r)  # no return: no information
        rr, aa = r[ok], a[ok]
        hit = rr <= self.max_range_m
        rc = np.minimum(rr, self.max_range_m)
        lo = self.laser_offset
        xl, yl = rc * np.cos(aa + lo[2]), rc * np.sin(aa + lo[2])
        ends = np.column_stack([xl + lo[0], yl + lo[1]])
        pts = ends[hit]
        res = self.cfg.tracking.resolution_m
        cells = np.floor(pts / res).astype(np.int64)
        _, first = np.unique(cells[:, 0] * 1_000_003 + cells[:, 1], return_index=True)
        return np.ascontiguousarray(pts[np.sort(first)]), ends.astype(np.float32), hit

    def _view(self, angles: F64) -> tuple[float, float] | None:
        """The scanner's field of view in the robot frame, first and last beam (rad); None
        for a scanner that looks all round (a gap of at most two beam spacings). Beams given
        across the +-pi seam (a rear scanner's -180..-90 and 90..180 deg) read as all round:
        no points are then left out (:meth:`~.frontend.Tracker.towards_blind_side`)."""
        a = np.asarray(angles, np.float64)
        if len(a) < 2:
            return None
        lo, hi = float(np.min(a)), float(np.max(a))
        if 2.0 * math.pi - (hi - lo) <= 2.0 * (hi - lo) / (len(a) - 1):
            return None
        yaw = float(self.laser_offset[2])
        return lo + yaw, hi + yaw

    def angular_step(self, points: F64) -> float:
        """Search step that moves the scan's far points (98th percentile of the ranges, at least
        3 m) by about one cell (:func:`~.scan_matching.angular_step`): a few far points need
        not set a fine step for all, Gauss-Newton refines the angle."""
        r_ref = _reference_range(points) if len(points) else max(self.max_range_m, 3.0)
        return sm.angular_step(self.cfg.tracking.resolution_m, r_ref)

    def add_keyframe(
        self, pose: F64, points: F64, ends: NDArray[np.float32], hits: NDArray[np.bool_]
    ) -> int:
        """Graph node for the keyframe, edges to the previous keyframe and its submaps."""
        node = len(self.keyframes)
        ends_q = np.rint(ends / self.end_unit_m).astype(np.int16)
        kf = _Keyframe(
            pose.copy(),
            points,
            ends_q,
            self.end_unit_m,
            hits,
            self.angular_step(points),
            self._odom.copy(),
        )
        self.keyframes.append(kf)
        var = self.graph.add_node(compose(self._global_from_local, pose))
        self.node_var.append(var)
        cfg = self.cfg
        info_local = local_information(
            self.tracker.hessian,
            pose[2],
            cfg.sigma_local_m,
            cfg.sigma_local_rad,
            cfg.local_weak_floor,
        )
        # this keyframe's odometry stands still while the robot moves (a stalled encoder): no
        # odometry edge to or from it; the next live keyframe is tied to the last live one
        stale = self.tracker.check.encoder_stall
        if node > 0 and self._relocated is None:  # no chain edge across a relocalisation
            prev = self.keyframes[node - 1]
            self.graph.add_edge(self.node_var[node - 1], var, between(prev.local, pose), info_local)
            noise = self.tracker.odometry_variance()
            anchor = self._odom_anchor
            # no odometry edge across a stretch where scan matching refuted odometry (a jump
            # it was not right after, a slip): it would pull against the local-SLAM edges
            if (
                cfg.odometry_edges
                and noise is not None
                and anchor is not None
                and not self._odom_doubted
                and not stale
            ):
                # odometry's error is a random walk: the variance grows with the scans between
                a_node, a_scans = anchor
                n = max(len(self.scan_times) - a_scans, 1)
                v_t = n * max(noise[0], cfg.odometry_floor_m**2)
                v_r = n * max(noise[1], cfg.odometry_floor_rad**2)
                info = np.diag([1.0 / v_t, 1.0 / v_t, 1.0 / v_r])
                z = between(self.keyframes[a_node].odom, kf.odom)
                self.graph.add_edge(self.node_var[a_node], var, z, info)
        elif self._relocated is not None:
            self._odom_anchor = None  # odometry did not see the robot carried off
        if not stale:
            self._odom_anchor = (node, len(self.scan_times))
            self._odom_doubted = False
        n_before = len(self.tracker.submaps)
        sensor_xy = compose(pose, self.laser_offset)[:2]
        self.tracker.insert(node, pose, sensor_xy, compose(pose, _xy0(ends))[:, :2], hits)
        for s in self.tracker.submaps[n_before:]:
            self.submap_var.append(self.graph.add_node(compose(self._global_from_local, s.origin)))
        owners = [s for s in self.tracker.submaps[-3:] if s.nodes and s.nodes[-1] == node]
        for s in owners:
            self.graph.add_edge(self.submap_var[s.index], var, between(s.origin, pose), info_local)
        kf.submap = min(s.index for s in owners)
        if node >= len(self._homes):
            grow = max(node, 64)
            self._homes = np.concatenate([self._homes, np.zeros(grow, np.int64)])
            self._var_t = np.concatenate([self._var_t, np.zeros(grow)])
            self._var_r = np.concatenate([self._var_r, np.zeros(grow)])
        self._homes[node] = kf.submap
        if node > 0 and self._relocated is None:
            step = between(self.keyframes[node - 1].local, pose)
            self._var_t[node], self._var_r[node] = step_variances(cfg.loop, step)
        return node

    def find_loop_closures(self, node: int) -> list[LoopClosure]:
        """Candidates within the search radius, matched and verified (for a keyframe whose
        matching points are still kept: the newest)."""
        cfg = self.cfg
        est = self.graph.poses[np.asarray(self.node_var)]
        homes = self._homes[: len(self.keyframes)]
        kf = self.keyframes[node]
        if kf.points is None:
            raise ValueError(f"keyframe {node}: its matching points were dropped")
        out: list[LoopClosure] = []
        self._places.grow(node + 1)
        drift_m, drift_rad = drift_bounds(
            est[:, :2], self._var_t, self._var_r, node, cfg.loop.drift_sigmas, self._places.place
        )
        for s, bound_m, bound_rad in self.loops.candidates(
            node, est[:, :2], homes, drift_m, self.tracker.submaps, drift_rad
        ):
            g_s = self.graph.poses[self.submap_var[s]]
            closure = self.loops.match(
                node,
                kf.points,
                kf.ang_step,
                est[node].copy(),  # not a view: it is kept in the closure
                kf.local,
                self.tracker.submaps[s],
                g_s,
                bound_m,
                bound_rad,
            )
            if closure is not None:
                out.extend(self.loops.verify(closure))
        return out

    def _relocalise_due(self) -> bool:
        """Global relocalisation is tried when tracking is lost, and again every ten times
        ``lost_scans`` while it stays lost (a long stretch of unmapped space)."""
        n = self.cfg.tracking.lost_scans
        lost = max(self.tracker.poor, n)
        return self.cfg.global_relocalisation and (lost - n) % (10 * n) == 0

    def relocalise(self, points: F64, local: F64, local_score: float) -> tuple[F64, int] | None:
        """Global relocalisation when tracking is lost: a subsample of the scan's points
        (``tracking.global_points``) looked for over the whole area of every finished submap
        and every heading, coarse to fine (:func:`~.relocalise.global_search`), then all points
        refined there. Accepted only when the whole scan scores at least
        ``tracking.global_min_score``, better than at the tracked pose ``local`` (score
        ``local_score``) by ``doubt.margin``, and lies away from it (more than
        ``relocalise_window_m``: nearer, tracking's own search had its chance), where
        odometry allows (:meth:`_odometry_allows`). Returns the local pose and the submap, or
        None."""
        cfg = self.cfg.tracking
        finished = [s for s in self.tracker.submaps if s.finished]
        if not finished or len(points) < 3:
            return None
        sub = points[:: max(1, len(points) // cfg.global_points)]
        res = cfg.resolution_m
        found = global_search(
            finished,
            sub,
            res,
            _reference_range(points),
            0.5 * cfg.global_min_score,  # the subsample's bound to beat
            self.loops.pyramid,
        )
        if found is None:
            return None
        s = self.tracker.submaps[found.submap]
        pyr = self.loops.pyramid(s)
        coarse = 2.0 * self.angular_step(points)
        step = self.angular_step(points)
        pose, _ = sm.branch_and_bound(
            pyr, s.ox, s.oy, res, points, found.pose, 2 * res, coarse, step, 0.0
        )
        pose, score, _ = sm.gauss_newton(
            pyr[0], s.ox, s.oy, res, points, pose, cfg.gn_iterations, 0.0
        )
        score = sm.score_pose(pyr[0], s.ox, s.oy, res, points, pose)
        d = between(local, pose)
        if (
            score < max(cfg.global_min_score, local_score + cfg.doubt.margin)
            or math.hypot(d[0], d[1]) <= cfg.relocalise_window_m
            or not self._odometry_allows(pose)
        ):
            return None
        return pose, s.index

    def _odometry_still(self) -> bool:
        """Odometry's increment to this scan is under ``doubt.moving_m`` and
        ``doubt.moving_rad`` (it reported standing still, up to its noise)."""
        prev = self.tracker.odom
        if prev is None:
            return False
        u, doubt = between(prev, self._odom), self.cfg.tracking.doubt
        return bool(math.hypot(u[0], u[1]) < doubt.moving_m and abs(u[2]) < doubt.moving_rad)

    def _odometry_allows(self, pose: F64) -> bool:
        """Whether a global relocalisation's pose (local frame) is one odometry allows: turned
        and moved as odometry turned and moved since the last scan that fitted, within
        ``doubt.gate_sigmas`` of its learnt per-scan noise times the scans since (heading at
        least ``doubt.min_gate_rad``, position at least ``doubt.min_gate_m``), unless
        odometry reported standing still at one of the scans since (:meth:`_odometry_still`;
        a robot carried off: its wheels saw nothing of it, so any place and heading).

        A building of look-alike halves (corridors round a symmetric core) scores as well 180
        deg off; a row of look-alike offices scores as well one door further on (a simulated
        office floor at 1 Hz was placed 4 m along its corridor, three poor scans after
        leaving a room). Tracking that lost its place while odometry kept running had
        odometry moving and turning all along."""
        if self._fit is None or self._froze:
            return True
        fit_pose, fit_odom = self._fit
        moved = between(fit_odom, self._odom)
        expected = compose(fit_pose, moved)
        var = self.tracker.odometry_variance()
        doubt = self.cfg.tracking.doubt
        k = doubt.gate_sigmas
        scans = max(self._since_fit, 1)
        sigma_m = math.sqrt(scans * var[0]) if var is not None else 0.0
        sigma_rad = math.sqrt(scans * var[1]) if var is not None else 0.0
        gate_m = max(doubt.min_gate_m, k * sigma_m)
        gate_rad = max(doubt.min_gate_rad, k * sigma_rad)
        off = pose[:2] - expected[:2]
        return bool(
            math.hypot(off[0], off[1]) <= gate_m
            and abs(wrap_scalar(pose[2] - expected[2])) <= gate_rad
        )

    def relocation_closure(self, node: int, submap: int) -> list[LoopClosure]:
        """The edge that ties a keyframe found by :meth:`relocalise` to the submap it was
        found in (its only tie to the graph besides its new submap): the loop detector's
        match there, unverified (the relocalisation's strict score stands for that)."""
        kf, s = self.keyframes[node], self.tracker.submaps[submap]
        g_s = self.graph.poses[self.submap_var[submap]]
        guess = compose(g_s, between(s.origin, kf.local))  # where the match put it
        # the local frame continues from the found pose: map it to where that submap is
        self._global_from_local = compose(guess, inverse(kf.local))
        self.graph.poses[self.node_var[node]] = guess
        for new in self.tracker.active:
            self.graph.poses[self.submap_var[new.index]] = compose(
                self._global_from_local, new.origin
            )
        assert kf.points is not None
        c = self.loops.match(node, kf.points, kf.ang_step, guess, kf.local, s, g_s)
        return [] if c is None else [c]

    def add_loop_closure(self, c: LoopClosure) -> None:
        """Submap -> node edge with the match as measurement (switchable in optimisation)."""
        self._loop_edge_ids.append(self.graph.n_edges)
        self.graph.add_edge(
            self.submap_var[c.submap], self.node_var[c.node], c.measurement, c.information
        )
        self.loop_edges.append(c)
        nodes = self.tracker.submaps[c.submap].nodes
        self._ties.append((c.node, min(nodes), max(nodes)))
        self._places.tie(c.node, min(nodes))
        self._places.tie(c.node, max(nodes))
        self._unoptimised += 1
        self._moving_closure |= not self.loops.agrees(between(c.estimate, c.matched))

    def _held_ties(self) -> NDArray[np.int64]:
        """(M, 2) keyframe pairs held together by the loop closures the last optimisation kept
        (switch at least a half) and those added since."""
        ties = np.asarray(self._ties, dtype=np.int64).reshape(-1, 3)
        held = np.ones(len(ties), dtype=bool)
        held[: len(self.switches)] = self.switches >= 0.5
        ties = ties[held]
        return np.concatenate([ties[:, [0, 1]], ties[:, [0, 2]]])

    def loop_closed(self) -> bool:
        """Optimise after a closure that moves the graph, or every ``optimize_every`` keyframes
        while small closures come in."""
        if not self._unoptimised:
            return False
        due = len(self.keyframes) - self._last_optimised_node >= self.cfg.optimize_every
        return self._moving_closure or due

    def switchable_edges(self) -> NDArray[np.bool_]:
        """(E,) True for the graph's loop-closure edges (all False if they are not switchable)."""
        mask = np.zeros(self.graph.n_edges, dtype=bool)
        if self.cfg.switchable_loops:
            mask[np.asarray(self._loop_edge_ids, dtype=np.int64)] = True
        return mask

    def switch_stages(self, mask: NDArray[np.bool_]) -> list[float]:
        """Switch scales (std) for the closures added since the last optimisation, in turn:
        from one that keeps each of them whole at the current poses down to ``switch_scale``,
        divided by ``switch_stage_factor`` in chi2 per stage (graduated non-convexity,
        :func:`~.posegraph_graduated.graduated_scales`). Closures already optimised had their
        switch decided at a consistent graph: their prior is not relaxed again (a switched-off
        false closure would pull again in every optimisation, and its chi2 would set the
        stages of all later ones)."""
        new = self._new_closures(mask)
        worst = float(edge_chi2(self.graph)[new].max()) if new.any() else 0.0
        return graduated_scales(worst, self.cfg.switch_scale, self.cfg.switch_stage_factor)

    def _new_closures(self, mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """(E,) True for the switchable loop-closure edges added since the last optimisation."""
        new = np.zeros_like(mask)
        ids = np.asarray(self._loop_edge_ids[self._loops_optimised :], dtype=np.int64)
        new[ids] = mask[ids]
        return new

    def optimise(self, max_iterations: int = 20) -> None:
        """Sparse Levenberg-Marquardt over all keyframes and submaps (first keyframe fixed),
        loop closures switchable, the new ones with a graduated prior (:meth:`switch_stages`)."""
        mask = self.switchable_edges()
        new = self._new_closures(mask)
        stages = self.switch_stages(mask)
        for k, scale in enumerate(stages):
            final = k == len(stages) - 1
            scales = np.full(self.graph.n_edges, self.cfg.switch_scale)
            scales[new] = scale
            result = optimize(
                self.graph,
                robust="huber",
                robust_scale=self.cfg.huber_scale,
                max_iterations=max_iterations if final else min(max_iterations, 10),
                tolerance=1e-6 if final else 1e-4,
                switchable=mask,
                switch_scale=scales,
            )
            self.graph.poses = result.poses
        self.switches = result.switches[mask]
        # a closure switched off holds nothing together (and one switched on again does)
        self._places.reset(self._held_ties(), len(self.keyframes))
        last = len(self.keyframes) - 1
        g_last = self.graph.poses[self.node_var[last]]
        self._global_from_local = compose(g_last, inverse(self.keyframes[last].local))
        self._unoptimised = 0
        self._moving_closure = False
        self._loops_optimised = len(self._loop_edge_ids)
        self._last_optimised_node = len(self.keyframes)
        self.loops.clear_pending()
        self.n_optimisations += 1
        release_free_heap()  # the solver's temporaries grow with the graph (see .memory)

    # ------------------------------------------------------------------ results
    def finish(self) -> None:
        """Final optimisation (call once at the end of a log)."""
        if self.keyframes:
            self.optimise(max_iterations=50)

    def trajectory(self) -> tuple[F64, F64]:
        """``(timestamps (M,), poses (M, 3))``: every scan's global robot pose,
        ``g_k = G_kf * (l_kf^-1 * l_k)``."""
        if not self.scan_times:
            return np.zeros(0), np.zeros((0, 3))
        local = np.asarray(self.scan_local)
        kfi = np.asarray(self.scan_keyframe)
        kf_local = np.asarray([k.local for k in self.keyframes])[kfi]
        kf_global = self.graph.poses[np.asarray(self.node_var)][kfi]
        return np.asarray(self.scan_times), compose(kf_global, between(kf_local, local))

    def keyframe_poses(self) -> F64:
        """Global poses (K, 3) of the keyframes."""
        return self.graph.poses[np.asarray(self.node_var)].copy()

    def occupancy_map(self, resolution_m: float | None = None) -> OccupancyMap:
        """Log-odds map rendered from the optimised keyframe poses."""
        res = resolution_m or self.cfg.tracking.resolution_m
        poses = self.keyframe_poses()
        sensors = compose(poses, self.laser_offset)
        ends = [compose(p, _xy0(k.ends))[:, :2] for p, k in zip(poses, self.keyframes, strict=True)]
        return render_occupancy(sensors, ends, [k.hits for k in self.keyframes], res)

    @property
    def submaps(self) -> list[Submap]:
        return self.tracker.submaps


def _reference_range(points: F64) -> float:
    """The range (m) that sets a scan's angular search steps: the 98th percentile of its
    points' ranges, at least 3 m."""
    r = np.hypot(points[:, 0], points[:, 1])
    k = int(0.98 * (len(r) - 1))
    return max(float(np.partition(r, k)[k]), 3.0) if len(r) else 3.0


def _xy0(xy: NDArray[np.floating]) -> F64:
    """Points (n, 2) as poses (n, 3) with theta 0, for :func:`compose`."""
    return np.column_stack([xy, np.zeros(len(xy))]).astype(np.float64)
