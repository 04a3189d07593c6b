"""Odometry's scale measured from pairs of raw scans (agvsim.slam.scale_pairs)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.slam.graph_slam import GraphSlam, SlamConfig
from agvsim.slam.scale_pairs import PairScale, _Scan
from agvsim.slam.se2 import between, compose

from helpers import cast_segments

ANGLES = np.radians(np.arange(-90.0, 90.5, 1.0))
# a 20 m x 8 m hall, door jambs and boxes along its walls: every stretch placed along it
HALL = np.array(
    [
        [0, 0, 20, 0],
        [20, 0, 20, 8],
        [20, 8, 0, 8],
        [0, 8, 0, 0],
        *[[x, 0, x, 0.5] for x in (3.0, 6.5, 9.0, 13.5, 17.0)],
        *[[x, 8, x, 7.4] for x in (2.0, 5.0, 8.5, 12.0, 15.5, 18.5)],
        [10, 3.5, 11, 3.5],
        [11, 3.5, 11, 4.5],
    ],
    dtype=float,
)
# a corridor 1.5 m wide and 200 m long, walls without a feature, its ends far beyond the
# scanner's 8 m: the scans cannot tell where along it they were taken
CORRIDOR = np.array([[-100, 0, 100, 0], [-100, 1.5, 100, 1.5]], dtype=float)


def drive(walls: np.ndarray, truth: np.ndarray, scale: float, max_range: float = 30.0):
    """Scans (ranges, inf beyond ``max_range``) along ``truth`` and odometry whose every
    translation is ``scale`` times the true one."""
    odom = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:], strict=True):
        d = between(a, b)
        d[:2] *= scale
        odom.append(compose(odom[-1], d))
    for pose, o in zip(truth, odom, strict=True):
        r = cast_segments(pose, walls, ANGLES)
        yield np.where(r <= max_range, r, np.inf), o


def straight(x0: float, x1: float, y: float, step: float = 0.1) -> np.ndarray:
    xs = np.arange(x0, x1, step)
    return np.column_stack([xs, np.full_like(xs, y), np.zeros_like(xs)])


def pairs_along(walls: np.ndarray, truth: np.ndarray, scale: float, max_range: float = 30.0):
    slam = GraphSlam(max_range)  # for its scan_points
    ps = PairScale(0.05, 0.05, 0.5, slam.max_range_m, noise_floor=0.01)
    for ranges, odom in drive(walls, truth, scale, max_range):
        points, ends, hits = slam.scan_points(ranges, ANGLES)
        ps.observe(odom, ranges, ANGLES, np.zeros(3), points, ends, hits)
    return ps


@pytest.mark.parametrize("scale", [1.0, 1.05, 0.93])
def test_a_wheel_scale_is_measured_from_the_scans_alone(scale: float) -> None:
    """Along the hall there and back (12 m each way), odometry ``scale`` times the truth: the
    pairs' estimate is 1 / scale to 0.5 %, and decided once 5 m are in (exact odometry: 1)."""
    out = straight(2.0, 16.0, 2.0)
    back = straight(2.0, 16.0, 5.5)[::-1].copy()
    back[:, 2] = math.pi
    truth = np.vstack([out, back])
    ps = pairs_along(HALL, truth, scale)
    k, se, path = ps.estimate()
    assert path > 20.0 * scale
    assert k == pytest.approx(1.0 / scale, rel=5e-3)
    assert se < 0.01
    if scale == 1.0:
        assert ps.scale == 1.0
    else:
        assert ps.scale == pytest.approx(1.0 / scale, rel=5e-3)


