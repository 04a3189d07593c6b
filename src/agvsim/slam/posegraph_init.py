"""Initial guesses for pose graphs: odometry chain and spanning tree.

Graphs without vertices (``manhattan.g2o``) start from the chain of odometry edges
``i -> i + 1``: ``X_0 = 0``, ``X_{i+1} = X_i Z_{i,i+1}``, i.e. ``th_{i+1} = th_i + dth_i`` and
``t_{i+1} = t_i + R(th_i) dt_i`` (prefix sums, no Python loop). Where an edge of the chain is
missing, :func:`spanning_tree_poses` composes measurements along a breadth-first tree instead.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order

from agvsim.slam.se2 import compose, inverse, wrap_angle

__all__ = ["odometry_chain_poses", "spanning_tree_poses", "initial_poses"]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def odometry_chain_poses(n_nodes: int, edge_i: I64, edge_j: I64, measurements: F64) -> F64 | None:
    """Poses (N, 3) from the first edge ``i -> i + 1`` of every i (or ``i + 1 -> i``, inverted);
    ``None`` if some consecutive pair has no edge."""
    step = np.full((max(n_nodes - 1, 0), 3), np.nan)
    for ii, jj, z in ((edge_i, edge_j, measurements), (edge_j, edge_i, inverse(measurements))):
        fwd = jj == ii + 1
        # reversed so that the first edge of each i is the one that sticks
        idx, rel = ii[fwd][::-1], z[fwd][::-1]
        unset = np.isnan(step[idx, 0])
        step[idx[unset]] = rel[unset]
    if n_nodes > 1 and np.isnan(step).any():
        return None
    poses = np.zeros((n_nodes, 3))
    if n_nodes <= 1:
        return poses
    th = np.concatenate([[0.0], np.cumsum(step[:, 2])])  # unwrapped heading of nodes 0..N-1
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    poses[1:, 0] = np.cumsum(c * step[:, 0] - s * step[:, 1])
    poses[1:, 1] = np.cumsum(s * step[:, 0] + c * step[:, 1])
    poses[:, 2] = wrap_angle(th)
    return poses


def spanning_tree_poses(
    n_nodes: int, edge_i: I64, edge_j: I64, measurements: F64, root: int = 0
) -> F64:
    """Poses (N, 3) composed along a breadth-first spanning tree from ``root`` (at the origin);
    nodes not connected to the root stay at the origin."""
    poses = np.zeros((n_nodes, 3))
    if n_nodes == 0 or edge_i.shape[0] == 0:
        return poses
    rows = np.concatenate([edge_i, edge_j])
    cols = np.concatenate([edge_j, edge_i])
    adj = sp.csr_matrix((np.ones(rows.shape[0]), (rows, cols)), shape=(n_nodes, n_nodes))
    order, pred = breadth_first_order(adj, root, directed=True, return_predecessors=True)
    lookup: dict[tuple[int, int], tuple[int, bool]] = {}
    for e in range(edge_i.shape[0] - 1, -1, -1):
        lookup[(int(edge_i[e]), int(edge_j[e]))] = (e, False)
        lookup[(int(edge_j[e]), int(edge_i[e]))] = (e, True)
    for node in order[1:]:
        parent = int(pred[node])
        e, flipped = lookup[(parent, int(node))]
        z = inverse(measurements[e]) if flipped else measurements[e]
        poses[node] = compose(poses[parent], z)
    return poses


def initial_poses(n_nodes: int, edge_i: I64, edge_j: I64, measurements: F64) -> F64:
    """The odometry chain if complete, else the breadth-first spanning tree from node 0."""
    chain = odometry_chain_poses(n_nodes, edge_i, edge_j, measurements)
    if chain is not None:
        return chain
    return spanning_tree_poses(n_nodes, edge_i, edge_j, measurements)
