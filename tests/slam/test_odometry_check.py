"""Odometry that tracking can doubt: reference prediction, stalls, gates, growing windows,
noise floors; end to end on a synthetic hall with odometry that freezes and jumps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_graph_slam import ANGLES, cast, loop_path

from agvsim.slam.frontend import OdometryFusion, Tracker, TrackingConfig
from agvsim.slam.graph_slam import GraphSlam, SlamConfig
from agvsim.slam.odometry_check import DoubtConfig, OdometryCheck
from agvsim.slam.se2 import between, compose, wrap_angle


def test_prediction_from_the_reference_after_a_freeze() -> None:
    """Hand-worked: the reference is pose (1, 2, 0) with odometry (0, 0, 0). Two scans refute
    odometry (frozen at 0); then odometry jumps to (1, 0, pi/2): from the reference that is
    (1, 2) + (1, 0) = (2, 2) heading pi/2, whatever tracking did during the freeze."""
    chk = OdometryCheck(DoubtConfig())
    chk.accept(np.array([1.0, 2.0, 0.0]), np.zeros(3), doubted=False)
    chk.accept(np.array([1.3, 2.0, 0.1]), np.zeros(3), doubted=True)
    chk.accept(np.array([1.6, 2.1, 0.3]), np.zeros(3), doubted=True)
    assert chk.since_ref == 3
    cands = chk.candidates(
        np.array([1.6, 2.1, 0.3]), np.zeros(3), np.array([1.0, 0.0, math.pi / 2])
    )
    assert len(cands) == 2
    np.testing.assert_allclose(cands[1], [2.0, 2.0, math.pi / 2], atol=1e-12)
    # scan to scan the jump is added on top of the motion tracking already followed
    np.testing.assert_allclose(cands[0][2], wrap_angle(0.3 + math.pi / 2), atol=1e-12)


def test_reference_moves_on_after_max_doubt_scans() -> None:
    chk = OdometryCheck(DoubtConfig(max_doubt_scans=3))
    chk.accept(np.zeros(3), np.zeros(3), doubted=False)
    for k in range(1, 3):
        chk.accept(np.array([0.1 * k, 0, 0]), np.zeros(3), doubted=True)
        assert chk.ref_pose is not None and chk.ref_pose[0] == 0.0
    chk.accept(np.array([0.3, 0, 0]), np.zeros(3), doubted=True)  # the third in a row
    assert chk.ref_pose is not None and chk.ref_pose[0] == pytest.approx(0.3)
    assert chk.since_ref == 1 and chk.n_doubted == 3


def test_stall_while_moving_offers_the_last_motion() -> None:
    chk = OdometryCheck(DoubtConfig())
    chk.accept(np.zeros(3), np.zeros(3), doubted=False)
    chk.accept(np.array([0.1, 0.0, 0.02]), np.array([0.1, 0.0, 0.02]), doubted=False)
    odom = np.array([0.1, 0.0, 0.02])  # unchanged: stalled while moving 0.1 m a scan
    cands = chk.candidates(np.array([0.1, 0.0, 0.02]), odom, odom)
    assert chk.stall
    np.testing.assert_allclose(between(cands[0], cands[1]), [0.1, 0.0, 0.02], atol=1e-12)
    assert chk.disagrees(cands[0], cands[1], 0.5, 0.5, None, None)  # a stall always refutes
    # standing still before: an unchanged odometry is no stall
    still = OdometryCheck(DoubtConfig())
    still.accept(np.zeros(3), np.zeros(3), doubted=False)
    still.accept(np.zeros(3), np.zeros(3), doubted=False)
    assert len(still.candidates(np.zeros(3), np.zeros(3), np.zeros(3))) == 1 and not still.stall


def test_an_encoder_stall_needs_odometry_moving_before_and_lasts_while_tracking_moves() -> None:
    """A robot at rest whose tracked pose jitters by more than ``moving_m`` under a frozen
    odometry gets the last motion offered (a stall) but decides no tie (no encoder stall: its
    odometry did not move at the scan before); one that stalls on the move does, while
    odometry stays frozen and tracking still moves, and no longer where tracking stops too."""
    jitter = OdometryCheck(DoubtConfig())
    jitter.accept(np.zeros(3), np.zeros(3), doubted=False)
    jitter.accept(np.array([0.012, 0.0, 0.0]), np.zeros(3), doubted=False)  # 1.2 cm > moving_m
    assert len(jitter.candidates(np.array([0.012, 0.0, 0.0]), np.zeros(3), np.zeros(3))) == 2
    assert jitter.stall and not jitter.encoder_stall and jitter.preferred is None
    jitter.accept(np.array([0.024, 0.0, 0.0]), np.zeros(3), doubted=True)
    assert not jitter.stalls_only  # the reference is not preferred when odometry moves again
    chk = OdometryCheck(DoubtConfig())
    chk.accept(np.zeros(3), np.zeros(3), doubted=False)
    odom = np.array([0.05, 0.0, 0.0])
    chk.accept(odom.copy(), odom.copy(), doubted=False)  # both moved 5 cm
    pose = odom.copy()
    for _ in range(3):  # odometry frozen, the robot still driving 5 cm a scan
        chk.candidates(pose, odom, odom)
        assert chk.encoder_stall and chk.preferred == 1
        pose = pose + np.array([0.05, 0.0, 0.0])
        chk.accept(pose, odom, doubted=True)
    chk.candidates(pose, odom, odom)
    assert chk.encoder_stall
    chk.accept(pose.copy(), odom, doubted=True)  # tracking saw it stop
    chk.candidates(pose, odom, odom)
    assert chk.frozen and not chk.stall and not chk.encoder_stall and chk.preferred is None


def test_gate_uses_learnt_spread_floors_and_the_fit_margin() -> None:
    """Gate = max(floor, 4 sqrt(n s_o^2 + s_m^2)). With s_o^2 = 0.01 m^2 per scan, n = 4 and
    s_m^2 = 0: 4 * sqrt(0.04) = 0.8 m; with tiny noises the 0.1 m / 3 deg floors apply."""
    chk = OdometryCheck(DoubtConfig())
    chk.since_ref = 4
    guess = np.zeros(3)
    big = (0.01, 1e-8)
    assert not chk.disagrees(guess, np.array([0.79, 0.0, 0.0]), 0.9, 0.1, big, (0.0, 0.0))
    assert chk.disagrees(guess, np.array([0.81, 0.0, 0.0]), 0.9, 0.1, big, (0.0, 0.0))
    tiny = (1e-10, 1e-10)
    assert not chk.disagrees(guess, np.array([0.09, 0.0, 0.0]), 0.9, 0.1, tiny, None)
    assert chk.disagrees(guess, np.array([0.11, 0.0, 0.0]), 0.9, 0.1, tiny, None)
    assert chk.disagrees(guess, np.array([0.0, 0.0, math.radians(3.1)]), 0.9, 0.1, tiny, None)
    # the scan fits no better at the match (a featureless corridor): odometry is kept
    assert not chk.disagrees(guess, np.array([2.0, 0.0, 0.0]), 0.5, 0.48, tiny, None)
    off = OdometryCheck(DoubtConfig(enabled=False))
    assert not off.disagrees(guess, np.array([2.0, 0.0, 0.0]), 0.9, 0.1, tiny, None)


def test_search_windows_grow_with_the_scans_since_the_reference() -> None:
    """Heading variance 1e-4 rad^2 a scan: after 25 scans the std is 0.05 rad and the window
    3 x 0.05 = 0.15 rad; after one scan 0.03 rad, under the 6 deg base; capped at 45 deg."""
    chk = OdometryCheck(DoubtConfig())
    base_m, base_rad = 0.15, math.radians(6.0)
    var = (1e-6, 1e-4)
    chk.since_ref = 1
    assert chk.windows(var, base_m, base_rad) == (base_m, base_rad)
    chk.since_ref = 25
    assert chk.windows(var, base_m, base_rad)[1] == pytest.approx(0.15)
    chk.since_ref = 10**6
    assert chk.windows(var, base_m, base_rad) == (pytest.approx(0.4), pytest.approx(math.pi / 4))
    assert chk.windows(None, base_m, base_rad) == (base_m, base_rad)


def test_fusion_noise_floor_follows_the_motion() -> None:
    """Floors 1 % of the distance, 1 % of the turn plus 0.25 deg per metre: a step of 0.5 m
    turning 0.1 rad gives (0.005 m)^2 and (0.001 + 0.5 * 0.25 deg)^2."""
    cfg = TrackingConfig()
    fusion = OdometryFusion(
        10, 3, (cfg.odom_floor_m_per_m, cfg.odom_floor_rad_per_rad, cfg.odom_floor_rad_per_m)
    )
    v_t, v_r = fusion.floor_variance(np.array([0.3, 0.4, 0.1]))
    assert v_t == pytest.approx(0.005**2)
    assert v_r == pytest.approx((0.001 + 0.5 * math.radians(0.25)) ** 2)
    assert fusion.floor_variance(np.zeros(3)) == (0.0, 0.0)


def freezing_odometry(truth: np.ndarray, every: int, length: int) -> np.ndarray:
    """Exact odometry that repeats its last value for ``length`` scans every ``every`` scans,
    then jumps back to the truth."""
    odom = truth.copy()
    for start in range(every, len(truth) - length, every):
        odom[start : start + length] = truth[start - 1]
    return odom


def track_error(truth: np.ndarray, odom: np.ndarray, doubt: DoubtConfig) -> tuple[float, int]:
    """Largest position error (m) of the SLAM trajectory, both started at their first pose,
    and the number of scans whose match refuted odometry."""
    rng = np.random.default_rng(3)
    cfg = SlamConfig(tracking=TrackingConfig(doubt=doubt))
    slam = GraphSlam(30.0, config=cfg)
    for k, (pose, o) in enumerate(zip(truth, odom, strict=True)):
        slam.update(0.2 * k, cast(pose) + rng.normal(0.0, 0.01, ANGLES.size), ANGLES, o)
    slam.finish()
    _, est = slam.trajectory()
    d = between(est[0], est) - between(truth[0], truth)
    return float(np.hypot(d[:, 0], d[:, 1]).max()), slam.tracker.check.n_doubted


def test_freeze_then_jump_is_followed_by_scan_matching() -> None:
    # 0.15 m or 10 deg a scan; odometry frozen 10 scans out of every 25, then it jumps by up
    # to 1.5 m or 90 deg
    truth = loop_path(0.98, step_m=0.15)
    odom = freezing_odometry(truth, 25, 10)
    err, doubted = track_error(truth, odom, DoubtConfig())
    blind, _ = track_error(truth, odom, DoubtConfig(enabled=False))
    assert doubted >= 60  # the frozen scans were caught (measured 83 of 80 frozen + jumps)
    assert err < 0.1  # measured 0.03 m
    assert blind > 1.0  # trusted blindly, each jump is added twice: measured 10 m


def test_a_freeze_longer_than_max_doubt_scans_keeps_its_reference() -> None:
    """A turn on the spot of 3 deg a scan with odometry frozen for 30 scans (more than
    max_doubt_scans = 20): every frozen scan refutes odometry (a stall), the reference stays
    at the scan before the freeze, and when odometry jumps by the whole 90 deg turn the
    prediction from the reference is the true pose."""
    chk = OdometryCheck(DoubtConfig(max_doubt_scans=20))
    step = np.array([0.0, 0.0, math.radians(3.0)])
    pose = np.array([1.0, 2.0, 0.0])
    odom = np.array([5.0, 5.0, 1.0])  # odometry in its own frame
    chk.accept(pose.copy(), odom.copy(), doubted=False)
    chk.accept(pose := pose + step, odom := odom + step, doubted=False)  # moving
    frozen = odom.copy()
    for k in range(30):
        cands = chk.candidates(pose, frozen, frozen)
        # scan to scan, the last motion, and from the second frozen scan the reference
        assert chk.stall and chk.frozen and len(cands) == (2 if k == 0 else 3)
        pose = pose + step  # tracking follows the turn (the last-motion candidate)
        assert chk.disagrees(cands[0], pose, 0.9, 0.9, (1e-6, 1e-6), (1e-6, 1e-6))
        chk.accept(pose.copy(), frozen, doubted=True)
    assert chk.since_ref == 31 and chk.n_doubted == 30
    jumped = frozen + 30 * step  # odometry moves again: 90 deg in one message
    cands = chk.candidates(pose, frozen, jumped)
    np.testing.assert_allclose(cands[-1], [1.0, 2.0, math.radians(93.0)], atol=1e-12)


def _hall_tracker(cfg: TrackingConfig) -> tuple[Tracker, GraphSlam]:
    """A tracker whose submap holds 20 keyframes along the test hall (y = 1.5 m, x from
    1.5 m in 0.2 m steps), and the GraphSlam whose scans it was built from."""
    tracker = Tracker(cfg)
    slam = GraphSlam(30.0)
    for node in range(20):
        pose = np.array([1.5 + 0.2 * node, 1.5, 0.0])
        _, ends, hits = slam.scan_points(cast(pose), ANGLES)
        world = compose(pose, np.column_stack([ends, np.zeros(len(ends))]))[:, :2]
        tracker.insert(node, pose, pose[:2], world, hits)
    return tracker, slam


def test_a_poor_fit_is_searched_widely_around_every_prediction() -> None:
    """A scan whose far half lies outside the submap (new space) fits poorly everywhere: 0.42
    at the truth. Of the two predictions, the one 70 deg off fits (marginally) better at its
    centre than the one 30 deg off, but only the latter's wide window (+-40 deg) holds the
    truth: the wide search runs around both and finds it within a cell, its fit beating the
    other window's by more than the odometry check's margin (it searched around the former
    alone, and ended far off). Relocalisation is off to test the wide search."""
    from agvsim.slam import scan_matching as sm

    cfg = TrackingConfig(fuse_odometry=False, relocalise_scans=10**6)
    tracker, slam = _hall_tracker(cfg)
    truth = np.array([3.0, 1.6, 0.05])
    pts, _, _ = slam.scan_points(cast(truth), ANGLES)
    unseen = np.column_stack([np.full(len(pts), 25.0), np.linspace(-5.0, 5.0, len(pts))])
    pts = np.vstack([pts, unseen])
    near = truth + [0.0, 0.0, math.radians(30.0)]
    far = truth + [0.0, 0.0, math.radians(-70.0)]
    s = tracker.active[0]

    def fit(pose: np.ndarray) -> float:
        return float(sm.score_pose(s.likelihood, s.ox, s.oy, cfg.resolution_m, pts, pose))

    assert fit(truth) < cfg.retry_score and fit(far) > fit(near)
    pose, score = tracker.match(pts, [near, far], slam.angular_step(pts[: len(ANGLES)]))
    assert np.hypot(*(pose[:2] - truth[:2])) < cfg.resolution_m
    assert abs(wrap_angle(pose[2] - truth[2])) < math.radians(1.0)
    assert score >= fit(truth)


@pytest.mark.parametrize("fuse", [True, False])
def test_fused_odometry_does_not_also_pull_the_search(
    fuse: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With odometry fused (by its learnt noise), the narrow correlative search runs without
    the fixed motion prior, which would count odometry twice and hold matches towards a
    prediction that lags a turn; without fusion the prior is odometry's only say. Either way a
    prediction 5 deg and 10 cm off in the test hall is matched back to the truth."""
    from agvsim.slam import scan_matching as sm

    weights: list[tuple[float, float]] = []
    search = sm.correlative_search

    def spy(*args):  # type: ignore[no-untyped-def]
        weights.append((args[-2], args[-1]))
        return search(*args)

    monkeypatch.setattr(sm, "correlative_search", spy)
    cfg = TrackingConfig(fuse_odometry=fuse, prior_lin_weight=3.0, prior_ang_weight=4.0)
    tracker, slam = _hall_tracker(cfg)
    truth = np.array([3.0, 1.6, 0.05])
    pts, _, _ = slam.scan_points(cast(truth), ANGLES)
    guess = truth + [0.1, 0.0, math.radians(5.0)]
    pose, score = tracker.match(pts, [guess], slam.angular_step(pts))
    assert weights[0] == ((0.0, 0.0) if fuse else (3.0, 4.0))
    assert score > cfg.retry_score and len(weights) == 1  # no wide search needed
    assert np.hypot(*(pose[:2] - truth[:2])) <= cfg.resolution_m + 1e-9
    assert abs(wrap_angle(pose[2] - truth[2])) < math.radians(1.0)


