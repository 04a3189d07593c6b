"""A narrow scan match held back on its window's edge by the last keyframe's samples
(:meth:`agvsim.slam.frontend.Tracker._held`, issue 19's fourteenth round): refined from the
prediction instead and not learnt from, so that a run of them cannot teach the fusion that
odometry was off by the shortfall (the learnt noise grew, the windows with it, and a simulated
hospital's corridors, driven six times at 1.4 Hz, held tracking on its keyframes)."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import Submap, Tracker, TrackingConfig
from agvsim.slam.fusion import OdometryFusion
from agvsim.slam.mapping import gaussian_kernel, likelihood_field

RES = 0.05
OX, OY = -5.0, -3.0  # the grid's corner: x in [-5, 5), y in [-3, 3)
# cell centres (the field is interpolated between them): walls and far samples seen from the
# origin
WALL_Y = 1.275
BUMPS = np.array([[3.025, 0.625], [3.025, -0.625], [4.025, 0.025]])


def _submap(walls: bool) -> Submap:
    """A corridor's two walls along x (everywhere, when ``walls``) and three isolated samples
    where the last scan, taken at the origin, saw them."""
    occ = np.zeros((120, 200), dtype=bool)
    if walls:
        for y in (-WALL_Y, WALL_Y):
            occ[int((y - OY) // RES), :] = True
    for x, y in BUMPS:
        occ[int((y - OY) // RES), int((x - OX) // RES)] = True
    field = likelihood_field(occ, 0.05, RES)
    empty = np.zeros((0, 0), np.float32)
    return Submap(0, np.zeros(3), OX, OY, empty, field, gaussian_kernel(0.05, RES))


def _scan(walls: bool) -> np.ndarray:
    """The scan (robot frame) as taken at the origin: the walls from x = -1 to 2 m, every
    0.1 m (when ``walls``), and the three far samples."""
    pts = [BUMPS]
    if walls:
        x = np.arange(-1.0, 2.0 + 1e-9, 0.1)
        pts += [np.column_stack([x, np.full(x.size, y)]) for y in (-WALL_Y, WALL_Y)]
    return np.concatenate(pts)


def _tracker() -> Tracker:
    t = Tracker(TrackingConfig())
    t.pose = np.zeros(3)  # the last scan's pose: the origin
    return t


def _score(s: Submap, pts: np.ndarray, pose: tuple[float, float, float]) -> float:
    return float(sm.score_pose(s.likelihood, s.ox, s.oy, RES, pts, np.array(pose)))


GUESS = np.array([0.47, 0.0, 0.0])  # odometry: 0.47 m on, as between sparse scans
WIN_M = 0.15  # the narrow window: 3 cells, its edge 0.125 m off or more


def test_a_match_on_the_back_edge_that_fits_still_best_is_held() -> None:
    s, pts, t = _submap(True), _scan(True), _tracker()
    # hand-worked: at the origin all 65 points lie on occupied cells (field 1); at the
    # prediction and at the window's back edge (0.32 m) the 62 wall points still do and the
    # three far samples lie 0.32 m or more from theirs (field exp(-0.32^2 / 0.005) ~ 1e-9)
    assert _score(s, pts, (0.0, 0.0, 0.0)) == pytest.approx(1.0, abs=1e-6)
    edge = GUESS - [0.15, 0.0, 0.0]
    score = _score(s, pts, tuple(edge))
    assert score == pytest.approx(62 / 65, abs=1e-6)
    assert _score(s, pts, tuple(GUESS)) == pytest.approx(62 / 65, abs=1e-6)
    assert t._held(s, pts, edge, score, GUESS, WIN_M)


def test_a_match_inside_the_window_or_on_the_front_edge_is_not_held() -> None:
    s, pts, t = _submap(True), _scan(True), _tracker()
    for off in (-0.10, 0.0, 0.15):  # inside (0.10 < 0.125), at the prediction, ahead
        pose = GUESS + [off, 0.0, 0.0]
        assert not t._held(s, pts, pose, _score(s, pts, tuple(pose)), GUESS, WIN_M)
    side = GUESS + [0.0, 0.15, 0.0]  # on the edge, but across the motion
    assert not t._held(s, pts, side, _score(s, pts, tuple(side)), GUESS, WIN_M)


def test_odometry_that_was_really_off_is_not_held() -> None:
    # no walls: the scan fits only where the last scan was (a robot that stood still while
    # its wheels turned); at the prediction it fits nowhere (score ~0, under retry_score)
    s, pts, t = _submap(False), _scan(False), _tracker()
    edge = GUESS - [0.15, 0.0, 0.0]
    assert _score(s, pts, tuple(GUESS)) < t.cfg.retry_score
    assert not t._held(s, pts, edge, _score(s, pts, tuple(edge)), GUESS, WIN_M)
    # a match that fits better than the scan does standing still (1.0 here): the walls
    # placed it
    s2, pts2 = _submap(True), _scan(True)
    assert not t._held(s2, pts2, edge, 1.0 + 1e-3, GUESS, WIN_M)
    edge_score = _score(s2, pts2, tuple(edge))
    # and the first scan has nothing to be held by
    t.pose = None
    assert not t._held(s2, pts2, edge, edge_score, GUESS, WIN_M)


def test_tracking_keeps_the_prediction_and_does_not_learn_from_a_held_match() -> None:
    # the whole match: the correlative search's best in the 0.15 m window about 0.47 m is on
    # its back edge (the far samples pull towards the origin, the walls do not mind), held:
    # the pose stays at the prediction, and the fusion records no match for that scan
    s, pts, t = _submap(True), _scan(True), _tracker()
    s.nodes = [0]
    t.active, t.submaps = [s], [s]
    cfg = t.cfg
    assert cfg.window_m == WIN_M and t.fusion is not None
    t.odom = t.odom_raw = np.zeros(3)
    t.fusion.preset((1e-4, 1e-4, 0.5, 1e-6))
    pose, score = t.match(pts, [GUESS.copy()], 0.01)
    assert t.held
    assert abs(pose[0] - GUESS[0]) < RES and abs(pose[1]) < RES
    t.accept(pose, GUESS)
    assert t.fusion.matches == []  # nothing learnt from it


def test_fuse_without_learning_records_no_match() -> None:
    f = OdometryFusion(300, 10)
    f.preset((1e-4, 1e-4, 0.5, 1e-6))
    guess, match = np.zeros(3), np.array([0.1, 0.0, 0.0])
    hess = np.diag([1.0, 1.0, 1.0])
    f.add(np.zeros(3))
    f.fuse(guess, match, hess, learn=False)
    f.add(np.array([0.5, 0.0, 0.0]))
    assert f.matches == []
    f.fuse(guess, match, hess)
    f.add(np.array([1.0, 0.0, 0.0]))
    assert len(f.matches) == 1
