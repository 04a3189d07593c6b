"""Scan points that land where the matched submap was never observed are left out of the
match (:func:`agvsim.slam.scan_matching.observed_before`, ``TrackingConfig.observed_share``; issue
19's fifteenth round): the submap ends where its scans saw, and a point just past that edge
fits only with the scan moved back onto the last returns. A robot driving backwards with a
front scanner sees each wall come into view beside it, and every match fell short: the
simulated hospital driven there and back six times at 1.4 Hz came out 2 % small."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agvsim.slam.frontend import Tracker, TrackingConfig
from agvsim.slam.graph_slam import GraphSlam
from agvsim.slam.scan_matching import observed_before


def _grid() -> np.ndarray:
    """10 x 10 cells of 0.1 m from (0, 0): observed (free, -0.4) where x < 0.5, except the
    cell (ix 2, iy 5), whose log-odds is back at 0 (as much hit as missed: unknown)."""
    g = np.zeros((10, 10), np.float32)
    g[:, :5] = -0.4
    g[5, 2] = 0.0
    return g


def test_observed_before_looks_short_of_each_point_on_its_ray() -> None:
    g = _grid()
    pose = np.array([0.05, 0.55, 0.0])
    pts = np.array(
        [
            [0.3, 0.0],  # world (0.35, 0.55); 0.1 m short: (0.25, 0.55), the cell at 0
            [0.5, 0.0],  # world (0.55, 0.55), an unseen cell; short of it (0.45, 0.55): seen
            [0.7, 0.0],  # short of it (0.65, 0.55): never seen
            [0.05, 0.0],  # nearer the sensor than 0.1 m
            [2.0, 0.0],  # short of it (1.95, 0.55): off the grid
        ]
    )
    got = observed_before(g, 0.0, 0.0, 0.1, pts, pose, np.zeros(2), 0.1)
    assert got.tolist() == [False, True, False, True, False]


def test_observed_before_starts_the_rays_at_the_sensor() -> None:
    g = _grid()
    # facing +y; the sensor 0.1 m ahead of the base: at (0.55, 0.15) in the world
    pose = np.array([0.55, 0.05, math.pi / 2])
    pts = np.array(
        [
            [0.5, 0.0],  # world (0.55, 0.55); ray straight up, 0.1 m short: (0.55, 0.45)
            # world (0.15, 0.55); the ray from (0.55, 0.15) is 0.566 m long, 0.1 m short of
            # its end: (0.221, 0.479), a seen cell (from the base it would be (0.222, 0.476))
            [0.5, 0.4],
        ]
    )
    got = observed_before(g, 0.0, 0.0, 0.1, pts, pose, np.array([0.1, 0.0]), 0.1)
    assert got.tolist() == [False, True]


WALL_Y = 1.025  # cell centres: the walls stamp where they are


def _scan(pose: np.ndarray, range_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A front scanner (181 beams over 180 deg) at ``pose`` in a corridor between walls at
    y = +-WALL_Y with no end: its points (robot frame), its rays' ends (world) and hits."""
    a = np.radians(np.linspace(-90.0, 90.0, 181)) + pose[2]
    d = np.column_stack([np.cos(a), np.sin(a)])
    t = np.full(a.size, np.inf)
    with np.errstate(divide="ignore"):
        for y in (-WALL_Y, WALL_Y):
            ty = (y - pose[1]) / d[:, 1]
            t = np.where((ty > 0) & (ty < t), ty, t)
    hit = t <= range_m
    ends = pose[:2] + d * np.minimum(t, range_m)[:, None]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rel = ends[hit] - pose[:2]
    pts = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
    return pts, ends, hit


@pytest.mark.parametrize("back_m", [0.05, 0.1, 0.2])
def test_a_scanner_driven_backwards_is_not_held_where_it_was(back_m: float) -> None:
    # the first scan at the origin, mapped; the robot then backs up by back_m and odometry
    # says so exactly. Along a corridor without an end in reach (3 m) the walls say nothing
    # of x; only the returns on the wall now beside and behind the scanner, past the edge of
    # what the first scan saw, do: they fit only with the scan moved back onto the first
    # scan's last returns
    results = {}
    for share in (None, 0.5):
        t = Tracker(dataclasses.replace(TrackingConfig(), observed_share=share))
        p0 = np.zeros(3)
        _, ends, hits = _scan(p0, 3.0)
        t.insert(0, p0, p0[:2], ends, hits)
        t.pose, t.odom, t.odom_raw = p0.copy(), p0.copy(), p0.copy()
        t.view = (-math.pi / 2, math.pi / 2)
        assert t.fusion is not None
        t.fusion.preset((1.0, 1e-8, 1.0, 1.0))  # the match, not odometry, places the scan
        truth = np.array([-back_m, 0.0, 0.0])
        pts, _, _ = _scan(truth, 3.0)
        pose, _ = t.match(pts, [truth.copy()], math.radians(0.5))
        results[share] = (pose, t.unobserved)
    held, n_all = results[None]
    assert n_all == 0
    assert abs(held[0]) < 0.03  # matched where the first scan was: short by all of back_m
    pose, n_left = results[0.5]
    # the returns whose ray ends in wall never seen, both walls: up to where the first scan's
    # +-90 deg beams met them (x = 0), give or take a cell; those in that cell still pull,
    # by a few millimetres at most
    assert n_left > 0
    assert pose == pytest.approx([-back_m, 0.0, 0.0], abs=0.005)


