"""Odometry fusion in tracking: the noises of odometry and of the scan matches are told apart
by how they grow with the number of scans, and the fused track beats both."""

from __future__ import annotations

import numpy as np
import pytest

from agvsim.slam.frontend import OdometryFusion
from agvsim.slam.se2 import compose


def feed(sigma_match: float, sigma_odom: float, n: int = 600, seed: int = 0, scale: float = 1.0):
    """A robot driving a gentle arc, 5 cm per scan: matches = truth + white noise (each is
    placed against a fixed map), odometry = truth + a random walk. Returns the fusion, the
    truth, the fused track, the raw matches and the odometry."""
    rng = np.random.default_rng(seed)
    step = np.array([0.05, 0.0, 0.004])
    truth, odom = [np.zeros(3)], [np.zeros(3)]
    odom_step = step * np.array([scale, scale, 1.0])  # a wheel-radius error: translation only
    for _ in range(n - 1):
        truth.append(compose(truth[-1], step))
        noise = rng.normal(0.0, [sigma_odom, sigma_odom, 1e-4])
        odom.append(compose(odom[-1], odom_step + noise))
    truth_a, odom_a = np.array(truth), np.array(odom)
    matches = truth_a + rng.normal(0.0, [sigma_match, sigma_match, 1e-4], (n, 3))
    fusion = OdometryFusion(window=300, lag=10)
    fused = [truth_a[0].copy()]
    for k in range(1, n):
        guess = compose(fused[-1], _between(odom_a[k - 1], odom_a[k]))
        fused.append(fusion.fuse(guess, matches[k], np.eye(3)))
        fusion.add(odom_a[k])
    return fusion, truth_a, np.array(fused), matches, odom_a


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from agvsim.slam.se2 import between

    return between(a, b)


def test_noises_are_told_apart() -> None:
    # odometry worse than the matches: both variances come out (v_L - v_1 is large)
    fusion, *_ = feed(sigma_match=0.001, sigma_odom=0.004)
    var_odom, var_match, _, _ = fusion.estimate()
    # (increments over 10 scans overlap: ~30 independent ones in the window, hence factor 2)
    assert 0.5 * 0.004**2 < var_odom < 2.0 * 0.004**2
    assert var_match < 0.2 * var_odom
    # odometry far better: the match's variance comes out, odometry's is known to be small
    # (its share of v_L - v_1 is within the spread's sampling error)
    fusion, *_ = feed(sigma_match=0.004, sigma_odom=0.0005)
    var_odom, var_match, _, _ = fusion.estimate()
    assert var_match == pytest.approx(0.004**2, rel=0.3)
    assert var_odom < 0.1 * var_match


def test_fused_track_follows_the_better_source() -> None:
    # odometry slips, matches are good: the fused track stays with the matches
    _, truth, fused, matches, odom = feed(sigma_match=0.001, sigma_odom=0.004)
    half = len(truth) // 2  # after the noises are learnt

    def err(track: np.ndarray) -> float:
        return float(np.hypot(*(track[half:, :2] - truth[half:, :2]).T).mean())

    assert err(fused) < 2.0 * err(matches) and err(fused) < 0.2 * err(odom)
    # good odometry, jittery matches: the scan-to-scan motion is odometry's, not the jitter
    _, truth, fused, matches, odom = feed(sigma_match=0.004, sigma_odom=0.0005)

    def jitter(track: np.ndarray) -> float:
        d = np.diff(track[half:, :2], axis=0) - np.diff(truth[half:, :2], axis=0)
        return float(np.hypot(*d.T).mean())

    assert jitter(fused) < 0.2 * jitter(matches)


def test_standing_still_teaches_nothing() -> None:
    fusion = OdometryFusion(window=300, lag=10)
    pose = np.array([1.0, 2.0, 0.3])
    rng = np.random.default_rng(1)
    for _ in range(100):
        # until the noises are known the pose is odometry's, whatever the match says
        match = pose + rng.normal(0, 0.003, 3)
        assert np.array_equal(fusion.fuse(pose, match, np.eye(3)), pose)
        fusion.add(pose)
    assert not fusion.ready() and fusion.odometry_variance() is None


def test_odometry_scale_error_is_estimated() -> None:
    """Odometry 5 % long: the least-squares scale of the matches' increments against
    odometry's is 1 / 1.05 to within 0.3 %; unbiased odometry gets exactly 1 (within its
    noise: the scale is not touched); and the learnt odometry noise is its noise, not the
    bias (the 2.5 mm a scan it runs ahead would otherwise look like noise)."""
    fusion, *_ = feed(sigma_match=0.002, sigma_odom=0.0005, scale=1.05)
    assert fusion.scale() == pytest.approx(1 / 1.05, rel=3e-3)
    var_odom, _, _, _ = fusion.estimate()
    assert var_odom < 0.002**2
    fusion, *_ = feed(sigma_match=0.002, sigma_odom=0.0005)
    assert fusion.scale() == 1.0
    # standing still: nothing to estimate from
    fusion, *_ = feed(sigma_match=0.002, sigma_odom=0.0, n=20, scale=1.05)
    assert fusion.scale() == 1.0


