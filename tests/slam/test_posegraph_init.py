"""Guess-free pose-graph initialisation (chordal relaxation + linear translations)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.posegraph import PoseGraph, chi2, initial_guess, optimize
from agvsim.slam.posegraph_init import chordal_poses, odometry_chain_poses
from agvsim.slam.se2 import between, compose, wrap_angle


def noise_free_graph(seed: int, n: int, loops: int) -> tuple[PoseGraph, np.ndarray]:
    """Random-walk truth (headings anywhere on the circle), odometry and random loop edges with
    exact measurements and anisotropic information; the poses start at random (node 0 exact)."""
    rng = np.random.default_rng(seed)
    steps = np.column_stack(
        [rng.uniform(-2, 2, n - 1), rng.uniform(-2, 2, n - 1), rng.uniform(-3, 3, n - 1)]
    )
    truth = np.zeros((n, 3))
    truth[0] = rng.uniform(-5, 5, 3)
    for k in range(n - 1):
        truth[k + 1] = compose(truth[k], steps[k])
    i = np.concatenate([np.arange(n - 1), rng.integers(0, n, loops)])
    j = np.concatenate([np.arange(1, n), rng.integers(0, n, loops)])
    keep = i != j
    i, j = i[keep], j[keep]
    a = rng.normal(size=(i.shape[0], 3, 3))
    info = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(3)  # symmetric positive definite
    start = rng.uniform(-20, 20, (n, 3))
    start[:, 2] = rng.uniform(-math.pi, math.pi, n)
    start[0] = truth[0]
    return PoseGraph.from_arrays(start, i, j, between(truth[i], truth[j]), info), truth


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30), loops=st.integers(0, 30))
def test_chordal_recovers_a_noise_free_graph_exactly(seed: int, n: int, loops: int) -> None:
    g, truth = noise_free_graph(seed, n, loops)
    p = chordal_poses(
        g.n_nodes, g.edge_i, g.edge_j, g.measurements, g.information, anchor_pose=truth[0]
    )
    assert p is not None
    np.testing.assert_allclose(p[:, :2], truth[:, :2], atol=1e-6)
    np.testing.assert_allclose(wrap_angle(p[:, 2] - truth[:, 2]), 0.0, atol=1e-8)


def test_chordal_heading_is_the_weighted_mean_of_unit_vectors() -> None:
    """Hand-worked: two edges 0 -> 1 saying 0 and 90 deg. With equal heading information the
    relaxed r_1 is the mean of (1, 0) and (0, 1), so th_1 = 45 deg; with weights 1 and 3 it is
    (1, 3) / 4, th_1 = atan2(3, 1). Translations: both edges say 'forward 2 m' from node 0 (at
    heading 0), so t_1 = (2, 0) whatever the weights."""
    z = np.array([[2.0, 0.0, 0.0], [2.0, 0.0, math.pi / 2]])
    for w2, expected in ((1.0, math.pi / 4), (3.0, math.atan2(3.0, 1.0))):
        info = np.stack([np.diag([1.0, 1.0, 1.0]), np.diag([1.0, 1.0, w2])])
        p = chordal_poses(2, np.array([0, 0]), np.array([1, 1]), z, info)
        assert p is not None
        assert p[1, 2] == pytest.approx(expected, abs=1e-12)
        np.testing.assert_allclose(p[1, :2], [2.0, 0.0], atol=1e-12)


def test_chordal_keeps_the_anchor_and_marks_unconnected_nodes() -> None:
    g, truth = noise_free_graph(3, 6, 4)
    # add two nodes joined only to each other: not connected to the anchor
    g.add_nodes([[1.0, 2.0, 0.3], [4.0, 5.0, -0.2]])
    g.add_edge(6, 7, [1.0, 0.0, 0.0], np.eye(3))
    anchor_pose = np.array([3.0, -1.0, 2.5])
    p = chordal_poses(g.n_nodes, g.edge_i, g.edge_j, g.measurements, g.information, 2, anchor_pose)
    assert p is not None
    np.testing.assert_allclose(p[2], anchor_pose, atol=1e-12)
    assert np.isnan(p[6:]).all() and not np.isnan(p[:6]).any()
    # relative geometry is the truth's
    np.testing.assert_allclose(between(p[2], p[:6]), between(truth[2], truth[:6]), atol=1e-6)
    # optimize's start keeps the given poses where chordal has none, and node 0 fixed
    start = initial_guess(g, "chordal")
    np.testing.assert_allclose(start[6:], g.poses[6:])
    np.testing.assert_allclose(start[0], g.poses[0])
    # an anchor without edges: nothing to relax
    lone = chordal_poses(3, np.array([1]), np.array([2]), np.zeros((1, 3)), np.eye(3)[None])
    assert lone is None


def test_random_start_reaches_the_optimum_only_with_a_guess_free_start() -> None:
    g, truth = noise_free_graph(11, 60, 40)
    res = optimize(g, initialisation="auto", max_iterations=50)
    assert res.converged and res.chi2_final < 1e-12 and res.chi2_initial > 1e3
    np.testing.assert_allclose(res.poses[:, :2], truth[:, :2], atol=1e-6)
    # the same graph from its random start alone ends in a local minimum
    plain = optimize(g, initialisation="given", max_iterations=50)
    assert plain.chi2_final > 1.0


def test_auto_keeps_a_better_given_start() -> None:
    """With noisy measurements the chordal start is near, not at, the optimum: a given start at
    the optimum has the lower chi2 and auto keeps it."""
    g, _ = noise_free_graph(4, 20, 15)
    rng = np.random.default_rng(0)
    noisy = PoseGraph.from_arrays(
        g.poses,
        g.edge_i,
        g.edge_j,
        g.measurements + rng.normal(0, 0.05, g.measurements.shape),
        g.information,
    )
    opt = optimize(noisy, initialisation="chordal").poses
    noisy.poses = opt
    np.testing.assert_array_equal(initial_guess(noisy, "auto"), opt)
    assert chi2(noisy, initial_guess(noisy, "chordal")) > chi2(noisy, opt)


KNOWN_OPTIMA = {"intel": 45.0047, "manhattan": 3549.04, "city10000": 511.985}


@pytest.mark.slow
@pytest.mark.skipif(datasets_dir() is None, reason="datasets folder absent")
@pytest.mark.parametrize("name", sorted(KNOWN_OPTIMA))
def test_benchmark_graphs_reach_their_optimum_from_any_start(name: str) -> None:
    """Stored guess, odometry chain and a random heading per pose: chi2 within 0.1 %."""
    from agvsim.slam.g2o import load_g2o

    root = datasets_dir()
    assert root is not None
    g = load_g2o(root / "posegraphs" / f"{name}.g2o")
    chain = odometry_chain_poses(g.n_nodes, g.edge_i, g.edge_j, g.measurements)
    assert chain is not None
    rotated = g.poses.copy()
    rotated[1:, 2] = np.random.default_rng(7).uniform(-math.pi, math.pi, g.n_nodes - 1)
    for start in (g.poses.copy(), chain, rotated):
        g.poses = start
        res = optimize(g, initialisation="auto")
        assert res.chi2_final == pytest.approx(KNOWN_OPTIMA[name], rel=1e-3)