def test_search_windows_grow_with_the_turn_predicted() -> None:
    """Heading variance 1e-4 rad^2 a scan, one scan since the reference, and a turn whose
    learnt error adds (0.05 rad)^2: the std is sqrt(1e-4 + 25e-4) = 0.05099 rad and the
    window 3 x 0.05099 = 0.15297 rad; without ``turn_windows`` the turn adds nothing."""
    base_m, base_rad = 0.15, math.radians(6.0)
    var = (1e-6, 1e-4)
    chk = OdometryCheck(DoubtConfig())
    assert chk.windows(var, base_m, base_rad, 0.05**2)[1] == pytest.approx(0.152971, abs=1e-6)
    assert chk.windows(var, base_m, base_rad, 0.0) == (base_m, base_rad)
    off = OdometryCheck(DoubtConfig(turn_windows=False))
    assert off.windows(var, base_m, base_rad, 0.05**2) == (base_m, base_rad)


def test_a_lost_scan_that_fits_nowhere_keeps_the_prediction() -> None:
    """Scans of scattered returns (0.5-4 m, drawn once) fit nowhere in the test hall (under
    ``lost_score`` even after the wide search and the relocalisation). The first two are poor
    scans (the search's least bad pose is kept, not mapped); from the third tracking is lost
    and such a scan keeps the prediction exactly, as the wide window's best lies outside the
    narrow window. With ``unmatched_hold_scans=0`` the least bad pose is kept as before."""
    room = np.random.default_rng(5).uniform(0.5, 4.0, ANGLES.size)
    for hold, keeps in [(9, True), (0, False)]:
        cfg = TrackingConfig(fuse_odometry=False, unmatched_hold_scans=hold)
        tracker, slam = _hall_tracker(cfg)
        pts, _, _ = slam.scan_points(room, ANGLES)
        guess = np.array([3.0, 1.5, 0.3])
        for k in range(3):
            pose, score = tracker.match(pts, [guess], slam.angular_step(pts))
            assert score < cfg.lost_score
            assert tracker.lost == (k == 2)
        assert tracker.unmatched == keeps
        assert np.array_equal(pose, guess) == keeps
        if not keeps:  # the least bad pose lies outside the narrow window (0.15 m, 6 deg)
            off = between(guess, pose)
            assert abs(off[2]) > cfg.window_rad or np.abs(off[:2]).max() > cfg.window_m


