"""Initial guesses for pose graphs: odometry chain, spanning tree and chordal relaxation.

Graphs without vertices (``manhattan.g2o``) start from the chain of odometry edges
``i -> i + 1``: ``X_0 = 0``, ``X_{i+1} = X_i Z_{i,i+1}``, i.e. ``th_{i+1} = th_i + dth_i`` and
``t_{i+1} = t_i + R(th_i) dt_i`` (prefix sums, no Python loop). Where an edge of the chain is
missing, :func:`spanning_tree_poses` composes measurements along a breadth-first tree instead.

Both compose measurements, so one bad edge (or a long chain of drifting ones) bends everything
after it. :func:`chordal_poses` uses every edge at once and no guess at all: a linear relaxation
for the rotations, then a linear solve for the translations. From it Levenberg-Marquardt
reaches the known optima of the benchmark graphs whatever their stored guess
(:func:`~.posegraph.optimize` with ``initialisation="auto"``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.sparse.csgraph import breadth_first_order, connected_components

from agvsim.slam.se2 import compose, inverse, rotation_matrices, wrap_angle

__all__ = ["chordal_poses", "initial_poses", "odometry_chain_poses", "spanning_tree_poses"]

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


def chordal_poses(
    n_nodes: int,
    edge_i: I64,
    edge_j: I64,
    measurements: F64,
    information: F64,
    anchor: int = 0,
    anchor_pose: F64 | None = None,
) -> F64 | None:
    """Poses (N, 3) that do not depend on any initial guess: rotations by chordal relaxation,
    then translations by linear least squares with those rotations fixed (Carlone et al.,
    "Initialization techniques for 3D SLAM", ICRA 2015; in 2-D this is LAGO's two stages).

    1. Each rotation is a vector ``r_i = (cos th_i, sin th_i)``. An edge asks
       ``r_j = R(th_z) r_i``: two linear equations, weighted by the edge's heading information
       ``Omega_33``. With ``r_anchor`` fixed this is a sparse linear least-squares problem; each
       ``r_i`` is then projected back onto the circle, ``th_i = atan2(s_i, c_i)``.
    2. With the headings fixed, ``t_j - t_i = R(th_i) t_z`` is linear in the translations, each
       edge weighted by its translational information rotated into the world frame.

    ``anchor`` is placed at ``anchor_pose`` (the origin by default). Nodes not connected to the
    anchor by edges get ``NaN``; ``None`` when the anchor has no edges.
    """
    ei, ej = np.asarray(edge_i, np.int64), np.asarray(edge_j, np.int64)
    z = np.asarray(measurements, np.float64)
    om = np.asarray(information, np.float64)
    out = np.full((n_nodes, 3), np.nan)
    if n_nodes == 0:
        return out
    rows = np.concatenate([ei, ej])
    cols = np.concatenate([ej, ei])
    adj = sp.csr_matrix((np.ones(rows.shape[0]), (rows, cols)), shape=(n_nodes, n_nodes))
    _, labels = connected_components(adj, directed=False)
    member = labels == labels[anchor]
    if member.sum() == 1:
        out[anchor] = np.zeros(3) if anchor_pose is None else anchor_pose
        return out if ei.shape[0] == 0 or n_nodes == 1 else None
    keep = member[ei]  # an edge lies in the anchor's component with both ends or neither
    ei, ej, z, om = ei[keep], ej[keep], z[keep], om[keep]
    var = np.full(n_nodes, -1, np.int64)
    free = member.copy()
    free[anchor] = False
    var[free] = np.arange(int(free.sum()))
    m = int(free.sum())
    th = _chordal_headings(var, m, anchor, ei, ej, z, om)
    theta = np.zeros(n_nodes)
    theta[free] = th
    xy = _linear_translations(var, m, ei, ej, z, om, theta)
    out[member, 2] = wrap_angle(theta[member])
    out[member, :2] = 0.0
    out[free, :2] = xy
    if anchor_pose is not None:
        out[member] = compose(anchor_pose, out[member])
    return out


def _solve_normal(rows: I64, cols: I64, vals: F64, rhs_w: F64, n_eq: int, n_var: int) -> F64:
    """Least squares ``min |W^1/2 (A x - c)|^2`` from COO entries of ``A`` (with the weights
    folded in: ``vals`` and ``rhs_w`` are ``W^1/2 A`` and ``W^1/2 c``) by a sparse solve of
    the normal equations ``A^T A x = A^T c``."""
    a = sp.csr_matrix((vals, (rows, cols)), shape=(n_eq, n_var))
    ata = (a.T @ a).tocsc()
    atb = a.T @ rhs_w
    # a vanishing diagonal would mean an unconstrained variable; the component check rules it out
    ata = ata + sp.identity(n_var, format="csc") * 1e-12 * max(float(ata.diagonal().max()), 1.0)
    return np.asarray(spla.spsolve(ata, atb), np.float64)


def _chordal_headings(var: I64, m: int, anchor: int, ei: I64, ej: I64, z: F64, om: F64) -> F64:
    """Stage 1 of :func:`chordal_poses`: headings (m,) of the free nodes."""
    k = ei.shape[0]
    w = np.sqrt(np.maximum(om[:, 2, 2], 1e-12))
    cz, sz = np.cos(z[:, 2]) * w, np.sin(z[:, 2]) * w
    # residual rows 2k, 2k+1: r_j - R(th_z) r_i; unknowns (c, s) of node v at 2v, 2v+1
    eq = np.arange(k)
    r_list, c_list, v_list = [], [], []
    rhs = np.zeros(2 * k)
    # + w r_j
    for comp in (0, 1):
        r_list.append(2 * eq + comp)
        c_list.append(2 * var[ej] + comp)
        v_list.append(w)
    # - R(th_z) r_i = -[[cz, -sz], [sz, cz]] (c_i, s_i)
    for row_c, col_c, val in ((0, 0, -cz), (0, 1, sz), (1, 0, -sz), (1, 1, -cz)):
        r_list.append(2 * eq + row_c)
        c_list.append(2 * var[ei] + col_c)
        v_list.append(val)
    rows = np.concatenate(r_list)
    cols = np.concatenate(c_list)
    vals = np.concatenate(v_list)
    fixed = cols < 0  # entries of the anchor (c, s) = (1, 0) move to the right-hand side
    # a column -2 is the anchor's c (index 2 * -1 + 0), -1 its s: only c = 1 contributes
    anchor_c = fixed & (cols == -2)
    np.subtract.at(rhs, rows[anchor_c], vals[anchor_c])
    sol = _solve_normal(rows[~fixed], cols[~fixed], vals[~fixed], rhs, 2 * k, 2 * m)
    return np.arctan2(sol[1::2], sol[0::2])


def _linear_translations(var: I64, m: int, ei: I64, ej: I64, z: F64, om: F64, theta: F64) -> F64:
    """Stage 2 of :func:`chordal_poses`: translations (m, 2) of the free nodes, headings fixed.

    Edge residual ``e = M (t_j - t_i - R_i t_z)`` with ``M = R(th_i + th_z)^T`` (the pose
    graph's translational error at these headings), cost ``e^T Omega_tt e``: whitened by the
    Cholesky factor ``L^T`` of ``Omega_tt``, each edge gives two rows ``L^T M (t_j - t_i) =
    L^T M R_i t_z``."""
    k = ei.shape[0]
    om_tt = om[:, :2, :2]
    # L^T with L L^T = Omega_tt; a singular Omega_tt (no translational information) gets a tiny
    # ridge so that Cholesky succeeds and the edge carries (next to) no weight
    scale = np.maximum(np.abs(om_tt).max(axis=(1, 2)), 1e-12)
    lt = np.swapaxes(np.linalg.cholesky(om_tt + 1e-12 * scale[:, None, None] * np.eye(2)), 1, 2)
    mt = np.swapaxes(rotation_matrices(theta[ei] + z[:, 2]), 1, 2)
    wm = lt @ mt  # (k, 2, 2)
    ri = rotation_matrices(theta[ei])
    rhs = np.einsum("kab,kb->ka", wm, np.einsum("kab,kb->ka", ri, z[:, :2])).reshape(-1)
    r_list, c_list, v_list = [], [], []
    eq = np.arange(k)
    for a in (0, 1):
        for b in (0, 1):
            r_list += [2 * eq + a, 2 * eq + a]
            c_list += [2 * var[ej] + b, 2 * var[ei] + b]
            v_list += [wm[:, a, b], -wm[:, a, b]]
    rows, cols, vals = np.concatenate(r_list), np.concatenate(c_list), np.concatenate(v_list)
    # the anchor sits at the origin: its columns drop out (t_anchor = 0)
    ok = cols >= 0
    sol = _solve_normal(rows[ok], cols[ok], vals[ok], rhs, 2 * k, 2 * m)
    return sol.reshape(-1, 2)
