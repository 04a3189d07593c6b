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
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import NDArray

from agvsim.slam import scan_matching as sm
from agvsim.slam.fusion import OdometryFusion
from agvsim.slam.mapping import (
    coarse_field,
    gaussian_kernel,
    likelihood_field,
    stamp_points,
    update_log_odds,
)
from agvsim.slam.odometry_check import DoubtConfig, OdometryCheck
from agvsim.slam.se2 import between, compose

__all__ = ["MotionFilter", "OdometryFusion", "Submap", "Tracker", "TrackingConfig"]

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]


@dataclass(frozen=True)
class TrackingConfig:
    """Knobs of local SLAM (metres, radians)."""

    resolution_m: float = 0.05  # 20 cells/m, the thesis's map resolution
    sigma_m: float = 0.05  # width of the likelihood field exp(-d^2 / 2 sigma^2)
    window_m: float = 0.15  # correlative search window around the odometry prediction, +-
    window_rad: float = math.radians(6.0)
    # motion prior of the narrow search when odometry is not fused (fuse_odometry False):
    # score - w_t |dt|^2 - w_th dth^2 (1/m^2, 1/rad^2); a fused odometry enters only in the
    # fusion, weighed by its learnt noise (Tracker.match)
    prior_lin_weight: float = 2.0
    prior_ang_weight: float = 2.0
    retry_score: float = 0.6  # below it, search again in the wide window
    wide_window_m: float = 0.4
    wide_window_rad: float = math.radians(40.0)
    gn_iterations: int = 10
    gn_prior_weight: float = 1e-4
    fuse_odometry: bool = True  # weigh each match against odometry by their noise (online)
    fusion_window: int = 300  # scans the noise estimates look back over
    fusion_lag: int = 10  # scans between the two increments that separate the noises
    submap_keyframes: int = 40  # keyframes per submap
    # ... or this much path between its keyframes, whichever comes first: 40 keyframes at the
    # motion filter's 0.2 m. Between sparse scans every scan is a keyframe, 0.5 m or more
    # apart, and 40 of them made submaps 20 m long that held a corner's heading error inside
    # them, where no loop closure can mend it (a simulated hospital at 1.4 Hz: 4 deg at its
    # first corner; issue 19's fourteenth round)
    submap_length_m: float = 8.0
    submap_half_size_m: float = 45.0  # live submap grid: +- this around its origin
    surface_gap_m: float = 0.5  # neighbouring returns closer than this are joined in the field
    # long corridors beyond the scanner's reach (docs/slam.md, issue 19's eleventh and twelfth
    # rounds): a return whose neighbours both lie farther than surface_gap_m on a line through
    # it (a wall seen far off or edge-on) is stamped along that line, edge_on_reach_m each
    # way, not as a bump (spread_edge_on; the segments to the neighbours turn by at most
    # this), and one seen through an opening, behind the returns on either side and
    # glimpse_depth_m or more behind the nearer, is not stamped (glimpses). None: every
    # return is a bump, as on the published logs' figures (SlamConfig.point_samples); those
    # bumps held tracking on its last keyframe along a simulated hospital's corridors
    # wherever odometry's scale was 2 % or more off
    edge_on_turn_rad: float | None = math.radians(15.0)
    # ... but only while the scans come densely: the median distance tracked between the last
    # steps_kept moving scans at most this (None: window_m). A keyframe's bumps can hold only
    # the scans matched within the narrow window around them; on a robot that moves farther
    # between scans they cannot, and point samples placed the simulated hospital's scans at
    # 1-2.5 Hz (0.2-0.5 m a scan) up to three times better, with and without wheel-scale
    # errors (issue 19's thirteenth round)
    edge_on_max_step_m: float | None = None
    steps_kept: int = 20
    # longer than the robot moves between keyframes and between scans: a spread's end holds
    # a scan as a bump did (0.3 m shrank the hospital by 1.3 % at 1.5 Hz, 0.4 m a scan);
    # longer, a keyframe's heading error reaches farther along the far walls
    edge_on_reach_m: float = 0.5
    # while the scans come densely (as edge-on samples are spread), a surface whose end a
    # nearer return hides is continued this far past it in the live field, along the line
    # fitted to its last occluded_fit_m, unless it ends in a concave corner against the
    # surface that hides it (:func:`extend_occluded`; None: not), and with last_sample_spread
    # (off by default) the farthest edge-on sample of a wall whose continuation lies beyond
    # the range is spread both ways (:func:`spread_last_sample`; False: left a bump). Both
    # ends are where a surface went out of sight, not where it ends: stamped, they pull the
    # next scans' new returns back onto them (a corner bringing a slanted wing into view
    # turned the tracked heading by a degree). The default since the nineteenth round
    # (docs/slam.md, "Surfaces that go out of sight"): over the robustness table, the
    # geometric mean of each log's ten rows against None: the slanted wings 0.73
    # (unperturbed 0.110 -> 0.049 m), the office floor 0.85, the simulated hospital 0.96,
    # ACES 1.00, the warehouse 1.00, Intel 1.02, the thesis maze 1.04; the farthest samples
    # spread as well slipped the thesis maze's online run on seed 2 (0.022 -> 0.054 m)
    occluded_reach_m: float | None = 0.5
    occluded_fit_m: float = 0.3
    # ... and it stops where the live submap's log-odds saw the point and its eight
    # neighbours free, below this (two misses net with l_miss -0.4; None: not checked)
    occluded_free_logodds: float | None = -0.8
    # ... and only a surface seen straight over at least this from its end (0: any run of
    # occluded_fit_m): twice the reach, so that nothing is continued farther than half what
    # was seen of it. A door jamb's face (a wall's thickness) was continued past the wall
    # into the room: on a simulated office floor 15 % of the continued points lay more than
    # 0.1 m off every wall, 3.6 % with this
    occluded_seen_m: float = 1.0
    last_sample_spread: bool = False
    # a back wall through a door lies metres behind a jamb; a return between two nearer ones
    # less than this behind both is clutter that places the scan: left out with the rest,
    # ACES lost a tenth of its accuracy
    glimpse_depth_m: float = 1.0
    # scan points that land where the matched submap was never observed are left out of the
    # match while the robot moves where its scanner does not look (``Tracker.view``: a front
    # scanner driven backwards or sideways) and at least this share of the scan lands where
    # it was (:func:`~.scan_matching.observed_before`, ``window_m`` short of each point; fewer: the
    # robot enters unmapped space and every point is matched). The submap ends where its
    # scans saw, and on the blind side walls come into view right beside the scanner: a
    # point just past that edge fits only with the scan moved back onto the last returns,
    # and each match fell short (a simulated hospital driven there and back six times at
    # 1.4 Hz: 2.5 % a backward pass, the map 2 % small; issue 19's fifteenth round). Driving
    # forwards new walls come into view far off; left out there as well, the measured gains
    # and losses did not make a default (docs/slam.md). None: every point is matched
    observed_share: float | None = 0.5
    # each return is mapped as the mean of itself and its smooth_beams neighbours each side
    # when they lie on one surface with it: joined (neighbours within surface_gap_m) and
    # within smooth_dev_m of the chord between the outermost two (a corner sharper than that
    # is mapped as seen; :func:`smooth_surface`). On a straight wall the mean lies on the
    # wall and its range noise is 1/sqrt(3) of one return's: the field stamps the maximum
    # over every scan, so each scan's noise widened the ridge (issue 19's twenty-second
    # round: 3 cm more range noise doubled the thesis maze's error). Only the map is
    # smoothed; scans are matched as measured. 0: every return mapped as measured
    smooth_beams: int = 1
    smooth_dev_m: float = 0.1
    l_hit: float = 0.85
    l_miss: float = -0.4
    l_clamp: float = 4.0
    doubt: DoubtConfig = field(default_factory=DoubtConfig)  # odometry checked by matching
    # floors of odometry's per-scan noise from a wheel odometry's physics (std): translation
    # per metre driven (wheel radius, slip), heading per radian turned (track width) and per
    # metre driven (wheel radius difference); the learnt noise never falls below them
    odom_floor_m_per_m: float = 0.01
    odom_floor_rad_per_rad: float = 0.01
    odom_floor_rad_per_m: float = math.radians(0.25)
    # ceilings of a match's learnt noise (std): a scan that fits is not off by more; a larger
    # learnt spread is odometry's error that does not build up (.fusion.OdometryFusion)
    match_ceiling_m: float = 0.05
    match_ceiling_rad: float = math.radians(1.0)
    # odometry's heading error per radian turned (learnt, .fusion) weighs the fusion too: in a
    # turn the match's heading counts for more (the heading window grows with it regardless,
    # doubt.turn_windows)
    turn_fusion: bool = True
    lost_score: float = 0.35  # below it after the wide search: lost (relocalise_scans, lost_scans)
    lost_scans: int = 3
    # a lost scan (lost_scans poor ones in a row) that still fits under lost_score at a pose
    # outside the narrow window is *unmatched*: a wide window's least bad fit says nothing of
    # its pose, so it keeps the prediction and is not mapped (GraphSlam) while the poor scans
    # in a row number at most this; past it the robot is taken to drive through unmapped
    # space and is mapped at the prediction. 0: such a scan keeps its search result
    unmatched_hold_scans: int = 9
    # a scan under lost_score even after the wide search is looked for over
    # +-relocalise_window_m and every heading in the submap from this many such scans in a row
    # (1: at once; between sparse scans the robot moves and turns far)
    relocalise_scans: int = 1
    relocalise_window_m: float = 2.0  # relocalisation search: +- this, all headings
    global_min_score: float = 0.7  # global relocalisation (all submaps) accepted from this score
    global_points: int = 48  # scan points the global search places (then all are refined)
    # a finished submap keeps its field max-pooled over this many cells a side for the global
    # search (20 cm cells; .relocalise), built once; 0: no global search over it
    global_cell_factor: int = 4

    def __post_init__(self) -> None:
        """A clear error for a value no tracking could run with (NaN fails every test)."""

        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(
                f"TrackingConfig.{name} must be {allowed}, got {getattr(self, name)!r}"
            )

        if isinstance(self.smooth_beams, bool) or not isinstance(self.smooth_beams, int):
            raise bad("smooth_beams", "a whole number of beams (0: not smoothed)")
        for name in _POSITIVE:
            if not getattr(self, name) > 0:
                raise bad(name, "positive")
        for name in _NON_NEGATIVE:
            if not getattr(self, name) >= 0:
                raise bad(name, ">= 0")
        for name in ("retry_score", "lost_score", "global_min_score"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise bad(name, "a mean likelihood in [0, 1]")
        if self.lost_score > self.retry_score:
            raise ValueError(
                f"TrackingConfig.lost_score ({self.lost_score}) must not exceed retry_score "
                f"({self.retry_score}): a lost scan is a poor one"
            )
        if self.observed_share is not None and not 0.0 < self.observed_share <= 1.0:
            raise bad("observed_share", "in (0, 1] or None")
        if self.edge_on_turn_rad is not None and not 0.0 < self.edge_on_turn_rad <= math.pi / 2:
            raise bad("edge_on_turn_rad", "in (0, pi/2] or None")
        if self.occluded_reach_m is not None and not self.occluded_reach_m > 0:
            raise bad("occluded_reach_m", "positive or None")
        if not self.occluded_seen_m >= 0:
            raise bad("occluded_seen_m", ">= 0")
        if self.occluded_free_logodds is not None and not self.occluded_free_logodds < 0:
            raise bad("occluded_free_logodds", "negative (seen free) or None")
        if self.edge_on_max_step_m is not None and not self.edge_on_max_step_m > 0:
            raise bad("edge_on_max_step_m", "positive or None")
        if not self.l_miss < 0.0:
            raise bad("l_miss", "negative (a ray through a cell: free)")


# TrackingConfig's fields that must be above 0, and those that may be 0 as well
_POSITIVE = (
    "resolution_m",
    "sigma_m",
    "window_m",
    "window_rad",
    "wide_window_m",
    "wide_window_rad",
    "gn_iterations",
    "fusion_window",
    "fusion_lag",
    "submap_keyframes",
    "submap_length_m",
    "submap_half_size_m",
    "surface_gap_m",
    "steps_kept",
    "edge_on_reach_m",
    "occluded_fit_m",
    "glimpse_depth_m",
    "l_hit",
    "l_clamp",
    "lost_scans",
    "relocalise_scans",
    "relocalise_window_m",
    "global_points",
    "smooth_dev_m",
)
_NON_NEGATIVE = (
    "prior_lin_weight",
    "prior_ang_weight",
    "gn_prior_weight",
    "odom_floor_m_per_m",
    "odom_floor_rad_per_rad",
    "odom_floor_rad_per_m",
    "match_ceiling_m",
    "match_ceiling_rad",
    "unmatched_hold_scans",
    "global_cell_factor",
    "smooth_beams",
)


@njit(cache=True)
def smooth_surface(
    ends: np.ndarray, hits: np.ndarray, max_gap_m: float, half: int, max_dev_m: float
) -> np.ndarray:
    """A copy of ``ends`` (in beam order) with each hit ``k`` replaced by the mean of the hits
    ``k - w .. k + w``, for the largest ``w <= half`` whose run is one surface: every
    neighbouring pair closer than ``max_gap_m`` and every point within ``max_dev_m`` of the
    chord from ``k - w`` to ``k + w``. A hit with no such run (an end, an isolated return, a
    sharp corner) and every non-hit stay as they are. Collinear hits stay on their line."""
    n = ends.shape[0]
    out = ends.copy()
    for k in range(n):
        if not hits[k]:
            continue
        for w in range(half, 0, -1):
            if k - w < 0 or k + w >= n:
                continue
            ok = True
            for j in range(k - w, k + w):
                if not (hits[j] and hits[j + 1]):
                    ok = False
                    break
                gap = math.hypot(ends[j + 1, 0] - ends[j, 0], ends[j + 1, 1] - ends[j, 1])
                if gap > max_gap_m:
                    ok = False
                    break
            if not ok:
                continue
            ax, ay = ends[k - w, 0], ends[k - w, 1]
            dx, dy = ends[k + w, 0] - ax, ends[k + w, 1] - ay
            chord = math.hypot(dx, dy)
            if chord <= 0.0:
                continue
            for j in range(k - w + 1, k + w):
                if abs((ends[j, 0] - ax) * dy - (ends[j, 1] - ay) * dx) / chord > max_dev_m:
                    ok = False
                    break
            if not ok:
                continue
            sx, sy = 0.0, 0.0
            for j in range(k - w, k + w + 1):
                sx += ends[j, 0]
                sy += ends[j, 1]
            out[k, 0], out[k, 1] = sx / (2 * w + 1), sy / (2 * w + 1)
            break
    return out


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


@njit(cache=True)
def spread_edge_on(
    ends: np.ndarray,
    hits: np.ndarray,
    max_gap_m: float,
    step_m: float,
    max_turn_rad: float,
    reach_m: float,
) -> np.ndarray:
    """Points every ``step_m`` on the wall through each *edge-on* sample: a hit whose beam
    neighbours both returned farther than ``max_gap_m`` from it on a line through it (the
    segments to them turn by at most ``max_turn_rad``), as on a wall seen far off or at a
    grazing angle. The points run from the sample towards each neighbour, half way and at
    most ``reach_m``.

    Such a sample says where the wall is across itself, not where along it: that is where the
    beam happened to fall, and it moves with the robot. Stamped as a bump, the samples of one
    keyframe were where the next scans' samples, on the same beams, fitted best with the robot
    not moved: along a corridor whose ends were out of range tracking was held on the keyframe
    before (issue 19, a simulated hospital). Spread along the wall they still place the scan
    across the wall and in heading, and no longer along it. (Leaving them out of matching
    instead cost the thesis maze's runs a third to three fifths of their accuracy; both cost
    ACES some of its: off by default, docs/slam.md.)"""
    n = ends.shape[0]
    cos_max = math.cos(max_turn_rad)
    count = 0
    for k in range(1, n - 1):
        if hits[k - 1] and hits[k] and hits[k + 1]:
            ga = math.hypot(ends[k, 0] - ends[k - 1, 0], ends[k, 1] - ends[k - 1, 1])
            gb = math.hypot(ends[k + 1, 0] - ends[k, 0], ends[k + 1, 1] - ends[k, 1])
            if ga > max_gap_m and gb > max_gap_m:
                count += 2 * int(reach_m / step_m) + 2
    out = np.empty((count, 2))
    j = 0
    for k in range(1, n - 1):
        if not (hits[k - 1] and hits[k] and hits[k + 1]):
            continue
        ax, ay = ends[k, 0] - ends[k - 1, 0], ends[k, 1] - ends[k - 1, 1]
        bx, by = ends[k + 1, 0] - ends[k, 0], ends[k + 1, 1] - ends[k, 1]
        ga, gb = math.hypot(ax, ay), math.hypot(bx, by)
        if ga <= max_gap_m or gb <= max_gap_m or (ax * bx + ay * by) < cos_max * ga * gb:
            continue
        for dx, dy, g in ((-ax, -ay, ga), (bx, by, gb)):
            reach = min(0.5 * g, reach_m)
            m = int(reach / step_m)
            for i in range(1, m + 1):
                f = i * step_m / g
                out[j, 0], out[j, 1] = ends[k, 0] + f * dx, ends[k, 1] + f * dy
                j += 1
    return out[:j]


@njit(cache=True)
def _bearing_step(ends: np.ndarray, origin: np.ndarray) -> float:
    """The median bearing step (rad) between consecutive scan ``ends`` seen from ``origin``:
    the beam spacing, where beams that returned nothing were dropped from the scan."""
    n = ends.shape[0]
    if n < 3:
        return 0.0
    d = np.empty(n - 1)
    for k in range(n - 1):
        a0 = math.atan2(ends[k, 1] - origin[1], ends[k, 0] - origin[0])
        a1 = math.atan2(ends[k + 1, 1] - origin[1], ends[k + 1, 0] - origin[0])
        d[k] = abs((a1 - a0 + math.pi) % (2.0 * math.pi) - math.pi)
    return float(np.median(d))


@njit(cache=True)
def _next_beam(
    ends: np.ndarray,
    hits: np.ndarray,
    origin: np.ndarray,
    k: int,
    o: int,
    beam_step: float,
    max_range_m: float,
) -> tuple[bool, float, float, float]:
    """The beam next to ``ends[k]`` on the side of entry ``o`` when it returned nothing:
    (True, its unit direction, the range it looked to) for a miss entry (clipped at the range)
    or for beams dropped between ``k`` and ``o`` (their bearings more than 1.5 beam steps
    apart); (False, ...) when ``o`` is a return on the next beam or lies outside the scan."""
    n = ends.shape[0]
    if o < 0 or o >= n:
        return False, 0.0, 0.0, 0.0
    if not hits[o]:
        vx, vy = ends[o, 0] - origin[0], ends[o, 1] - origin[1]
        r = math.hypot(vx, vy)
        if r <= 0.0:
            return False, 0.0, 0.0, 0.0
        return True, vx / r, vy / r, r
    a_k = math.atan2(ends[k, 1] - origin[1], ends[k, 0] - origin[0])
    a_o = math.atan2(ends[o, 1] - origin[1], ends[o, 0] - origin[0])
    d = (a_o - a_k + math.pi) % (2.0 * math.pi) - math.pi
    if beam_step <= 0.0 or abs(d) <= 1.5 * beam_step:
        return False, 0.0, 0.0, 0.0
    a = a_k + (beam_step if d > 0 else -beam_step)
    return True, math.cos(a), math.sin(a), max_range_m


@njit(cache=True)
def _continued_out_of_range(
    origin: np.ndarray,
    ex: float,
    ey: float,
    ux: float,
    uy: float,
    vx: float,
    vy: float,
    range_m: float,
) -> bool:
    """Whether the surface through ``(ex, ey)`` continued along ``(ux, uy)`` would have met
    the beam ``(vx, vy)`` from ``origin`` only beyond ``range_m`` (or not at all): then that
    beam's silence says nothing against it."""
    den = vx * uy - vy * ux
    if abs(den) < 1e-12:
        return True
    wx, wy = ex - origin[0], ey - origin[1]
    t = (wx * uy - wy * ux) / den  # along the beam
    s = (wx * vy - wy * vx) / den  # along the continuation
    return s <= 0.0 or t <= 0.0 or t > range_m


@njit(cache=True)
def spread_last_sample(
    ends: np.ndarray,
    hits: np.ndarray,
    origin: np.ndarray,
    max_gap_m: float,
    step_m: float,
    reach_m: float,
    max_range_m: float,
) -> np.ndarray:
    """Points every ``step_m`` on the wall through each *last* edge-on sample: a hit whose
    neighbour on one side returned farther than ``max_gap_m`` from it (the wall's next
    sample) and whose beam on the other side returned nothing, where the wall continued
    would lie beyond ``max_range_m`` for that beam (:func:`_next_beam`). The points run
    towards the neighbour, half way and at most ``reach_m``, and ``reach_m`` on past the
    sample.

    The farthest sample of a wall seen edge-on along a corridor has no neighbour beyond it,
    so :func:`spread_edge_on` leaves it a bump, and the next scans' farthest samples, a step
    farther on, were pulled back onto it."""
    n = ends.shape[0]
    m = int(reach_m / step_m)
    out = np.empty((2 * m * n, 2))
    beam_step = _bearing_step(ends, origin)
    j = 0
    for k in range(n):
        if not hits[k]:
            continue
        for side in range(2):
            nb = k + 1 if side == 0 else k - 1  # the wall's next sample
            o = k - 1 if side == 0 else k + 1  # the silent side
            if nb < 0 or nb >= n or not hits[nb]:
                continue
            gx, gy = ends[k, 0] - ends[nb, 0], ends[k, 1] - ends[nb, 1]
            g = math.hypot(gx, gy)
            if g <= max_gap_m:
                continue
            silent, vx, vy, r = _next_beam(ends, hits, origin, k, o, beam_step, max_range_m)
            ux, uy = gx / g, gy / g
            if not silent or not _continued_out_of_range(
                origin, ends[k, 0], ends[k, 1], ux, uy, vx, vy, r
            ):
                continue
            toward = int(min(0.5 * g, reach_m) / step_m)
            for i in range(1, toward + 1):
                out[j, 0], out[j, 1] = ends[k, 0] - i * step_m * ux, ends[k, 1] - i * step_m * uy
                j += 1
            for i in range(1, m + 1):
                out[j, 0], out[j, 1] = ends[k, 0] + i * step_m * ux, ends[k, 1] + i * step_m * uy
                j += 1
    return out[:j]


@njit(cache=True)
def _seen_free(
    logodds: np.ndarray, ox: float, oy: float, res: float, x: float, y: float, free_lo: float
) -> bool:
    """Whether the log-odds grid saw ``(x, y)`` free: the cell under it and its eight
    neighbours all below ``free_lo``. A wall's own line passes through cells that rays
    grazing it crossed; no wall lies within a cell of a point whose neighbours were all seen
    free (a cell outside the grid was not seen)."""
    ix, iy = int(math.floor((x - ox) / res)), int(math.floor((y - oy) / res))
    if iy < 1 or iy >= logodds.shape[0] - 1 or ix < 1 or ix >= logodds.shape[1] - 1:
        return False
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            if not logodds[iy + dy, ix + dx] < free_lo:
                return False
    return True


@njit(cache=True)
def _fit_line(ends: np.ndarray, a: int, b: int) -> tuple[float, float, float, float, float]:
    """Total least squares line through ``ends[a..b]`` (inclusive, either order): its centre,
    unit direction (pointing from ``a`` towards ``b``) and the rms distance of the points."""
    lo, hi = min(a, b), max(a, b)
    cnt = hi - lo + 1
    mx, my = 0.0, 0.0
    for i in range(lo, hi + 1):
        mx += ends[i, 0]
        my += ends[i, 1]
    mx, my = mx / cnt, my / cnt
    sxx, syy, sxy = 0.0, 0.0, 0.0
    for i in range(lo, hi + 1):
        dx, dy = ends[i, 0] - mx, ends[i, 1] - my
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
    ang = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
    ux, uy = math.cos(ang), math.sin(ang)
    if (ends[b, 0] - ends[a, 0]) * ux + (ends[b, 1] - ends[a, 1]) * uy < 0.0:
        ux, uy = -ux, -uy
    ss = 0.0
    for i in range(lo, hi + 1):
        d = (ends[i, 0] - mx) * uy - (ends[i, 1] - my) * ux
        ss += d * d
    return mx, my, ux, uy, math.sqrt(ss / cnt)


@njit(cache=True)
def _meets_hider(
    ends: np.ndarray,
    hits: np.ndarray,
    origin: np.ndarray,
    end: int,
    nb: int,
    inner: int,
    res: float,
) -> bool:
    """Whether the surface ending at ``ends[end]`` runs into the one that hides the rest of
    it: the end lies on the line through the hiding return ``ends[nb]`` and the return past
    it (the beam after ``nb``, away from ``end``), within the end's sample spacing (to its
    run neighbour ``ends[inner]``) and a cell, and that line, followed on, would have met the
    end's own beam (from ``origin``) no nearer than the end. That is a concave corner, seen
    with the second wall edge-on: the first wall ends there, and continued it would run into
    the second. A hiding wall that stops short of the end's beam (its own end is what hides,
    a corner seen from outside) does not count."""
    n = ends.shape[0]
    nb2 = nb + (nb - end)
    if nb2 < 0 or nb2 >= n or not hits[nb2] or inner < 0 or inner >= n:
        return False
    lx, ly = ends[nb2, 0] - ends[nb, 0], ends[nb2, 1] - ends[nb, 1]
    ll = math.hypot(lx, ly)
    if ll <= 0.0:
        return False
    ex, ey = ends[end, 0] - ends[nb, 0], ends[end, 1] - ends[nb, 1]
    off = abs(ex * ly - ey * lx) / ll
    spacing = math.hypot(ends[end, 0] - ends[inner, 0], ends[end, 1] - ends[inner, 1])
    if off > spacing + res:
        return False
    # the end's beam: origin + t v; the hiding line: nb + s l
    vx, vy = ends[end, 0] - origin[0], ends[end, 1] - origin[1]
    r_end = math.hypot(vx, vy)
    den = vx * ly - vy * lx
    if abs(den) < 1e-12 or r_end <= 0.0:
        return True  # along the beam: nothing says the hiding wall stops short
    wx, wy = ends[nb, 0] - origin[0], ends[nb, 1] - origin[1]
    t = (wx * ly - wy * lx) / den  # in units of the end's range
    return t * r_end >= r_end - res


@njit(cache=True)
def _seen_straight(
    ends: np.ndarray,
    first: int,
    last: int,
    end: int,
    step: int,
    cx: float,
    cy: float,
    ux: float,
    uy: float,
    tol_m: float,
    seen_m: float,
) -> bool:
    """Whether the run ``first .. last`` stays on the line ``(cx, cy) + s (ux, uy)`` within
    ``tol_m`` from ``ends[end]`` back (``step`` into the run) over at least ``seen_m``."""
    k = end
    while first <= k <= last:
        ex, ey = ends[k, 0] - cx, ends[k, 1] - cy
        if abs(ex * uy - ey * ux) > tol_m:
            return False
        dx, dy = ends[end, 0] - ends[k, 0], ends[end, 1] - ends[k, 1]
        if dx * ux + dy * uy >= seen_m:
            return True
        k += step
    return False


@njit(cache=True)
def extend_occluded(
    ends: np.ndarray,
    hits: np.ndarray,
    origin: np.ndarray,
    max_gap_m: float,
    step_m: float,
    reach_m: float,
    fit_m: float,
    straight_m: float,
    logodds: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    free_lo: float,
    corner_check: bool = True,
    seen_m: float = 0.0,
) -> np.ndarray:
    """Points every ``step_m``, for ``reach_m``, continuing each surface past an end that a
    nearer return hides: a run of returns joined as :func:`densify_surface` joins them, whose
    beam neighbour past the run's end returned nearer to ``origin`` (the sensor) and farther
    than ``max_gap_m`` from it, unless the two surfaces meet there (:func:`_meets_hider`, a
    concave corner; ``corner_check``). The direction is the line fitted (total least squares)
    to the run's last ``fit_m``, its rms distance at most ``straight_m``; a shorter run, or
    clutter, is not continued, nor one not seen on that line (within twice ``straight_m``)
    over ``seen_m`` from its end (:func:`_seen_straight`; 0: any). The continuation starts at
    the end's foot on that line and stops where it would pass in front of the hiding return
    (the scanner would have seen it there) and where the log-odds grid (``logodds``, corner
    ``ox, oy``, cells ``res``) saw it free, below ``free_lo`` (:func:`_seen_free`): the
    surface does not run on across space the scanner saw through before.

    Such an end is where the surface went out of sight, not where it ends: a wall of the next
    wing seen past a corner, a wall behind a pillar. The next scans, a little farther on, see
    more of it; their new points land just past the end, where the stamped end pulls them
    back along the surface, and every keyframe laid down that way was short by the pull (the
    tracked heading turned by about a degree where a corner brought a slanted wing into view,
    docs/slam.md). An end where the beam past it goes farther (a door jamb, a corner seen
    from outside) is where the surface ends and is not continued."""
    n = ends.shape[0]
    m = int(reach_m / step_m)
    count = 0
    for k in range(n):
        if hits[k]:
            count += 2 * m
    out = np.empty((count, 2))
    j = 0
    k = 0
    while k < n:
        if not hits[k]:
            k += 1
            continue
        first = k  # a run of joined returns: first .. last
        while (
            k + 1 < n
            and hits[k + 1]
            and math.hypot(ends[k + 1, 0] - ends[k, 0], ends[k + 1, 1] - ends[k, 1]) <= max_gap_m
        ):
            k += 1
        last = k
        k += 1
        for side in range(2):
            end = first if side == 0 else last
            nb = end - 1 if side == 0 else end + 1
            if nb < 0 or nb >= n or not hits[nb]:
                continue
            r_end = math.hypot(ends[end, 0] - origin[0], ends[end, 1] - origin[1])
            r_nb = math.hypot(ends[nb, 0] - origin[0], ends[nb, 1] - origin[1])
            if r_nb >= r_end:
                continue  # the surface ends here: the beam past it goes on
            step = 1 if side == 0 else -1  # into the run
            if corner_check and _meets_hider(ends, hits, origin, end, nb, end + step, res):
                continue  # a concave corner: the surface ends against the one that hides it
            back, far = end, 0.0  # walk into the run until fit_m from its end
            while first <= back + step <= last and far < fit_m:
                back += step
                far = math.hypot(ends[end, 0] - ends[back, 0], ends[end, 1] - ends[back, 1])
            if far < fit_m:
                continue  # the run is too short
            cx, cy, ux, uy, rms = _fit_line(ends, back, end)
            if rms > straight_m:
                continue  # clutter
            if seen_m > 0.0 and not _seen_straight(
                ends, first, last, end, step, cx, cy, ux, uy, 2.0 * straight_m, seen_m
            ):
                continue  # seen too short to say it runs on
            t = (ends[end, 0] - cx) * ux + (ends[end, 1] - cy) * uy
            x0, y0 = cx + t * ux, cy + t * uy  # the end's foot on the line
            for i in range(1, m + 1):
                px, py = x0 + i * step_m * ux, y0 + i * step_m * uy
                if math.hypot(px - origin[0], py - origin[1]) <= r_nb:
                    break  # in front of the return that hides it
                if _seen_free(logodds, ox, oy, res, px, py, free_lo):
                    break  # seen through before
                out[j, 0], out[j, 1] = px, py
                j += 1
    return out[:j]


@njit(cache=True)
def glimpses(
    ends: np.ndarray, hits: np.ndarray, origin: np.ndarray, max_gap_m: float, depth_m: float
) -> np.ndarray:
    """(n,) True for the hits seen through an opening: both beam neighbours returned, nearer
    to ``origin`` (the sensor), one of them by ``depth_m`` or more, and farther than
    ``max_gap_m`` from it, as a back wall glimpsed through a door between its jambs (or
    beside one, its other neighbour a sample of the same wall, seen edge-on). Which way that
    wall runs, one sample cannot say, so it cannot be spread (:func:`spread_edge_on`);
    stamped as a bump it held tracking like an edge-on sample does. Clutter less than
    ``depth_m`` behind both neighbours (a lab's) places the scan and is kept."""
    n = ends.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for k in range(1, n - 1):
        if not (hits[k - 1] and hits[k] and hits[k + 1]):
            continue
        r = math.hypot(ends[k, 0] - origin[0], ends[k, 1] - origin[1])
        behind, depth = True, 0.0
        for j in (k - 1, k + 1):
            gap = math.hypot(ends[j, 0] - ends[k, 0], ends[j, 1] - ends[k, 1])
            rj = math.hypot(ends[j, 0] - origin[0], ends[j, 1] - origin[1])
            if gap <= max_gap_m or rj >= r:
                behind = False
            depth = max(depth, r - rj)
        out[k] = behind and depth >= depth_m
    return out


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
    path_m: float = 0.0  # the path between its keyframes (m)
    last_xy: F64 | None = None  # the newest keyframe's position (local frame)
    finished: bool = False
    # a finished submap keeps only its occupied cells (row, column; int16), a few kB: its
    # likelihood field is a pure function of them and is rebuilt when loop closing needs it
    # (:meth:`field`; the loop detector caches what it rebuilt). Memory then follows the
    # length of the walls mapped, not the log's duration or the sensor's range.
    occupied_cells: NDArray[np.int16] | None = None
    grid_shape: tuple[int, int] = (0, 0)
    field_sigma_m: float = 0.0
    field_resolution_m: float = 0.0
    # the field max-pooled over coarse_factor cells a side and dilated by one coarse cell
    # (uint8, rounded up; :func:`~.mapping.coarse_field`): the global relocalisation's bound
    coarse: NDArray[np.uint8] | None = None
    coarse_factor: int = 0

    def field(self) -> F32:
        """The likelihood field for matching (rebuilt from the occupied cells once finished)."""
        if self.occupied_cells is None:
            return self.likelihood
        occ = np.zeros(self.grid_shape, dtype=bool)
        occ[self.occupied_cells[:, 0], self.occupied_cells[:, 1]] = True
        return likelihood_field(occ, self.field_sigma_m, self.field_resolution_m)

    def insert(
        self,
        cfg: TrackingConfig,
        sensor_xy: F64,
        ends: F64,
        hits: NDArray[np.bool_],
        node: int,
        edge_on: bool = True,
        max_range_m: float = 0.0,
    ) -> None:
        """Ray-update the log-odds grid and stamp the hits into the live field (local frame),
        neighbouring ones joined (:func:`densify_surface`); with ``edge_on_turn_rad`` and
        ``edge_on``, edge-on ones spread along their wall (:func:`spread_edge_on`) and glimpses
        through an opening left out (:func:`glimpses`). ``ends`` are mapped as given
        (:meth:`Tracker.insert` smooths them first)."""
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
            stamp, spread = hits, None
            sensor = np.asarray(sensor_xy, np.float64).reshape(2)
            if cfg.edge_on_turn_rad is not None and edge_on:
                stamp = hits & ~glimpses(ends, hits, sensor, cfg.surface_gap_m, cfg.glimpse_depth_m)
                gap, turn, reach = cfg.surface_gap_m, cfg.edge_on_turn_rad, cfg.edge_on_reach_m
                spread = spread_edge_on(ends, hits, gap, 0.5 * res, turn, reach)
                if cfg.last_sample_spread and max_range_m > 0:
                    tail = spread_last_sample(
                        ends, hits, sensor, gap, 0.5 * res, reach, max_range_m
                    )
                    spread = np.concatenate((spread, tail))
            pts = densify_surface(ends, stamp, cfg.surface_gap_m, 0.5 * res)
            if spread is not None:
                pts = np.concatenate((pts, spread))
            if cfg.occluded_reach_m is not None and edge_on:
                hidden = extend_occluded(
                    ends,
                    hits,
                    sensor,
                    cfg.surface_gap_m,
                    0.5 * res,
                    cfg.occluded_reach_m,
                    cfg.occluded_fit_m,
                    0.5 * res,
                    self.logodds,
                    self.ox,
                    self.oy,
                    res,
                    -math.inf if cfg.occluded_free_logodds is None else cfg.occluded_free_logodds,
                    True,
                    cfg.occluded_seen_m,
                )
                pts = np.concatenate((pts, hidden))
        stamp_points(self.likelihood, self.ox, self.oy, res, pts, self.kernel)
        self.nodes.append(node)
        xy = np.array(sensor_xy[:2], dtype=np.float64)  # the sensor's path
        if self.last_xy is not None:
            self.path_m += math.hypot(xy[0] - self.last_xy[0], xy[1] - self.last_xy[1])
        self.last_xy = xy

    def finish(self, cfg: TrackingConfig) -> None:
        """Crop to the mapped cells and keep only the occupied ones (:meth:`field`)."""
        known = np.nonzero(self.logodds != 0)
        if known[0].size:
            pad = self.kernel.shape[0]
            y0, x0 = max(known[0].min() - pad, 0), max(known[1].min() - pad, 0)
            y1, x1 = known[0].max() + pad + 1, known[1].max() + pad + 1
            self.logodds = np.ascontiguousarray(self.logodds[y0:y1, x0:x1])
            self.ox += x0 * cfg.resolution_m
            self.oy += y0 * cfg.resolution_m
        occ = self.logodds > 0
        if max(occ.shape) > np.iinfo(np.int16).max:
            raise ValueError(f"submap {self.index}: {occ.shape} cells exceed int16 indices")
        self.occupied_cells = np.argwhere(occ).astype(np.int16)
        self.grid_shape = (int(occ.shape[0]), int(occ.shape[1]))
        self.field_sigma_m, self.field_resolution_m = cfg.sigma_m, cfg.resolution_m
        if cfg.global_cell_factor > 0:
            self.coarse = coarse_field(self.field(), cfg.global_cell_factor)
            self.coarse_factor = cfg.global_cell_factor
        empty = np.zeros((0, 0), np.float32)
        self.likelihood, self.logodds = empty, empty  # the log-odds are not needed any more
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
        self.odom: F64 | None = None  # last scan's pose on scale-corrected odometry
        self.odom_raw: F64 | None = None  # ... on odometry as given
        self.odom_now = np.zeros(3)  # the scan being processed, corrected (predict)
        self.active: list[Submap] = []
        self.submaps: list[Submap] = []
        floors = (cfg.odom_floor_m_per_m, cfg.odom_floor_rad_per_rad, cfg.odom_floor_rad_per_m)
        self.fusion = (
            OdometryFusion(
                cfg.fusion_window,
                cfg.fusion_lag,
                floors,
                (cfg.match_ceiling_m, cfg.match_ceiling_rad),
                cfg.turn_fusion,
            )
            if cfg.fuse_odometry
            else None
        )
        self.check = OdometryCheck(cfg.doubt)
        self.doubted = False  # the last scan's match refuted odometry
        # ... or the scan fitted a prediction other than scan to scan, unlike a stall
        self.odom_suspect = False
        self.n_relocalised = 0
        self.lost = False  # tracking lost and not found again near the prediction
        self.poor = 0  # scans in a row that fit under retry_score
        # the last scan was lost and fit under lost_score, best outside the narrow window
        self.unmatched = False
        self.held = False  # the last scan's narrow match was held back (match)
        self.sensor_xy = np.zeros(2)  # the scanner's position (robot frame; rays start there)
        # the scanner's field of view, first and last beam (rad, robot frame; GraphSlam sets it
        # from each scan); None: all round
        self.view: tuple[float, float] | None = None
        # the range beyond which the scanner's returns are not used (m; GraphSlam sets it):
        # a beam that returned nothing looked this far. 0: unknown
        self.max_range_m = 0.0
        self.unobserved = 0  # the last scan's points left out as unobserved (match)
        self._lost = 0
        # J^T J of the last scan's match (local frame; :func:`~.scan_matching.match_hessian`),
        # None when it was not matched: how sharply the scan placed itself, per direction
        self.hessian: F64 | None = None
        # distances tracked between consecutive moving scans, the last steps_kept of them
        self._steps: deque[float] = deque(maxlen=max(cfg.steps_kept, 1))

    def dense_scans(self) -> bool:
        """Whether the scans come densely enough for edge-on samples to be spread: the median
        of the recent steps (``steps_kept``; a scan that moved under a centimetre does not
        count) at most ``edge_on_max_step_m`` (None: ``window_m``). True before the robot has
        moved."""
        limit = self.cfg.edge_on_max_step_m
        limit = self.cfg.window_m if limit is None else limit
        return not self._steps or float(np.median(self._steps)) <= limit

    def predict(self, odom_pose: F64) -> list[F64]:
        """Predictions of the scan's pose, scan to scan ``x_prev * (o_prev^-1 * o_now)`` first,
        then from the last scan odometry agreed with (:class:`~.odometry_check.OdometryCheck`);
        the first scan starts at its odometry. Odometry's increments are scaled by the
        fusion's estimate of its scale (:meth:`~.fusion.OdometryFusion.scale`): ``odom_now``
        is the scan's pose on that corrected odometry."""
        raw = np.asarray(odom_pose, np.float64)
        if self.pose is None or self.odom is None or self.odom_raw is None:
            self.odom_now = raw.copy()
            return [raw.copy()]
        u = between(self.odom_raw, raw)
        u[:2] *= 1.0 if self.fusion is None else self.fusion.scale()
        # an unchanged odometry stays exactly unchanged (composing a zero increment can round
        # the heading, and the odometry check tells a frozen odometry by an exact zero)
        self.odom_now = self.odom.copy() if not u.any() else compose(self.odom, u)
        return self.check.candidates(self.pose, self.odom, self.odom_now)

    def match(self, points: F64, guesses: list[F64], ang_step: float) -> tuple[F64, float]:
        """Correlative search then Gauss-Newton against the older active submap, around the
        prediction the scan fits best (ties, within ``doubt.margin``, to the one an encoder
        stall makes likely: :attr:`~.odometry_check.OdometryCheck.preferred`), in windows that
        grow with odometry's uncertainty (with no motion prior when odometry is fused: ties go
        to the candidate nearest it). A poor match (score under ``retry_score``: odometry
        glitch, fast turn) is searched again in the wide window around every prediction (where
        the scan fits poorly everywhere, the one it fits best at its centre need not be the one
        whose window holds the pose; another's result must beat that one's by ``doubt.margin``);
        one still under ``lost_score`` for ``relocalise_scans`` scans is relocalised in the
        submap; one that tracking lost and that still fits under ``lost_score``, outside the
        narrow window, keeps the prediction (``unmatched_hold_scans``). The heading window also
        grows with the turn the prediction makes, by odometry's learnt error per radian turned
        (:meth:`~.fusion.OdometryFusion.estimate_turn_ratio`). A match that refutes odometry is
        kept as it is; otherwise it is fused with the prediction. A narrow match held back on
        the window's edge by the last keyframe's samples (:meth:`_held`) is refined from the
        prediction instead and not learnt from (``held``). ``ang_step`` (rad) is the angular
        search step."""
        guess = guesses[0]
        self.doubted = self.odom_suspect = self.unmatched = self.held = False
        self.unobserved = 0
        self.hessian = None
        if not self.active:
            return guess, 0.0
        s, cfg = self.active[0], self.cfg
        res = cfg.resolution_m
        if len(guesses) > 1:
            fits = [sm.score_pose(s.likelihood, s.ox, s.oy, res, points, g) for g in guesses]
            best = int(np.argmax(fits))
            # ties go to the prediction an encoder stall makes likely (the last motion while
            # odometry stands still, the reference once it jumps): along a corridor both fit alike
            pref = self.check.preferred
            if pref is not None and fits[best] - fits[pref] < cfg.doubt.margin:
                best = pref
            guess = guesses[best]
            # the scan-to-scan odometry increment was wrong, and not as a stall would have it
            # (the frozen scans, the jump after them: odometry edges run across those)
            self.odom_suspect = best != 0 and best != pref
        points = self._observed(s, points, guess)
        odom_var = self.odometry_variance()
        turn_var = 0.0
        if self.fusion is not None and self.pose is not None:
            # odometry's heading error in proportion to the turn it predicts (learnt)
            turn_var = self.fusion.turn_variance(guess[2] - self.pose[2])
        win_m, win_rad = self.check.windows(odom_var, cfg.window_m, cfg.window_rad, turn_var)
        # a fused odometry pulls the pose once, in the fusion, by its learnt noise; a fixed
        # prior here as well pulled matches towards a prediction several degrees off wherever
        # odometry lags (smoothed over sparse scans), by a weight that knows no noise
        w_lin, w_ang = cfg.prior_lin_weight, cfg.prior_ang_weight
        if self.fusion is not None:
            w_lin = w_ang = 0.0
        pose, score = sm.correlative_search(
            s.likelihood,
            s.ox,
            s.oy,
            res,
            points,
            guess,
            win_m,
            win_rad,
            ang_step,
            w_lin,
            w_ang,
        )
        # a narrow match held back by the last keyframe (_held): not a measurement; refined
        # from the prediction instead, and not learnt from
        self.held = score >= cfg.retry_score and self._held(s, points, pose, score, guess, win_m)
        if self.held:
            pose = guess.copy()
        if score < cfg.retry_score:
            wide, wide_score = guess, -1.0
            # the prediction the scan fits best at its centre first; another's window wins
            # only by the odometry check's margin (in open space and look-alike places a
            # wide window always holds some marginally better fit)
            for g in [guess, *(g for g in guesses if g is not guess)]:
                w, w_score = sm.correlative_search(
                    s.likelihood,
                    s.ox,
                    s.oy,
                    res,
                    points,
                    g,
                    max(cfg.wide_window_m, win_m),
                    max(cfg.wide_window_rad, win_rad),
                    2.0 * ang_step,
                    0.0,
                    0.0,
                )
                if w_score > wide_score + (0.0 if g is guess else cfg.doubt.margin):
                    wide, wide_score = w, w_score
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
        self._lost = self._lost + 1 if score < cfg.lost_score else 0
        if self._lost >= cfg.relocalise_scans:
            pose, score = self._relocalise(s, points, guess, ang_step, pose, score)
        # a poor fit even after the wide search: kidnapped, or entering unmapped space
        self.poor = self.poor + 1 if score < cfg.retry_score else 0
        self.lost = self._lost >= cfg.lost_scans or self.poor >= cfg.lost_scans
        # farther than the window's half-widths, in the prediction's frame: a wide-search
        # pose, or a narrow one on the window's edge or corner (docs/slam.md, eighth round)
        off = between(guess, pose)
        outside = abs(off[2]) > win_rad or max(abs(off[0]), abs(off[1])) > win_m
        self.unmatched = (
            cfg.unmatched_hold_scans > 0 and self.lost and score < cfg.lost_score and outside
        )
        if self.unmatched:
            # in the Intel lab at 1 Hz the wide window's least bad pose of such a scan (0.12,
            # 32 deg off the prediction) was mapped and turned the middle rooms by 45 deg
            return guess.copy(), score
        refined, score2, _ = sm.gauss_newton(
            s.likelihood, s.ox, s.oy, res, points, pose, cfg.gn_iterations, cfg.gn_prior_weight
        )
        score = sm.score_pose(s.likelihood, s.ox, s.oy, res, points, pose)
        if score2 >= score and np.all(np.abs(refined[:2] - pose[:2]) < res):
            pose, score = refined, score2
        at_guess = sm.score_pose(s.likelihood, s.ox, s.oy, res, points, guess)
        match_var = None if self.fusion is None else self.fusion.match_variance()
        self.doubted = self.check.disagrees(guess, pose, score, at_guess, odom_var, match_var)
        self.hessian = sm.match_hessian(s.likelihood, s.ox, s.oy, res, points, pose)
        if self.fusion is not None and not self.doubted:
            step = between(self.pose, guess) if self.pose is not None else None
            pose = self.fusion.fuse(guess, pose, self.hessian, step, learn=not self.held)
        return pose, score

    def _observed(self, s: Submap, points: F64, guess: F64) -> F64:
        """The scan's points that land where ``s`` was observed, placed at the prediction
        ``guess`` (``observed_share``; all of them when too few do, and when the robot moves
        where the scanner looks: :meth:`towards_blind_side`). The window's half-width is how
        far the prediction may be off, so how far behind a wall seen before a point on it may
        land."""
        share = self.cfg.observed_share
        if share is None or len(points) == 0:
            return points
        if not self.towards_blind_side(guess):
            return points
        keep = sm.observed_before(
            s.logodds,
            s.ox,
            s.oy,
            self.cfg.resolution_m,
            points,
            guess,
            self.sensor_xy,
            self.cfg.window_m,
        )
        kept = int(np.count_nonzero(keep))
        if kept == len(points) or kept < share * len(points):
            return points
        self.unobserved = len(points) - kept
        return np.ascontiguousarray(points[keep])

    def towards_blind_side(self, guess: F64) -> bool:
        """Whether the predicted step from the last scan's pose to ``guess`` heads outside the
        scanner's field of view (``view``): a front scanner driven backwards or sideways.
        False for a step under ``doubt.moving_m`` (standing still, its direction is odometry's
        noise: on ACES steps of 1-10 mm pointed to the blind side on 107 scans, and the
        unperturbed run went from 0.0369 to 0.0390 m), an all-round scanner, or the first
        scan."""
        if self.pose is None or self.view is None:
            return False
        lo, hi = self.view
        if hi - lo >= 2.0 * math.pi:
            return False
        dx, dy = guess[0] - self.pose[0], guess[1] - self.pose[1]
        if math.hypot(dx, dy) < self.cfg.doubt.moving_m:
            return False
        heading = math.atan2(dy, dx) - self.pose[2]  # in the robot frame
        return (heading - lo) % (2.0 * math.pi) > hi - lo

    def _held(
        self, s: Submap, points: F64, pose: F64, score: float, guess: F64, win_m: float
    ) -> bool:
        """Whether a narrow match ``pose`` (score ``score``) about the prediction ``guess``
        was held back by the last keyframe's samples rather than placed by the walls: it lies
        on the translation window's edge (whole cells, ``win_m`` half-width) towards the last
        scan's pose, the scan fits there (standing still, at the match's heading) at least as
        well, and it fits the prediction well enough not to be searched again
        (``retry_score``).

        A keyframe's point samples (a wall's beams metres apart) are where the next scans'
        samples, on the same beams, fit best with the robot not moved; between sparse scans
        that pull reaches the window's edge, and a match left there each scan taught the
        fusion that odometry was off by the shortfall: the learnt noise grew, the windows
        with it, until the samples held tracking on its keyframes (a simulated hospital driven
        six times at 1.4 Hz, issue 19's fourteenth round). Odometry that really was off (a
        slip, a lag) leaves the prediction fitting clearly worse, and a robot that stood still
        while its wheels turned fits poorly there too."""
        if self.pose is None:
            return False
        res = self.cfg.resolution_m
        off = pose[:2] - guess[:2]
        edge = math.ceil(win_m / res) * res - 0.5 * res
        ahead = guess[:2] - self.pose[:2]
        if np.max(np.abs(off)) < edge or float(off @ ahead) >= 0.0:
            return False
        still = np.array([self.pose[0], self.pose[1], pose[2]])
        at_still = sm.score_pose(s.likelihood, s.ox, s.oy, res, points, still)
        at_guess = sm.score_pose(s.likelihood, s.ox, s.oy, res, points, guess)
        return bool(at_still >= score and at_guess >= self.cfg.retry_score)

    def _relocalise(
        self, s: Submap, points: F64, guess: F64, ang_step: float, pose: F64, score: float
    ) -> tuple[F64, float]:
        """Tracking lost: branch-and-bound over ``+-relocalise_window_m`` and every heading in
        the submap; the result replaces the match when it scores at least ``retry_score``."""
        cfg = self.cfg
        pyr = sm.max_pyramid(s.likelihood, 5)
        found, found_score = sm.branch_and_bound(
            pyr,
            s.ox,
            s.oy,
            cfg.resolution_m,
            points,
            guess,
            cfg.relocalise_window_m,
            math.pi,
            2.0 * ang_step,
            max(cfg.retry_score, score),
        )
        if found_score >= cfg.retry_score and found_score > score:
            self.n_relocalised += 1
            self._lost = 0
            return found, found_score
        return pose, score

    def restart(self, pose: F64) -> list[Submap]:
        """Resume tracking at ``pose`` (local frame) after a global relocalisation: the active
        submaps are finished (the next keyframe starts a new one there), the odometry check
        forgets its reference (odometry did not see the robot carried off). Returns the
        submaps finished."""
        done = self.finish_all()
        self.pose = np.asarray(pose, np.float64).copy()
        self.check = OdometryCheck(self.cfg.doubt)
        self.lost, self._lost, self.poor, self.unmatched = False, 0, 0, False
        self.hessian = None  # the match was of the place it was lost at
        self.n_relocalised += 1
        return done

    def odometry_variance(self) -> tuple[float, float] | None:
        """Odometry's estimated variance per scan (translation per axis m^2, heading rad^2),
        None until the fusion has enough scans."""
        if self.fusion is None:
            return None
        return self.fusion.odometry_variance()

    def accept(self, pose: F64, odom_pose: F64) -> None:
        if self.pose is not None:
            step = math.hypot(pose[0] - self.pose[0], pose[1] - self.pose[1])
            if step >= 0.01:
                self._steps.append(step)
        self.pose, self.odom = pose, self.odom_now.copy()
        self.odom_raw = np.asarray(odom_pose, np.float64).copy()
        self.check.accept(pose, self.odom, self.doubted)
        if self.fusion is not None:
            self.fusion.add(self.odom_raw)  # raw: the fusion estimates the scale from it

    def insert(
        self, node: int, pose: F64, sensor_xy: F64, ends: F64, hits: NDArray[np.bool_]
    ) -> list[Submap]:
        """Insert a keyframe (local frame) into the active submaps, starting a new submap every
        half ``submap_keyframes`` or half ``submap_length_m`` of path, whichever comes first;
        returns the submaps that got finished (full: either of the two). With
        ``smooth_beams``, each hit is first averaged with its neighbours on the same surface
        (:func:`smooth_surface`), once for both submaps."""
        cfg = self.cfg
        if cfg.smooth_beams > 0:
            ends = smooth_surface(
                np.ascontiguousarray(ends, np.float64),
                np.ascontiguousarray(hits),
                cfg.surface_gap_m,
                cfg.smooth_beams,
                cfg.smooth_dev_m,
            )
        half = max(cfg.submap_keyframes // 2, 1)
        if not self.active or self._full(self.active[-1], half, 0.5 * cfg.submap_length_m):
            s = new_submap(len(self.submaps), pose, cfg, self.kernel)
            self.submaps.append(s)
            self.active.append(s)
        edge_on = self.dense_scans()
        for s in self.active:
            s.insert(cfg, sensor_xy, ends, hits, node, edge_on, self.max_range_m)
        done = []
        if self._full(self.active[0], cfg.submap_keyframes, cfg.submap_length_m):
            first = self.active.pop(0)
            first.finish(cfg)
            done.append(first)
        return done

    @staticmethod
    def _full(s: Submap, keyframes: int, length_m: float) -> bool:
        return len(s.nodes) >= keyframes or s.path_m >= length_m

    def finish_all(self) -> list[Submap]:
        done = [s for s in self.active if s.nodes]
        for s in done:
            s.finish(self.cfg)
        self.active = []
        return done