def _mapped_tracker() -> Tracker:
    """A tracker whose submap holds one scan taken at the origin (3 m corridor scanner),
    with the last scan there, and a front scanner's field of view."""
    t = Tracker(TrackingConfig())
    p0 = np.zeros(3)
    _, ends, hits = _scan(p0, 3.0)
    t.insert(0, p0, p0[:2], ends, hits)
    t.pose, t.odom, t.odom_raw = p0.copy(), p0.copy(), p0.copy()
    t.view = (-math.pi / 2, math.pi / 2)
    return t


def test_points_are_left_out_only_when_backing_up() -> None:
    # forwards the far ends of the walls (past the first scan's 3 m) land unobserved too, and
    # count; backing up, those beside the scanner are left out. Scans 0.1 or 0.5 m apart
    for step, left_out in ((0.1, False), (0.5, False), (-0.1, True), (-0.5, True)):
        t = _mapped_tracker()
        guess = np.array([step, 0.0, 0.0])
        pts, _, _ = _scan(guess, 3.0)
        t.match(pts, [guess.copy()], math.radians(0.5))
        assert (t.unobserved > 0) == left_out, step
    # an all-round scanner has no blind side
    t = _mapped_tracker()
    t.view = None
    guess = np.array([-0.1, 0.0, 0.0])
    pts, _, _ = _scan(guess, 3.0)
    t.match(pts, [guess.copy()], math.radians(0.5))
    assert t.unobserved == 0


def test_towards_blind_side_by_hand() -> None:
    t = _mapped_tracker()  # at the origin, facing +x, seeing -90..90 deg
    blind = {
        (0.1, 0.0): False,  # ahead
        (0.0, 0.1): False,  # 90 deg left: the last beam, still seen
        (-0.1, 0.0): True,  # backwards
        (-0.1, 0.1): True,  # 135 deg
        (-0.005, 0.0): False,  # under a centimetre (doubt.moving_m): standing still
    }
    for (x, y), want in blind.items():
        assert t.towards_blind_side(np.array([x, y, 0.0])) == want, (x, y)
    t.pose = np.array([0.0, 0.0, math.pi / 2])  # facing +y: -y is behind
    assert t.towards_blind_side(np.array([0.0, -0.1, math.pi / 2]))
    assert not t.towards_blind_side(np.array([0.1, 0.0, math.pi / 2]))  # its right: seen
    t.view = None  # all round
    assert not t.towards_blind_side(np.array([0.0, -0.1, math.pi / 2]))
    t.view, t.pose = (-math.pi / 2, math.pi / 2), None  # the first scan
    assert not t.towards_blind_side(np.array([-0.1, 0.0, 0.0]))


def test_the_field_of_view_comes_from_the_beams() -> None:
    # a front scanner (181 beams, -90..90 deg) mounted turned by 10 deg; a 270 deg one; an
    # all-round one whose last beam is a beam spacing short of the first
    slam = GraphSlam(30.0, np.array([0.2, 0.0, math.radians(10.0)]))
    front = np.radians(np.linspace(-90.0, 90.0, 181))
    assert slam._view(front) == pytest.approx((math.radians(-80.0), math.radians(100.0)))
    wide = np.radians(np.linspace(-135.0, 135.0, 541))
    assert slam._view(wide) == pytest.approx((math.radians(-125.0), math.radians(145.0)))
    round_ = np.radians(np.arange(360.0) - 180.0)
    assert slam._view(round_) is None
    # a rear scanner's beams given across the +-180 deg seam: read as all round
    rear = np.radians(np.concatenate([np.arange(-180.0, -89.0), np.arange(90.0, 181.0)]))
    assert slam._view(rear) is None


def test_a_scan_mostly_in_unseen_space_keeps_every_point() -> None:
    # backing up 0.1 m turned by 145 deg: facing back down the corridor, most of its returns
    # land where the first scan never looked; left out, a few would be left, so all count
    # (observed_share 0.5). With a share of 1 % they would be left out
    guess = np.array([-0.1, 0.0, math.radians(145.0)])
    pts, _, _ = _scan(guess, 3.0)
    counts = {}
    for share in (0.5, 0.01):
        t = _mapped_tracker()
        t.cfg = dataclasses.replace(t.cfg, observed_share=share)
        assert t.towards_blind_side(guess)
        t.match(pts, [guess.copy()], math.radians(0.5))
        counts[share] = t.unobserved
    assert counts[0.5] == 0
    assert counts[0.01] > 0.5 * len(pts)