def test_a_corridor_beyond_the_range_tells_no_scale() -> None:
    """Along a featureless corridor whose ends lie beyond the range the scans cannot place
    the motion along it: each pair stays at odometry's increment (the search starts from it,
    unscaled) with next to no weight, and the 5 % long odometry is left as it is, not
    corrected by a figure the scans never measured."""
    truth = straight(0.0, 30.0, 0.75)
    ps = pairs_along(CORRIDOR, truth, 1.05, max_range=8.0)
    assert ps.scale == 1.0
    assert ps.n_dropped + len(ps.pairs) >= 25  # a pair each metre was tried
    # far off the walls are sampled metres apart (bumps, not ridges): left out, and what
    # is left of each scan says nothing along the corridor
    hall = pairs_along(HALL, straight(2.0, 16.0, 2.0), 1.05)
    weight = max((p[2] for p in ps.pairs), default=0.0)
    assert weight < 0.01 * float(np.median(np.asarray(hall.pairs)[:, 2]))


def test_only_points_both_scans_see_are_matched() -> None:
    """A wall 3 m ahead, seen from a first scan at the origin out to 2 m either side of the
    beam straight ahead; the second scan's points on it (1 m further on) count where the
    first scan's beam in their direction returned within ``covisible_m``, not past the end
    it saw, and not a point behind a wall the first scan saw in front of it."""
    ps = PairScale(0.05, 0.05, 0.5, 30.0)
    angles = np.radians(np.arange(-60.0, 60.5, 1.0))
    r_ref = np.full(angles.size, np.inf)
    seen = np.abs(np.tan(angles) * 3.0) <= 2.0
    r_ref[seen] = 3.0 / np.cos(angles[seen])
    o = np.array([1.0, 0.0, 0.0])  # the second scan 1 m on, same heading
    # points in the second scan's frame: on the wall (x = 2) at y = 0, 1.5, 2.5; and one at
    # x = 4 straight ahead, behind the wall the first scan saw there
    pts = np.array([[2.0, 0.0], [2.0, 1.5], [2.0, 2.5], [4.0, 0.0]])
    first = _Scan(
        np.zeros(3),
        r_ref,
        angles,
        np.zeros(3),
        np.zeros((0, 2), np.float32),
        np.zeros(0, bool),
        np.zeros((0, 2)),
    )
    kept, _ = ps._covisible(pts, o, first)
    assert kept.tolist() == [[2.0, 0.0], [2.0, 1.5]]


def test_the_estimate_is_the_weighted_least_squares_slope_without_outliers() -> None:
    """Hand-worked: pairs ``(a, b, w)`` measuring 0.95 a metre, weights 1 and 3, and one pair
    off by far more than the others' scatter: ``k = sum w a b / sum w b^2`` over the rest."""
    ps = PairScale(0.05, 0.05, 0.5, 30.0)
    rows = [(0.95, 1.0, 1.0), (0.951, 1.0, 3.0), (0.949 * 1.2, 1.2, 1.0), (0.96, 1.0, 3.0)]
    ps.pairs.extend(rows * 3)
    ps.pairs.append((0.5, 1.0, 1.0))  # a bad match
    k, se, path = ps.estimate()
    a, b, w = np.asarray(rows * 3).T
    assert k == pytest.approx(np.sum(w * a * b) / np.sum(w * b * b), rel=1e-12)
    assert path == pytest.approx(np.sum(b))
    assert 0.0 < se < 0.01


def test_graph_slam_drives_with_the_scale_the_pairs_measured() -> None:
    """GraphSlam's tracking scales odometry's increments by the pairs' scale (5 % long
    odometry in the hall: 1 / 1.05 to 0.5 %), and with ``scale_pairs=None`` by the estimate
    from matches against the submap, as before."""
    truth = np.vstack([straight(2.0, 16.0, 2.0), straight(16.0, 18.0, 2.0)])
    slam = GraphSlam(30.0)
    for k, (ranges, odom) in enumerate(drive(HALL, truth, 1.05)):
        slam.update(0.1 * k, ranges, ANGLES, odom)
    assert slam.tracker.fusion is not None and slam.pair_scale is not None
    assert slam.tracker.fusion.scale() == pytest.approx(1 / 1.05, rel=5e-3)
    assert slam.tracker.fusion.scale() == slam.pair_scale.scale
    old = GraphSlam(30.0, config=SlamConfig(scale_pairs=None))
    assert old.pair_scale is None
    assert old.tracker.fusion is not None and old.tracker.fusion.pairs is None


