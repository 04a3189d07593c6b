"""Faults of the robustness suite: each does what it says, and only that, deterministically."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.scan import LaserScan
from agvsim.slam.perturb import Fault, FaultConfig, apply_fault
from agvsim.slam.se2 import between, compose


def scans(n: int = 400, rate_hz: float = 5.0) -> list[LaserScan]:
    """A robot driving 0.1 m and turning 0.05 rad per scan; 10 beams, one without a return."""
    pose = np.array([1.0, -2.0, 0.3])
    out = []
    ranges = np.array([1.0, 2.0, np.inf, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0])
    for k in range(n):
        out.append(
            LaserScan(k / rate_hz, -1.0, 2.0 / 9.0, 0.0, 80.0, ranges.copy(), np.zeros(3), pose)
        )
        pose = compose(pose, np.array([0.1, 0.0, 0.05]))
    return out


def run(fault: str, seed: int = 0, cfg: FaultConfig | None = None) -> list[LaserScan]:
    return list(apply_fault(scans(), fault, np.random.default_rng(seed), cfg))


def steps(recs: list[LaserScan]) -> np.ndarray:
    o = np.array([r.odom_pose for r in recs])
    return between(o[:-1], o[1:])


def test_none_is_the_identity_and_faults_are_deterministic() -> None:
    base = scans()
    same = list(apply_fault(base, "none", np.random.default_rng(0)))
    assert all(a is b for a, b in zip(base, same, strict=True))
    for f in Fault:
        a, b = run(f, seed=5), run(f, seed=5)
        assert [r.stamp_s for r in a] == [r.stamp_s for r in b]
        for ra, rb in zip(a, b, strict=True):
            np.testing.assert_array_equal(ra.odom_pose, rb.odom_pose)
            np.testing.assert_array_equal(ra.ranges, rb.ranges)


def test_scale_lengthens_translation_only() -> None:
    u = steps(run("scale"))
    np.testing.assert_allclose(u[:, 0], 0.105, atol=1e-12)
    np.testing.assert_allclose(u[:, 2], 0.05, atol=1e-12)


def test_heading_bias_adds_rate_times_time() -> None:
    cfg = FaultConfig(heading_bias_rad_per_s=0.01)
    u = steps(run("heading-bias", cfg=cfg))
    np.testing.assert_allclose(u[:, 2], 0.05 + 0.01 * 0.2, atol=1e-12)
    np.testing.assert_allclose(u[:, 0], 0.1, atol=1e-12)


def test_freeze_repeats_then_jumps_back_to_the_truth() -> None:
    cfg = FaultConfig(freeze_every_scans=30)
    base, out = scans(), run("freeze", seed=2, cfg=cfg)
    u = steps(out)
    frozen = np.all(u == 0.0, axis=1)
    assert frozen.sum() >= 20
    # every run of frozen increments lasts 2..10 scans; off a freeze odometry is the truth
    runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], frozen.astype(int), [0]]))))[::2]
    assert runs.min() >= 2 and runs.max() <= 10
    moving = np.concatenate([[True], ~frozen])
    for r, b, m in zip(out, base, moving, strict=True):
        if m:
            np.testing.assert_allclose(r.odom_pose, b.odom_pose, atol=1e-9)


def test_thin_keeps_the_rate() -> None:
    t = np.array([r.stamp_s for r in run("thin", cfg=FaultConfig(thin_rate_hz=1.5))])
    assert np.diff(t).min() >= 1 / 1.5 - 1e-12 and np.diff(t).max() <= 1 / 1.5 + 0.2 + 1e-12


def test_thin_phase_follows_the_seed() -> None:
    """The first kept scan lies within one period of the log's first scan, and which scans
    are kept depends on the seed (the same seed: the same scans)."""
    t0 = scans()[0].stamp_s
    firsts = set()
    for seed in range(6):
        t = [r.stamp_s for r in run("thin", seed=seed, cfg=FaultConfig(thin_rate_hz=1.5))]
        assert t0 <= t[0] < t0 + 1 / 1.5 + 0.2
        assert t == [r.stamp_s for r in run("thin", seed=seed, cfg=FaultConfig(thin_rate_hz=1.5))]
        firsts.add(t[0])
    assert len(firsts) >= 3


def test_drop_loses_about_the_fraction() -> None:
    kept = len(run("drop", cfg=FaultConfig(drop_fraction=0.25)))
    assert 0.75 * 400 - 40 < kept < 0.75 * 400 + 40


def test_range_noise_keeps_no_returns_and_the_range_limits() -> None:
    out = run("range-noise", cfg=FaultConfig(range_noise_m=0.5))
    r = np.array([x.ranges for x in out])
    assert np.all(np.isinf(r[:, 2])) and np.all(np.isfinite(np.delete(r, 2, axis=1)))
    noise = np.delete(r, 2, axis=1) - np.delete(scans()[0].ranges, 2)
    assert noise.std() == pytest.approx(0.5, rel=0.1) and r[np.isfinite(r)].min() >= 0.0


def test_bad_fault_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="drop_fraction"):
        FaultConfig(drop_fraction=1.0)
    with pytest.raises(ValueError, match="freeze scans"):
        FaultConfig(freeze_min_scans=5, freeze_max_scans=2)
    with pytest.raises(ValueError):
        list(apply_fault(scans(3), "melt", np.random.default_rng(0)))
    assert math.isfinite(FaultConfig().heading_bias_rad_per_s)


def turning_scans() -> list[LaserScan]:
    """Straight 0.1 m a scan for 30 scans, then a 90 deg turn on the spot in 9 scans of
    10 deg, and so on: 10 such legs (a square path driven 2.5 times)."""
    pose = np.array([0.0, 0.0, 0.0])
    out = []
    for leg in range(10):
        for k in range(39):
            t = (leg * 39 + k) * 0.2
            out.append(LaserScan(t, -1.0, 0.5, 0.0, 80.0, np.ones(5), np.zeros(3), pose))
            u = [0.1, 0.0, 0.0] if k < 30 else [0.0, 0.0, math.radians(10.0)]
            pose = compose(pose, np.array(u))
    return out


def test_freeze_turn_freezes_on_turns_and_jumps_by_the_turn() -> None:
    base = turning_scans()
    cfg = FaultConfig(freeze_every_scans=20)
    out = list(apply_fault(base, "freeze-turn", np.random.default_rng(3), cfg))
    u = steps(out)
    frozen = np.all(u == 0.0, axis=1)
    starts = np.flatnonzero(np.diff(np.concatenate([[0], frozen.astype(int)])) == 1)
    assert len(starts) >= 3
    for s in starts:
        end = s + int(np.argmin(frozen[s:])) if not frozen[s:].all() else len(frozen)
        if end == len(frozen):
            continue
        # the jump after the freeze turns by 45-90 deg (in 10 deg steps: 50-90), the
        # freeze lasts at most 9 scans, and odometry is the truth again after it
        assert math.radians(49.0) <= abs(u[end, 2]) <= math.radians(91.0)
        assert 1 <= end - s <= 9
        np.testing.assert_allclose(out[end + 1].odom_pose, base[end + 1].odom_pose, atol=1e-9)
    moving = np.concatenate([[True], ~frozen])
    for r, b, m in zip(out, base, moving, strict=True):
        if m:
            np.testing.assert_allclose(r.odom_pose, b.odom_pose, atol=1e-9)


def test_sparse_is_regular_and_long_loop_drifts_by_the_distance() -> None:
    # the constant-motion log: the mean of equal increments is the increment itself
    log = scans(rate_hz=4.0)  # stamps exact in binary: 1 Hz keeps every 4th scan

    def faulty(fault: str, cfg: FaultConfig | None = None) -> list[LaserScan]:
        return list(apply_fault(log, fault, np.random.default_rng(0), cfg))

    t = [r.stamp_s for r in faulty("sparse")]
    np.testing.assert_array_equal(np.diff(t), 1.0)
    u = steps(faulty("sparse"))  # 4 scans a kept step: 0.4 m and 0.2 rad
    true = compose_n(np.array([0.1, 0.0, 0.05]), 4)
    np.testing.assert_allclose(u, np.tile(true, (len(u), 1)), atol=1e-12)
    cfg = FaultConfig(drift_rad_per_m=0.02)
    d = steps(faulty("long-loop", cfg))
    np.testing.assert_allclose(d[:, 2] - true[2], 0.02 * math.hypot(true[0], true[1]), atol=1e-12)
    # on the square path the smoothed odometry lags each turn by its smoothing and catches up
    sq = list(apply_fault(turning_scans(), "sparse", np.random.default_rng(0), FaultConfig()))
    o = np.array([r.odom_pose for r in sq])
    truth = {r.stamp_s: r.odom_pose for r in turning_scans()}
    tr = np.array([truth[r.stamp_s] for r in sq])
    dth = np.abs(np.angle(np.exp(1j * (o[:, 2] - tr[:, 2]))))
    assert dth.max() > math.radians(20.0)  # it lags on the turns
    assert dth[-1] < 1e-9 or dth.max() < math.pi  # and its heading error stays bounded
    assert np.median(dth) < math.radians(1.0)


def compose_n(u: np.ndarray, n: int) -> np.ndarray:
    p = np.zeros(3)
    for _ in range(n):
        p = compose(p, u)
    return p
