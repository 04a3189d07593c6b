"""Pose-graph optimiser: hand-worked optima, noise-free recovery, Jacobians, robust kernels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.posegraph import (
    IterationInfo,
    PoseGraph,
    RobustKernel,
    _errors_jacobians,
    chi2,
    edge_errors,
    optimize,
)
from agvsim.slam.posegraph_init import odometry_chain_poses, spanning_tree_poses
from agvsim.slam.se2 import between, compose, wrap_angle

EYE = np.eye(3)


def square_graph(delta_m: float, heading_info: float) -> PoseGraph:
    """4 nodes, edges i -> i+1 (mod 4) each 'forward 1 m, turn left 90 deg'; the closing edge
    3 -> 0 says 1 + delta_m.

    Hand-worked optimum with stiff headings: the edges keep their world directions, so the
    problem is linear in the positions. The measured world displacements (1, 0), (0, 1),
    (-1, 0), (0, -1 - delta) leave a gap g = (0, -delta) around the cycle; with equal isotropic
    information each of the 4 edges absorbs -g/4, so every edge's error is delta/4 and
    chi2 = 4 (delta/4)^2 = delta^2 / 4. Poses: (0, 0), (1, delta/4), (1, 1 + delta/2),
    (0, 1 + 3 delta/4)."""
    g = PoseGraph()
    g.add_nodes([[0.0, 0.0, 0.0], [1.1, 0.2, 1.4], [0.8, 1.3, 3.0], [0.1, 0.9, -1.7]])
    info = np.diag([1.0, 1.0, heading_info])
    for k in range(4):
        length = 1.0 + (delta_m if k == 3 else 0.0)
        g.add_edge(k, (k + 1) % 4, [length, 0.0, math.pi / 2], info)
    return g


def test_square_with_inconsistent_loop_hand_worked() -> None:
    g = square_graph(0.2, heading_info=1e10)
    res = optimize(g)
    assert res.converged
    expected = np.array(
        [[0, 0, 0], [1, 0.05, math.pi / 2], [1, 1.1, math.pi], [0, 1.15, -math.pi / 2]]
    )
    np.testing.assert_allclose(res.poses[:, :2], expected[:, :2], atol=1e-6)
    np.testing.assert_allclose(wrap_angle(res.poses[:, 2] - expected[:, 2]), 0, atol=1e-6)
    assert res.chi2_final == pytest.approx(0.01, rel=1e-4)
    assert res.chi2_initial > res.chi2_final
    assert chi2(g, res.poses) == pytest.approx(res.chi2_final)
    np.testing.assert_array_equal(g.poses[1], [1.1, 0.2, 1.4])  # input left untouched
    # soft headings let the square bend: strictly better than the stiff optimum
    soft = square_graph(0.2, heading_info=1.0)
    assert optimize(soft).chi2_final < chi2(soft, expected) - 1e-3


def test_collinear_chain_in_tension_hand_worked() -> None:
    # x1, x2 minimise (x1 - 1)^2 + (x2 - x1 - 1)^2 + (x2 - 2.3)^2: x1 = 1.1, x2 = 2.2, chi2 = 0.03
    g = PoseGraph.from_arrays(
        [[0.0, 0.0, 0.0], [0.7, 0.3, 0.2], [2.5, -0.2, -0.3]],
        [0, 1, 0],
        [1, 2, 2],
        [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.3, 0.0, 0.0]],
        EYE,
    )
    res = optimize(g)
    expected = np.array([[0.0, 0.0, 0.0], [1.1, 0.0, 0.0], [2.2, 0.0, 0.0]])
    np.testing.assert_allclose(res.poses, expected, atol=1e-6)
    assert res.chi2_final == pytest.approx(0.03, rel=1e-9)


def test_two_weighted_measurements_average() -> None:
    # x1 minimises 1 (x - 1)^2 + 3 (x - 1.2)^2: x = 1.15, chi2 = 0.0225 + 0.0075
    g = PoseGraph.from_arrays(
        [[0, 0, 0], [0, 0, 0]],
        [0, 0],
        [1, 1],
        [[1.0, 0, 0], [1.2, 0, 0]],
        [EYE, 3 * EYE],
    )
    res = optimize(g)
    np.testing.assert_allclose(res.poses[1], [1.15, 0, 0], atol=1e-9)
    assert res.chi2_final == pytest.approx(0.03, rel=1e-9)


def random_graph(
    rng: np.random.Generator, n: int = 40, loops: int = 25
) -> tuple[PoseGraph, np.ndarray]:
    """A noise-free graph: random walk ground truth, odometry plus random loop edges; the
    poses start perturbed (node 0 exact)."""
    steps = np.column_stack(
        [rng.uniform(0.5, 1.5, n - 1), rng.uniform(-0.3, 0.3, n - 1), rng.uniform(-1.0, 1.0, n - 1)]
    )
    truth = np.zeros((n, 3))
    for k in range(n - 1):
        truth[k + 1] = compose(truth[k], steps[k])
    i = np.concatenate([np.arange(n - 1), rng.integers(0, n, loops)])
    j = np.concatenate([np.arange(1, n), rng.integers(0, n, loops)])
    keep = i != j
    i, j = i[keep], j[keep]
    start = truth + rng.normal(0, [0.3, 0.3, 0.15], truth.shape)
    start[0] = truth[0]
    info = np.stack([np.diag(rng.uniform(1, 100, 3)) for _ in i])
    return PoseGraph.from_arrays(start, i, j, between(truth[i], truth[j]), info), truth


def test_noise_free_graph_recovers_truth() -> None:
    g, truth = random_graph(np.random.default_rng(1))
    reports: list[IterationInfo] = []
    res = optimize(g, verbose=reports.append)
    assert res.converged and res.chi2_final < 1e-14 and res.chi2_initial > 1.0
    np.testing.assert_allclose(res.poses[:, :2], truth[:, :2], atol=1e-7)
    np.testing.assert_allclose(wrap_angle(res.poses[:, 2] - truth[:, 2]), 0, atol=1e-7)
    assert len(reports) == res.iterations and reports[-1].chi2 == pytest.approx(res.chi2_final)


def test_jacobians_match_finite_differences() -> None:
    g, _ = random_graph(np.random.default_rng(2), n=8, loops=6)
    _, a, b = _errors_jacobians(g.poses, g.edge_i, g.edge_j, g.measurements, True)
    h = 1e-6
    for node_of_edge, jac in ((g.edge_i, a), (g.edge_j, b)):
        for c in range(3):
            num = np.empty((g.n_edges, 3))
            for k in range(g.n_edges):
                plus, minus = g.poses.copy(), g.poses.copy()
                plus[node_of_edge[k], c] += h
                minus[node_of_edge[k], c] -= h
                d = edge_errors(g, plus)[k] - edge_errors(g, minus)[k]
                d[2] = wrap_angle(d[2])
                num[k] = d / (2 * h)
            np.testing.assert_allclose(jac[:, :, c], num, atol=1e-6)


def test_fixed_nodes_stay_put() -> None:
    g, truth = random_graph(np.random.default_rng(3))
    res = optimize(g, fixed=(0, 5))
    np.testing.assert_array_equal(res.poses[[0, 5]], g.poses[[0, 5]])
    with pytest.raises(ValueError, match="fixed node"):
        optimize(g, fixed=(99,))


def test_robust_kernels_reject_an_outlier() -> None:
    g, truth = random_graph(np.random.default_rng(4))
    g.add_edge(3, 30, [5.0, -4.0, 2.0], 100 * EYE)  # a wrong loop closure
    err = {}
    for kernel in RobustKernel:
        res = optimize(g, robust=kernel, robust_scale=1.0, max_iterations=200)
        err[kernel] = np.abs(res.poses[:, :2] - truth[:, :2]).max()
        assert res.cost_final <= res.cost_initial
    assert err[RobustKernel.NONE] > 0.1
    assert err[RobustKernel.CAUCHY] < 1e-2 and err[RobustKernel.HUBER] < err[RobustKernel.NONE]
    with pytest.raises(ValueError):
        optimize(g, robust="tukey")


def test_incremental_building_and_validation() -> None:
    g = PoseGraph()
    for k in range(50):  # grows past the initial capacity
        assert g.add_node([k, 0, 0]) == k
        if k:
            g.add_edge(k - 1, k, [1, 0, 0], EYE)
    assert g.n_nodes == 50 and g.n_edges == 49 and g.information.shape == (49, 3, 3)
    assert chi2(g) == pytest.approx(0.0)
    with pytest.raises(ValueError, match="node indices"):
        g.add_edge(0, 50, [1, 0, 0], EYE)
    with pytest.raises(ValueError, match="shape"):
        g.poses = np.zeros((3, 3))
    c = g.copy()
    c.poses = np.zeros((50, 3))
    assert g.poses[10, 0] == 10.0


def test_chain_and_tree_initialisation_agree() -> None:
    g, truth = random_graph(np.random.default_rng(5), n=12, loops=0)
    chain = odometry_chain_poses(g.n_nodes, g.edge_i, g.edge_j, g.measurements)
    tree = spanning_tree_poses(g.n_nodes, g.edge_i, g.edge_j, g.measurements)
    assert chain is not None
    np.testing.assert_allclose(chain[:, :2], truth[:, :2], atol=1e-9)
    np.testing.assert_allclose(tree[:, :2], truth[:, :2], atol=1e-9)
    # a reversed edge breaks the forward chain lookup only if absent: flip one and drop it
    assert odometry_chain_poses(g.n_nodes, g.edge_i[1:], g.edge_j[1:], g.measurements[1:]) is None


@pytest.mark.skipif(datasets_dir() is None, reason="datasets folder absent")
def test_intel_converges_to_known_optimum() -> None:
    from agvsim.slam.g2o import load_g2o

    root = datasets_dir()
    assert root is not None
    g = load_g2o(root / "posegraphs" / "intel.g2o")
    res = optimize(g)
    assert res.converged
    assert res.chi2_final == pytest.approx(45.0047, rel=1e-3)
