"""Reflector navigation: intensities on the reflector's beams, detection, association,
triangulation from exact geometry, and a filter that bounds the odometry's drift (and does
not where a layout leaves a blind spot)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.sensors.reflectors import (
    REFLECTOR_INTENSITY,
    Detection,
    ReflectorEkf,
    ReflectorMap,
    associate,
    detect,
    intensities,
    triangulate,
)


def wall_scan(n: int = 721) -> tuple[np.ndarray, np.ndarray]:
    """A 180 deg scan from the origin facing +x of a flat wall at x = 2 m."""
    a = np.linspace(-math.pi / 2 + 0.01, math.pi / 2 - 0.01, n)
    return 2.0 / np.cos(a), a


def test_beams_on_the_reflector_read_bright_and_the_rest_diffuse():
    r, a = wall_scan()
    refl = ReflectorMap(np.array([[2.0, 0.5]]), width_m=0.08)
    inten = intensities(np.zeros(3), r, a, (0.0, 0.0), 0.0, refl)
    hit_y = r * np.sin(a)
    bright = np.abs(hit_y - 0.5) <= 0.04
    assert bright.sum() >= 3
    np.testing.assert_array_equal(inten == REFLECTOR_INTENSITY, bright)
    assert (inten[~bright] < REFLECTOR_INTENSITY / 2).all()
    # no return: 0
    r2 = r.copy()
    r2[:10] = np.inf
    assert (intensities(np.zeros(3), r2, a, (0.0, 0.0), 0.0, refl)[:10] == 0).all()


def test_detection_gives_the_reflector_range_and_bearing():
    r, a = wall_scan(1441)
    refl = ReflectorMap(np.array([[2.0, 0.5], [2.0, -1.0]]), width_m=0.08)
    dets = detect(r, intensities(np.zeros(3), r, a, (0.0, 0.0), 0.0, refl), a)
    assert len(dets) == 2
    got = sorted((d.bearing_rad, d.range_m) for d in dets)
    for (b, rng), (x, y) in zip(got, [(2.0, -1.0), (2.0, 0.5)], strict=True):
        assert b == pytest.approx(math.atan2(y, x), abs=2e-3)
        assert rng == pytest.approx(math.hypot(x, y), abs=5e-3)


def test_a_run_across_the_ends_of_a_full_circle_scan_is_one_reflector():
    n = 360
    a = -math.pi + np.arange(n) * 2 * math.pi / n
    r = np.full(n, 3.0)
    inten = np.zeros(n)
    inten[[0, 1, n - 2, n - 1]] = REFLECTOR_INTENSITY  # straight behind
    (d,) = detect(r, inten, a)
    assert d.beams == 4
    assert abs(abs(d.bearing_rad) - math.pi) < 0.02


def _exact(pose: np.ndarray, xy: np.ndarray) -> list[Detection]:
    out = []
    for x, y in xy:
        dx, dy = x - pose[0], y - pose[1]
        b = math.atan2(dy, dx) - pose[2]
        out.append(Detection(math.hypot(dx, dy), math.atan2(math.sin(b), math.cos(b)), 3))
    return out


def test_triangulation_recovers_the_pose_from_three_reflectors():
    refl = ReflectorMap(np.array([[0.0, 5.0], [6.0, 4.0], [5.0, -3.0], [-4.0, -2.0]]))
    truth = np.array([1.2, 0.7, 0.4])
    dets = _exact(truth, refl.xy[:3])
    matches = list(zip(dets, range(3), strict=True))
    got = triangulate(matches, refl, truth + [0.4, -0.3, 0.2])
    np.testing.assert_allclose(got, truth, atol=1e-9)
    assert triangulate(matches[:2], refl, truth) is None  # two are not enough
    # association from a rough pose finds the same reflectors
    pairs = associate(truth + [0.1, 0.1, 0.02], _exact(truth, refl.xy), refl, gate_m=0.5)
    assert [k for _, k in pairs] == [0, 1, 2, 3]


def _drive(refl: ReflectorMap, seed: int, steps: int = 1500, visible_m: float = 8.0):
    """A robot circling (radius 3 m around (0, 0)); odometry with a 3 % scale error and noise;
    reflectors seen within ``visible_m`` with range and bearing noise. Returns the filter's and
    the odometry's position errors along the way."""
    rng = np.random.default_rng(seed)
    dt, v, w = 0.05, 0.6, 0.2
    truth = np.array([3.0, 0.0, math.pi / 2])
    odo = truth.copy()
    ekf = ReflectorEkf(refl, truth.copy())
    err_f, err_o = [], []
    for _ in range(steps):
        d_true = np.array([v * dt, 0.0, w * dt])
        th = truth[2]
        truth = truth + [v * dt * math.cos(th), v * dt * math.sin(th), w * dt]
        d_meas = d_true * [1.03, 1.0, 1.03] + rng.normal(0, [0.002, 0.0005, 0.002])
        c, s = math.cos(odo[2]), math.sin(odo[2])
        odo = odo + [c * d_meas[0], s * d_meas[0], d_meas[2]]
        ekf.predict(d_meas)
        near = refl.xy[np.hypot(*(refl.xy - truth[:2]).T) <= visible_m]
        dets = [
            Detection(d.range_m + rng.normal(0, 0.01), d.bearing_rad + rng.normal(0, 0.003), 3)
            for d in _exact(truth, near)
        ]
        ekf.correct(dets)
        err_f.append(math.hypot(*(ekf.pose[:2] - truth[:2])))
        err_o.append(math.hypot(*(odo[:2] - truth[:2])))
    return np.array(err_f), np.array(err_o)


RING = ReflectorMap(
    np.array([[6 * math.cos(a), 6 * math.sin(a)] for a in np.linspace(0, 2 * math.pi, 8, False)])
)


def test_the_filter_bounds_the_odometry_drift():
    err_f, err_o = _drive(RING, seed=1)
    assert err_o.max() > 0.5  # odometry alone drifts away
    assert err_f.max() < 0.05  # the reflectors hold the estimate
    assert np.median(err_f) < 0.02


def test_a_blind_spot_shows_in_the_error():
    # only reflectors on the right half: on the left half of the circle, too few are in view
    half = ReflectorMap(RING.xy[RING.xy[:, 0] > 0.5])
    err_full, _ = _drive(RING, seed=2, visible_m=5.0)
    err_half, _ = _drive(half, seed=2, visible_m=5.0)
    assert err_half.max() > 3 * err_full.max()