def test_odometry_error_that_does_not_build_up_is_not_put_on_the_matches() -> None:
    """Matches exact; odometry's heading off by white noise of 2 deg at every scan (smoothed
    or lagging odometry: wrong on each turn, right again after): its increments are off by
    2 * (2 deg)^2 in variance at every lag, which the two-lag model reads as match noise of
    (2 deg)^2. Capped at (1 deg)^2, the rest, 2 * (4 - 1) = 6 deg^2 per scan, is odometry's,
    and the heading gain moves to the matches (6 / 7)."""
    rng = np.random.default_rng(4)
    n = 400
    step = np.array([0.2, 0.0, 0.01])
    truth = [np.zeros(3)]
    for _ in range(n - 1):
        truth.append(compose(truth[-1], step))
    t = np.array(truth)
    odom = t.copy()
    odom[:, 2] += rng.normal(0.0, np.radians(2.0), n)
    for caps, s_o_deg2, gain in (
        ((np.inf, np.inf), 0.0, 0.0),
        ((0.05, np.radians(1.0)), 6.0, 6 / 7),
    ):
        fusion = OdometryFusion(window=300, lag=10, match_ceilings=caps)
        for k in range(1, n):
            fusion.fuse(t[k], t[k], np.eye(3))
            fusion.add(odom[k])
        _, _, k_rot, s_or = fusion.estimate()
        assert np.degrees(np.sqrt(s_or)) ** 2 == pytest.approx(s_o_deg2, abs=1.0)
        assert k_rot == pytest.approx(gain, abs=0.05)


def test_heading_error_per_radian_turned_is_learnt() -> None:
    """A robot that drives four 10 cm steps and then turns 0.5 rad on the spot, over and over;
    odometry's turns are off by 30 % of the turn (std, normal), its straight steps exact;
    the matches are the truth. The error per radian turned comes out as 0.30 (within the
    sampling error of ~60 turns); a robot that never turns 0.2 rad in a scan learns none."""
    rng = np.random.default_rng(4)
    truth, odom = [np.zeros(3)], [np.zeros(3)]
    for k in range(1, 320):
        step = np.array([0.0, 0.0, 0.5]) if k % 5 == 0 else np.array([0.1, 0.0, 0.0])
        truth.append(compose(truth[-1], step))
        err = np.array([0.0, 0.0, 0.5 * 0.3 * rng.normal()]) if k % 5 == 0 else np.zeros(3)
        odom.append(compose(odom[-1], step + err))
    fusion = OdometryFusion(window=300, lag=10)
    for k in range(1, len(truth)):
        fusion.fuse(truth[k], truth[k], np.eye(3))
        fusion.add(odom[k])
    assert fusion.estimate_turn_ratio() == pytest.approx(0.30, rel=0.25)
    assert fusion.turn_ratio == pytest.approx(fusion.estimate_turn_ratio(), rel=0.1)
    straight, *_ = feed(sigma_match=0.001, sigma_odom=0.004)
    assert straight.estimate_turn_ratio() == 0.0


def test_a_turn_weighs_the_heading_by_the_learnt_error_per_radian() -> None:
    """Odometry's heading variance 1e-4 rad^2 and the match's 1e-4 (gain 0.5); a learnt error
    of 0.5 rad per radian turned. A prediction that turns 0.4 rad adds (0.5 * 0.4)^2 = 0.04 to
    odometry's variance: gain 0.0401 / 0.0402, so a match 0.1 rad off moves the heading by
    0.0997512 rad. Driving straight, or with ``turn_gain`` off, the gain stays 0.5."""
    guess = np.array([1.0, 2.0, 0.3])
    match = guess + np.array([0.0, 0.0, 0.1])
    turn, straight = np.array([0.05, 0.0, 0.4]), np.array([0.2, 0.0, 0.0])
    for gain in (True, False):
        fusion = OdometryFusion(window=300, lag=10, turn_gain=gain)
        fusion.preset((1e-4, 1e-4, 0.5, 1e-4))
        fusion.turn_ratio = 0.5
        moved = fusion.fuse(guess, match, np.eye(3), turn)[2] - guess[2]
        assert moved == pytest.approx(0.1 * 0.0401 / 0.0402 if gain else 0.05, rel=1e-9)
        assert fusion.fuse(guess, match, np.eye(3), straight)[2] - guess[2] == pytest.approx(0.05)


def test_a_preset_carries_the_turn_ratio_into_the_fusion() -> None:
    """The warm-up's later passes start from the noises *and* the turn ratio the pass before
    learnt: with ``preset(noises, 0.5)`` and no scan learnt yet, a turn of 0.4 rad weighs the
    heading as in the test above (gain 0.0401 / 0.0402); without the ratio the gain is 0.5."""
    guess = np.array([1.0, 2.0, 0.3])
    match = guess + np.array([0.0, 0.0, 0.1])
    turn = np.array([0.05, 0.0, 0.4])
    for ratio, gain in ((0.5, 0.0401 / 0.0402), (0.0, 0.5)):
        fusion = OdometryFusion(window=300, lag=10, turn_gain=True)
        fusion.preset((1e-4, 1e-4, 0.5, 1e-4), ratio)
        assert not fusion.ready() and fusion.turn_ratio == ratio
        moved = fusion.fuse(guess, match, np.eye(3), turn)[2] - guess[2]
        assert moved == pytest.approx(0.1 * gain, rel=1e-9)
