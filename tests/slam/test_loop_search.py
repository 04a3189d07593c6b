"""Loop-closure search bounds from the uncertainty accumulated along the keyframe chain."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.slam.loop_closure import LoopConfig, drift_bounds, step_variances
from agvsim.slam.se2 import between, compose


def test_drift_bounds_by_hand() -> None:
    """Four keyframes 1 m apart along x; every step adds var_t = 0.01 per axis and var_r =
    0.001. Relative to node 3 (x = 3): step 1 (to x = 1) adds 2 * 0.01 + 0.001 * 2^2 = 0.024,
    step 2 adds 0.021, step 3 (lever 0) 0.02. So var_xy = 0.065, 0.041, 0.02, 0 for
    k = 0..3 and var_th = 0.003, 0.002, 0.001, 0; bounds are 2 std."""
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    var_t = np.array([0.0, 0.01, 0.01, 0.01])
    var_r = np.array([0.0, 0.001, 0.001, 0.001])
    b_m, b_rad = drift_bounds(xy, var_t, var_r, 3, 0, 2.0)
    np.testing.assert_allclose(b_m, 2 * np.sqrt([0.065, 0.041, 0.02, 0.0]), rtol=1e-12)
    np.testing.assert_allclose(b_rad, 2 * np.sqrt([0.003, 0.002, 0.001, 0.0]), rtol=1e-12)
    # a closure accepted at node 2 holds the graph there: older keyframes share its bound
    b_m, b_rad = drift_bounds(xy, var_t, var_r, 3, 2, 2.0)
    np.testing.assert_allclose(b_m, 2 * np.sqrt([0.02, 0.02, 0.02, 0.0]), rtol=1e-12)
    np.testing.assert_allclose(b_rad, 2 * np.sqrt([0.001, 0.001, 0.001, 0.0]), rtol=1e-12)


def test_step_variances_grow_with_distance_and_turn() -> None:
    cfg = LoopConfig(drift_m_per_sqrt_m=0.1, drift_rad_per_sqrt_m=0.02, drift_rad_per_sqrt_rad=0.05)
    v_t, v_r = step_variances(cfg, np.array([3.0, 4.0, -0.5]))  # 5 m, half a radian
    assert v_t == pytest.approx(0.01 * 5.0)
    assert v_r == pytest.approx(0.0004 * 5.0 + 0.0025 * 0.5)


def chain(steps: np.ndarray) -> np.ndarray:
    poses = [np.zeros(3)]
    for s in steps:
        poses.append(compose(poses[-1], s))
    return np.array(poses)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 40))
def test_drift_bound_matches_monte_carlo_spread(seed: int, n: int) -> None:
    """The propagated position spread is first-order exact: perturbing each step by its
    (small) random walk, the mean squared displacement of the last keyframe relative to the
    first, over many samples, matches var_xy(0) to within sampling error."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack(
        [rng.uniform(0.1, 2.0, n), rng.uniform(-0.5, 0.5, n), rng.uniform(-1.0, 1.0, n)]
    )
    cfg = LoopConfig(drift_m_per_sqrt_m=0.002, drift_rad_per_sqrt_m=0.0005)
    var = np.array([(0.0, 0.0)] + [step_variances(cfg, s) for s in steps])
    poses = chain(steps)
    b_m, b_rad = drift_bounds(poses[:, :2], var[:, 0], var[:, 1], n, 0, 1.0)
    samples = 4000
    noise = rng.normal(size=(samples, n, 3)) * np.sqrt(
        np.column_stack([var[1:, 0], var[1:, 0], var[1:, 1]])
    )
    ends = np.zeros((samples, 3))
    for k in range(n):  # every sample's chain at once
        ends = compose(ends, steps[k] + noise[:, k])
    rel = between(poses[-1], ends)
    d2 = np.mean(np.sum((ends[:, :2] - poses[-1, :2]) ** 2, axis=1))
    assert d2 == pytest.approx(b_m[0] ** 2, rel=0.12)
    assert np.mean(rel[:, 2] ** 2) == pytest.approx(b_rad[0] ** 2, rel=0.12)
    assert math.isfinite(b_m[0])
