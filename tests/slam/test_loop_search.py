"""Loop-closure search bounds from the uncertainty accumulated along the keyframe chain."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.slam.loop_closure import (
    LoopConfig,
    TiePlaces,
    drift_bounds,
    step_variances,
    tie_places,
)
from agvsim.slam.se2 import between, compose


def test_drift_bounds_by_hand() -> None:
    """Four keyframes 1 m apart along x; every step adds var_t = 0.01 per axis and var_r =
    0.001. Relative to node 3 (x = 3): step 1 (to x = 1) adds 2 * 0.01 + 0.001 * 2^2 = 0.024,
    step 2 adds 0.021, step 3 (lever 0) 0.02. So var_xy = 0.065, 0.041, 0.02, 0 for
    k = 0..3 and var_th = 0.003, 0.002, 0.001, 0; bounds are 2 std."""
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    var_t = np.array([0.0, 0.01, 0.01, 0.01])
    var_r = np.array([0.0, 0.001, 0.001, 0.001])
    b_m, b_rad = drift_bounds(xy, var_t, var_r, 3, 2.0)
    np.testing.assert_allclose(b_m, 2 * np.sqrt([0.065, 0.041, 0.02, 0.0]), rtol=1e-12)
    np.testing.assert_allclose(b_rad, 2 * np.sqrt([0.003, 0.002, 0.001, 0.0]), rtol=1e-12)


def test_a_closure_holds_only_what_its_route_reaches() -> None:
    """Six keyframes 1 m apart along x, the same steps as above. A closure at node 5 onto
    keyframe 2 (a submap there) makes keyframe 2 free to reach; keyframe 0 is then two steps
    of chain beyond it, k = 1 one step, k = 3 one step either way, k = 4 is cheaper along the
    chain from 5 (its lever is 0) than back from 2. The old rule gave every keyframe before
    the closure the closure's bound, 0 here.

    Costs relative to node 5 (x = 5), step j adds 0.02 + 0.001 * (5 - j)^2 in position, 0.001
    in heading: steps 1..5 cost 0.036, 0.029, 0.024, 0.021, 0.02. So var_xy = 0.065 (k = 0:
    steps 1 and 2), 0.029 (k = 1: step 2), 0 (k = 2), min(0.024, 0.02 + 0.021) = 0.024
    (k = 3, step 3 from keyframe 2), 0.02 (k = 4: step 5 from node 5), 0; var_th = 0.002,
    0.001, 0, 0.001, 0.001, 0."""
    xy = np.column_stack([np.arange(6.0), np.zeros(6)])
    var_t = np.array([0.0] + [0.01] * 5)
    var_r = np.array([0.0] + [0.001] * 5)
    b_m, b_rad = drift_bounds(xy, var_t, var_r, 5, 1.0, tie_places(np.array([[5, 2]]), 6))
    np.testing.assert_allclose(b_m**2, [0.065, 0.029, 0.0, 0.024, 0.02, 0.0], atol=1e-12)
    np.testing.assert_allclose(b_rad**2, [0.002, 0.001, 0.0, 0.001, 0.001, 0.0], atol=1e-12)
    # a tie of a keyframe to itself changes nothing (but the order of the sums)
    b2_m, b2_rad = drift_bounds(xy, var_t, var_r, 4, 1.0, tie_places(np.array([[3, 3]]), 6))
    n_m, n_rad = drift_bounds(xy, var_t, var_r, 4, 1.0)
    np.testing.assert_allclose(b2_m, n_m, rtol=1e-12)
    np.testing.assert_allclose(b2_rad, n_rad, rtol=1e-12)


def reference_routes(add: np.ndarray, node: int, ties: np.ndarray) -> np.ndarray:
    """Dijkstra over every keyframe (a heap, no shortcuts): chain step j joins j - 1 and j at
    cost add[j], a tie joins its pair at no cost."""
    adj: dict[int, list[tuple[int, float]]] = {k: [] for k in range(node + 1)}
    for j in range(1, node + 1):
        adj[j - 1].append((j, float(add[j])))
        adj[j].append((j - 1, float(add[j])))
    for a, b in ties:
        if a <= node and b <= node:
            adj[int(a)].append((int(b), 0.0))
            adj[int(b)].append((int(a), 0.0))
    dist = [math.inf] * (node + 1)
    dist[node] = 0.0
    heap = [(0.0, node)]
    while heap:
        d, u = heapq.heappop(heap)
        if d > dist[u]:
            continue
        for v, w in adj[u]:
            if d + w < dist[v]:
                dist[v] = d + w
                heapq.heappush(heap, (d + w, v))
    return np.array(dist)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 60), m=st.integers(0, 12))
def test_routes_match_a_search_over_every_keyframe(seed: int, n: int, m: int) -> None:
    """The search over the ties' keyframes alone gives the cheapest route over every keyframe;
    ties only ever shorten routes, and without ties every bound is the whole chain's."""
    rng = np.random.default_rng(seed)
    xy = np.cumsum(rng.normal(size=(n + 1, 2)), axis=0)
    var_t = np.concatenate([[0.0], rng.uniform(0.0, 0.01, n)])
    var_r = np.concatenate([[0.0], rng.uniform(0.0, 0.001, n)])
    ties = rng.integers(0, n + 1, size=(m, 2))
    places = tie_places(ties, n + 1)
    b_m, b_rad = drift_bounds(xy, var_t, var_r, n, 1.0, places)
    lever2 = np.sum((xy - xy[n]) ** 2, axis=1)
    np.testing.assert_allclose(
        b_m**2, reference_routes(2 * var_t + var_r * lever2, n, ties), rtol=1e-9, atol=1e-12
    )
    np.testing.assert_allclose(b_rad**2, reference_routes(var_r, n, ties), rtol=1e-9, atol=1e-12)
    n_m, n_rad = drift_bounds(xy, var_t, var_r, n, 1.0)
    assert np.all(b_m <= n_m + 1e-12) and np.all(b_rad <= n_rad + 1e-12)
    # the places kept up to date one tie at a time are the same
    live = TiePlaces()
    live.grow(n + 1)
    for a, b in ties:
        live.tie(int(a), int(b))
    np.testing.assert_array_equal(live.place[: n + 1], places)


def test_tie_places_name_bad_ties() -> None:
    with pytest.raises(ValueError, match=r"keyframes 0\.\.4"):
        tie_places(np.array([[1, 5]]), 5)


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
    b_m, b_rad = drift_bounds(poses[:, :2], var[:, 0], var[:, 1], n, 1.0)
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