def test_where_the_scale_stays_one_the_run_is_the_same_to_the_bit() -> None:
    """Exact odometry, ranges with 1 cm of noise: the pairs' estimate stays within the 1 % floor,
    tracking drives with exactly 1, and the trajectory is the one without the pairs."""
    scans = list(drive(HALL, straight(2.0, 16.0, 2.0), 1.0))
    runs = []
    for cfg in (SlamConfig(), SlamConfig(scale_pairs=None)):
        slam = GraphSlam(30.0, config=cfg)
        noise = np.random.default_rng(7)
        for k, (ranges, odom) in enumerate(scans):
            slam.update(0.1 * k, ranges + noise.normal(0, 0.01, ranges.size), ANGLES, odom)
        slam.finish()
        runs.append(slam.trajectory()[1])
    assert runs[0].shape == runs[1].shape
    assert np.array_equal(runs[0], runs[1])


def test_beams_given_in_either_order_measure_the_same() -> None:
    """The same scans with their beams listed from left to right instead: the same pairs
    (to a millimetre: the matching points are thinned to one a cell in beam order, so a few
    differ); beams not evenly spaced take no part in a pair."""
    truth = straight(2.0, 16.0, 2.0)
    slam = GraphSlam(30.0)
    runs = []
    for order in (slice(None), slice(None, None, -1)):
        ps = PairScale(0.05, 0.05, 0.5, slam.max_range_m, noise_floor=0.01)
        for ranges, odom in drive(HALL, truth, 1.05):
            r, a = ranges[order], ANGLES[order]
            ps.observe(odom, r, a, np.zeros(3), *slam.scan_points(r, a))
        runs.append(np.asarray(ps.pairs))
    assert len(runs[0]) >= 10
    assert runs[1].shape == runs[0].shape
    np.testing.assert_allclose(runs[1][:, :2], runs[0][:, :2], atol=1e-3)
    np.testing.assert_allclose(runs[1][:, 2], runs[0][:, 2], rtol=0.05)
    uneven = np.concatenate([ANGLES[:90], ANGLES[91:]])
    ps = PairScale(0.05, 0.05, 0.5, slam.max_range_m)
    for ranges, odom in drive(HALL, truth, 1.05):
        r = np.concatenate([ranges[:90], ranges[91:]])
        ps.observe(odom, r, uneven, np.zeros(3), *slam.scan_points(r, uneven))
    assert len(ps.pairs) == 0 and ps.scale == 1.0


def test_an_odometry_jump_leaves_the_estimate_alone() -> None:
    """Odometry that jumps 8 m along the hall between two scans (a glitch): the pair across
    the jump is dropped, not measured (at odometry's pose its points do not lie where the
    other scan saw the same surfaces), and the pairs before and after it measure the scale
    as without the jump."""
    truth = straight(2.0, 16.0, 2.0)
    slam = GraphSlam(30.0)
    runs = []
    for jump in (0.0, 8.0):
        ps = PairScale(0.05, 0.05, 0.5, slam.max_range_m, noise_floor=0.01)
        for k, (ranges, odom) in enumerate(drive(HALL, truth, 1.05)):
            o = odom + (np.array([jump, 0.0, 0.0]) if k >= 70 else 0.0)
            ps.observe(o, ranges, ANGLES, np.zeros(3), *slam.scan_points(ranges, ANGLES))
        runs.append(ps)
    plain, jumped = runs
    assert jumped.n_dropped == plain.n_dropped + 1
    assert len(jumped.pairs) == len(plain.pairs) - 1
    assert jumped.scale == pytest.approx(plain.scale, rel=2e-3)
    assert jumped.scale == pytest.approx(1 / 1.05, rel=5e-3)
