"""Returns mapped as the mean of their neighbours on the same surface (``smooth_surface``,
``TrackingConfig.smooth_beams``): exact on straight walls, corners and gaps left alone, range
noise cut by sqrt(3)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from agvsim.slam.frontend import Tracker, TrackingConfig, smooth_surface


def _wall_scan(ranges_noise: np.ndarray | None = None, n: int = 61) -> np.ndarray:
    """Returns of beams every 1 deg from -30 to +30 deg onto the wall x = 2 m, seen from the
    origin (uneven spacing along the wall: 1/cos)."""
    a = np.radians(np.linspace(-30.0, 30.0, n))
    r = 2.0 / np.cos(a)
    if ranges_noise is not None:
        r = r + ranges_noise
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def test_returns_on_a_straight_wall_stay_on_it():
    ends = _wall_scan()
    hits = np.ones(len(ends), bool)
    out = smooth_surface(ends, hits, 0.5, 1, 0.1)
    np.testing.assert_allclose(out[:, 0], 2.0, atol=1e-12)  # on the wall, to rounding
    # every inner point moved along the wall, by the mean of its neighbours' spacing
    k = 20
    assert out[k, 1] == pytest.approx(ends[k - 1 : k + 2, 1].mean(), abs=1e-12)
    # the two end returns have no neighbour on one side: as measured
    np.testing.assert_array_equal(out[[0, -1]], ends[[0, -1]])


def test_range_noise_is_cut_by_the_square_root_of_three():
    rng = np.random.default_rng(7)
    noise = rng.normal(0.0, 0.03, 4001)
    ends = _wall_scan(noise, n=4001)  # 0.015 deg apart: the wall's tilt under the noise
    hits = np.ones(len(ends), bool)
    out = smooth_surface(ends, hits, 0.5, 1, 0.2)
    raw = ends[1:-1, 0] - 2.0
    mean3 = out[1:-1, 0] - 2.0
    # the mean of three independent errors: sigma / sqrt(3) (0.577 of it)
    assert mean3.std() / raw.std() == pytest.approx(1.0 / math.sqrt(3.0), rel=0.05)


def test_a_right_angle_corner_is_mapped_as_seen():
    # returns along y = 1 (x = -0.5 .. 0) then along x = 0 (y = 1 .. 0.5), 5 cm apart: the
    # corner (0, 1) lies 0.035 m off the chord of its neighbours, farther than 0.02 m
    a = np.array([[x, 1.0] for x in np.arange(-0.5, 0.0, 0.05)] + [[0.0, 1.0]])
    b = np.array([[0.0, y] for y in np.arange(0.95, 0.45, -0.05)])
    ends = np.concatenate([a, b])
    hits = np.ones(len(ends), bool)
    k = len(a) - 1
    out = smooth_surface(ends, hits, 0.5, 1, 0.02)
    np.testing.assert_array_equal(out[k], ends[k])
    # ... and with a bound beyond 0.035 m it is averaged into the room: the mean of
    # (-0.05, 1), (0, 1), (0, 0.95)
    out = smooth_surface(ends, hits, 0.5, 1, 0.05)
    np.testing.assert_allclose(out[k], [-0.05 / 3, 2.95 / 3], atol=1e-12)


def test_gaps_misses_and_wider_runs():
    ends = _wall_scan()
    hits = np.ones(len(ends), bool)
    hits[10] = False  # a miss: itself untouched, and its neighbours have no run through it
    far = ends.copy()
    far[30:, 1] += 1.0  # a 1 m jump between returns 29 and 30: two surfaces
    out = smooth_surface(far, hits, 0.5, 1, 0.1)
    for k in (9, 10, 11, 29, 30):
        np.testing.assert_array_equal(out[k], far[k])
    assert not np.array_equal(out[12], far[12])
    # two beams a side where the run allows it, one next to the miss
    out2 = smooth_surface(ends, hits, 0.5, 2, 0.1)
    assert out2[20, 1] == pytest.approx(ends[18:23, 1].mean(), abs=1e-12)
    assert out2[12, 1] == pytest.approx(ends[11:14, 1].mean(), abs=1e-12)
    np.testing.assert_allclose(out2[hits, 0], 2.0, atol=1e-12)


def test_the_submap_maps_the_smoothed_returns_and_zero_turns_it_off():
    rng = np.random.default_rng(3)
    ends = _wall_scan(rng.normal(0.0, 0.04, 61))
    hits = np.ones(len(ends), bool)

    def off_the_wall_m(cfg: TrackingConfig) -> float:
        cfg = dataclasses.replace(cfg, submap_half_size_m=5.0, resolution_m=0.01)
        tracker = Tracker(cfg)
        tracker.insert(0, np.zeros(3), np.zeros(2), ends, hits)
        s = tracker.submaps[0]
        cells = np.argwhere(s.logodds > 0)
        x = s.ox + (cells[:, 1] + 0.5) * cfg.resolution_m  # the occupied cells' centres
        return float(np.abs(x - 2.0).mean())

    raw = off_the_wall_m(TrackingConfig(smooth_beams=0))
    smoothed = off_the_wall_m(TrackingConfig(smooth_beams=1))
    assert smoothed < 0.8 * raw  # 0.0307 against 0.0220 m, measured


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("smooth_beams", -1, ">= 0"),
        ("smooth_beams", 1.5, "whole number"),
        ("smooth_dev_m", 0.0, "positive"),
    ],
)
def test_bad_values_are_refused_by_name(field, value, allowed):
    with pytest.raises(ValueError, match=f"TrackingConfig.{field} must be .*{allowed}"):
        TrackingConfig(**{field: value})