def test_ties_go_to_the_prediction_a_stall_makes_likely() -> None:
    """While odometry stands still on the move the last motion wins ties (index 1); once it
    moves again after nothing but stalls, the reference prediction does; after a scan where
    odometry moved wrongly (a slip) no prediction is preferred."""
    chk = OdometryCheck(DoubtConfig())
    chk.accept(np.zeros(3), np.zeros(3), doubted=False)
    odom = np.array([0.1, 0.0, 0.0])
    chk.accept(odom.copy(), odom.copy(), doubted=False)  # the reference, moving 0.1 m a scan
    pose = odom.copy()
    for _ in range(3):  # odometry frozen at 0.1 m
        cands = chk.candidates(pose, odom, odom)
        assert chk.stall and chk.preferred == 1
        pose = cands[1]
        chk.accept(pose, odom, doubted=True)
    assert chk.stalls_only and chk.since_ref == 4
    jumped = np.array([0.5, 0.0, 0.0])  # the jump by the 0.4 m it missed
    cands = chk.candidates(pose, odom, jumped)
    assert not chk.frozen and chk.preferred == len(cands) - 1 == 1
    np.testing.assert_allclose(cands[1], [0.5, 0.0, 0.0], atol=1e-12)  # from the reference
    np.testing.assert_allclose(cands[0], [0.8, 0.0, 0.0], atol=1e-12)  # the jump added again
    # a slip: odometry moved, the match refuted it; the reference is no longer preferred
    slip = OdometryCheck(DoubtConfig())
    slip.accept(np.zeros(3), np.zeros(3), doubted=False)
    slip.candidates(np.zeros(3), np.zeros(3), odom)
    slip.accept(np.zeros(3), odom, doubted=True)
    assert not slip.stalls_only
    slip.candidates(np.zeros(3), odom, 2 * odom)
    assert slip.since_ref == 2 and slip.preferred is None
