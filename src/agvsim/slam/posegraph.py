"""2-D pose graphs and their sparse Levenberg-Marquardt optimiser.

A graph holds ``poses (N, 3)`` ``[x m, y m, theta rad]`` (world frame) and ``E`` edges: node
indices ``edge_i, edge_j (E,)``, ``measurements (E, 3)`` (pose j in the frame of pose i, the
g2o ``EDGE_SE2`` convention) and ``information (E, 3, 3)`` (inverse covariances, symmetric).

Error of edge k with measurement ``Z`` between poses ``X_i, X_j`` (see :mod:`.se2`)::

    e_k = t2v(Z^-1 (X_i^-1 X_j)):
    e_t  = R_z^T (R_i^T (t_j - t_i) - t_z)                 (2,)  m
    e_th = wrap(th_j - th_i - th_z)                         ()    rad
    chi2 = sum_k e_k^T Omega_k e_k

Jacobians with respect to additive increments of ``(t_i, th_i)`` and ``(t_j, th_j)``::

    A_k = [[-R_z^T R_i^T, R_z^T dR_i^T/dth (t_j - t_i)], [0, 0, -1]]
    B_k = [[ R_z^T R_i^T, 0                           ], [0, 0,  1]]

:func:`optimize` minimises ``sum_k rho(e_k^T Omega_k e_k)`` by Levenberg-Marquardt on the sparse
normal equations ``(H + lambda D) dx = -b``, ``H = J^T W Omega J``, ``b = J^T W Omega e``
(``D = diag(H)``, Marquardt's scaling); robust kernels ``rho`` enter as iteratively reweighted
information ``W_k = rho'(chi2_k)`` (:class:`RobustKernel`). The Jacobian blocks are built for
all edges at once with numpy; the sparsity pattern of ``H`` is computed once per call and reused
every iteration. Fixed nodes (node 0 by default: the gauge) are removed from the system. The
initial guesses used for graphs without vertices are in :mod:`.posegraph_init`.

Plain LM with this damping control reaches the known optima of the benchmark graphs from their
own initial guesses (intel 45.0047, city10000 511.985) and of M3500 from its odometry chain
(3549.04), without a rotation-first initialisation (``benchmarks/bench_posegraph.py``).
"""

from __future__ import annotations

import enum
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar, cast

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray

from agvsim.slam.posegraph_init import chordal_poses
from agvsim.slam.robust import RobustKernel, robust_cost_and_weights, switch_values
from agvsim.slam.se2 import rotation_matrices, wrap_angle

__all__ = [
    "Initialisation",
    "IterationInfo",
    "OptimizeResult",
    "PoseGraph",
    "RobustKernel",
    "chi2",
    "edge_chi2",
    "edge_errors",
    "optimize",
]

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
_A = TypeVar("_A", bound=np.ndarray[Any, Any])


def _grow(a: _A, n_min: int) -> _A:
    out = np.zeros((max(n_min, 2 * a.shape[0], 16), *a.shape[1:]), dtype=a.dtype)
    out[: a.shape[0]] = a
    return cast(_A, out)


@dataclass(eq=False)
class PoseGraph:
    """Nodes (poses) and edges (relative-pose measurements with information matrices).

    Arrays grow by doubling, so adding one node or edge at a time (an online SLAM) is amortised
    O(1). The properties are views of the used part; assign ``graph.poses = ...`` to replace poses.
    """

    _poses: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    _edge_i: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    _edge_j: I64 = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    _meas: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    _info: F64 = field(default_factory=lambda: np.zeros((0, 3, 3)))
    _n_nodes: int = 0
    _n_edges: int = 0

    @classmethod
    def from_arrays(
        cls,
        poses: ArrayLike,
        edge_i: ArrayLike,
        edge_j: ArrayLike,
        measurements: ArrayLike,
        information: ArrayLike,
    ) -> PoseGraph:
        """A graph from whole arrays: poses (N, 3), edge_i/j (E,), measurements (E, 3),
        information (E, 3, 3)."""
        g = cls()
        g.add_nodes(poses)
        g.add_edges(edge_i, edge_j, measurements, information)
        return g

    @property
    def n_nodes(self) -> int:
        return self._n_nodes

    @property
    def n_edges(self) -> int:
        return self._n_edges

    @property
    def poses(self) -> F64:
        """(N, 3) x m, y m, theta rad."""
        return self._poses[: self._n_nodes]

    @poses.setter
    def poses(self, value: ArrayLike) -> None:
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != (self._n_nodes, 3):
            raise ValueError(f"poses must have shape ({self._n_nodes}, 3), got {arr.shape}")
        self._poses[: self._n_nodes] = arr

    @property
    def edge_i(self) -> I64:
        return self._edge_i[: self._n_edges]

    @property
    def edge_j(self) -> I64:
        return self._edge_j[: self._n_edges]

    @property
    def measurements(self) -> F64:
        """(E, 3) pose j in the frame of pose i: dx m, dy m, dtheta rad."""
        return self._meas[: self._n_edges]

    @property
    def information(self) -> F64:
        """(E, 3, 3) information matrices (inverse covariance) of the measurements."""
        return self._info[: self._n_edges]

    def add_nodes(self, poses: ArrayLike) -> I64:
        """Append poses (K, 3) (or one (3,)); returns their node indices (K,)."""
        p = np.atleast_2d(np.asarray(poses, dtype=np.float64))
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"poses must have shape (K, 3), got {np.shape(poses)}")
        n0, n1 = self._n_nodes, self._n_nodes + p.shape[0]
        if n1 > self._poses.shape[0]:
            self._poses = _grow(self._poses, n1)
        self._poses[n0:n1] = p
        self._n_nodes = n1
        return np.arange(n0, n1, dtype=np.int64)

    def add_node(self, pose: ArrayLike) -> int:
        """Append one pose [x, y, theta]; returns its node index."""
        return int(self.add_nodes(np.reshape(np.asarray(pose, dtype=np.float64), (1, 3)))[0])

    def add_edges(
        self, i: ArrayLike, j: ArrayLike, measurements: ArrayLike, information: ArrayLike
    ) -> None:
        """Append K edges: i, j (K,) node indices, measurements (K, 3), information (K, 3, 3)
        (or one (3, 3) shared by all)."""
        ii = np.atleast_1d(np.asarray(i, dtype=np.int64))
        jj = np.atleast_1d(np.asarray(j, dtype=np.int64))
        z = np.atleast_2d(np.asarray(measurements, dtype=np.float64))
        om = np.asarray(information, dtype=np.float64)
        k = ii.shape[0]
        if om.shape == (3, 3):
            om = np.broadcast_to(om, (k, 3, 3))
        if ii.shape != (k,) or jj.shape != (k,) or z.shape != (k, 3) or om.shape != (k, 3, 3):
            raise ValueError(
                "edges need i, j (K,), measurements (K, 3), information (K, 3, 3); got "
                f"{ii.shape}, {jj.shape}, {z.shape}, {om.shape}"
            )
        bad = (ii < 0) | (ii >= self._n_nodes) | (jj < 0) | (jj >= self._n_nodes) | (ii == jj)
        if np.any(bad):
            e = int(np.argmax(bad))
            raise ValueError(
                f"edge ({ii[e]}, {jj[e]}): node indices must differ and lie in [0, {self._n_nodes})"
            )
        e0, e1 = self._n_edges, self._n_edges + k
        if e1 > self._edge_i.shape[0]:
            self._edge_i, self._edge_j = _grow(self._edge_i, e1), _grow(self._edge_j, e1)
            self._meas, self._info = _grow(self._meas, e1), _grow(self._info, e1)
        self._edge_i[e0:e1], self._edge_j[e0:e1] = ii, jj
        self._meas[e0:e1], self._info[e0:e1] = z, om
        self._n_edges = e1

    def add_edge(self, i: int, j: int, measurement: ArrayLike, information: ArrayLike) -> None:
        """Append one edge: pose j measured in the frame of pose i, with its 3x3 information."""
        self.add_edges(
            [i], [j], np.reshape(measurement, (1, 3)), np.reshape(information, (1, 3, 3))
        )

    def copy(self) -> PoseGraph:
        """An independent copy (arrays trimmed to size)."""
        return PoseGraph.from_arrays(
            self.poses, self.edge_i, self.edge_j, self.measurements, self.information
        )


def edge_errors(graph: PoseGraph, poses: F64 | None = None) -> F64:
    """``e_k = t2v(Z_k^-1 X_i^-1 X_j)`` for every edge, (E, 3) (see the module docstring)."""
    p = graph.poses if poses is None else poses
    e, _, _ = _errors_jacobians(p, graph.edge_i, graph.edge_j, graph.measurements, False)
    return e


def edge_chi2(graph: PoseGraph, poses: F64 | None = None) -> F64:
    """``e_k^T Omega_k e_k`` for every edge, (E,)."""
    e = edge_errors(graph, poses)
    return np.einsum("ka,kab,kb->k", e, graph.information, e)


def chi2(graph: PoseGraph, poses: F64 | None = None) -> float:
    """``sum_k e_k^T Omega_k e_k`` at the graph's poses (or the given ones)."""
    return float(np.sum(edge_chi2(graph, poses)))


def _errors_jacobians(
    poses: F64, ei: I64, ej: I64, z: F64, with_jacobians: bool
) -> tuple[F64, F64, F64]:
    """Errors (E, 3) and, if asked, Jacobians ``A, B`` (E, 3, 3) (module docstring)."""
    pi, pj = poses[ei], poses[ej]
    ci, si = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    cz, sz = np.cos(z[:, 2]), np.sin(z[:, 2])
    dx, dy = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    # d = R_i^T (t_j - t_i) and its derivative in th_i
    d0, d1 = ci * dx + si * dy, -si * dx + ci * dy
    dd0, dd1 = d1, -d0
    u0, u1 = d0 - z[:, 0], d1 - z[:, 1]
    e = np.empty((ei.shape[0], 3))
    e[:, 0] = cz * u0 + sz * u1
    e[:, 1] = -sz * u0 + cz * u1
    e[:, 2] = wrap_angle(pj[:, 2] - pi[:, 2] - z[:, 2])
    if not with_jacobians:
        return e, e, e
    # M = R_z^T R_i^T = R(th_i + th_z)^T
    m = np.swapaxes(rotation_matrices(pi[:, 2] + z[:, 2]), 1, 2)
    a = np.zeros((ei.shape[0], 3, 3))
    b = np.zeros((ei.shape[0], 3, 3))
    a[:, :2, :2] = -m
    a[:, 0, 2] = cz * dd0 + sz * dd1
    a[:, 1, 2] = -sz * dd0 + cz * dd1
    a[:, 2, 2] = -1.0
    b[:, :2, :2] = m
    b[:, 2, 2] = 1.0
    return e, a, b


class Initialisation(enum.StrEnum):
    """Where :func:`optimize` starts.

    * ``given``:   the graph's poses (a warm start: online SLAM re-optimising its own graph);
    * ``chordal``: :func:`~.posegraph_init.chordal_poses`, which ignores the given poses;
    * ``auto``:    whichever of the two has the lower chi2.
    """

    GIVEN = "given"
    CHORDAL = "chordal"
    AUTO = "auto"


def initial_guess(
    graph: PoseGraph, initialisation: Initialisation | str, fixed: Sequence[int] = (0,)
) -> F64:
    """The start :func:`optimize` uses (see :class:`Initialisation`), (N, 3). The chordal start
    keeps the first fixed node where it is (the gauge); with several fixed nodes, or nodes not
    connected to it, the given poses are kept (for those nodes)."""
    init = Initialisation(initialisation)
    poses = graph.poses.copy()
    fixed_idx = [int(f) for f in np.asarray(fixed, dtype=np.int64).reshape(-1)]
    if init is Initialisation.GIVEN or len(fixed_idx) != 1 or graph.n_edges == 0:
        return poses
    anchor = fixed_idx[0]
    chordal = chordal_poses(
        graph.n_nodes,
        graph.edge_i,
        graph.edge_j,
        graph.measurements,
        graph.information,
        anchor=anchor,
        anchor_pose=poses[anchor],
    )
    if chordal is None:
        return poses
    placed = ~np.isnan(chordal[:, 0])
    chordal[~placed] = poses[~placed]
    if init is Initialisation.CHORDAL:
        return chordal
    return chordal if chi2(graph, chordal) < chi2(graph, poses) else poses


@dataclass(frozen=True)
class IterationInfo:
    """What :func:`optimize` reports to its ``verbose`` callback after each iteration."""

    iteration: int
    cost: float  # robust cost after the iteration (chi2 for the plain kernel)
    chi2: float
    damping: float  # lambda for the next iteration
    accepted: bool
    seconds: float  # since the start of optimize


@dataclass(frozen=True)
class OptimizeResult:
    """Optimised poses (N, 3) and chi2 before/after (cost: robust cost, = chi2 if ``none``)."""

    poses: F64
    chi2_initial: float
    chi2_final: float
    iterations: int
    converged: bool
    cost_initial: float
    cost_final: float
    # (E,) switch of every edge at the result: 1 for edges that are not switchable, in [0, 1]
    # for switchable ones (0: the edge was found inconsistent with the rest and switched off)
    switches: F64 = field(default_factory=lambda: np.zeros(0))


class _NormalEquations:
    """Sparse ``H`` (3M x 3M, M free nodes) with a pattern built once; values by bincount.

    The pattern is found on 3x3 blocks (one key per edge block, not nine per scalar entry):
    its temporaries are a ninth of a scalar pattern's, and ``H`` is summed per block before
    it is scattered into CSR order."""

    def __init__(self, n_nodes: int, ei: I64, ej: I64, fixed: Sequence[int]) -> None:
        var = np.full(n_nodes, -1, dtype=np.int64)
        free = np.ones(n_nodes, dtype=bool)
        fixed_idx = np.asarray(fixed, dtype=np.int64).reshape(-1)
        if np.any((fixed_idx < 0) | (fixed_idx >= n_nodes)):
            raise ValueError(f"fixed node indices must lie in [0, {n_nodes}), got {list(fixed)}")
        free[fixed_idx] = False
        m = int(free.sum())
        var[free] = np.arange(m)
        self.var, self.n = var, 3 * m
        three = np.arange(3)
        # the 4 blocks (ii, ij, ji, jj) of every edge: block rows/cols (E, 4)
        bi, bj = var[ei], var[ej]
        blk_r = np.stack([bi, bi, bj, bj], axis=1).reshape(-1)
        blk_c = np.stack([bi, bj, bi, bj], axis=1).reshape(-1)
        self.valid = (blk_r >= 0) & (blk_c >= 0)
        diag = np.arange(m, dtype=np.int64)
        keys = np.concatenate([blk_r[self.valid] * m + blk_c[self.valid], diag * m + diag])
        ukeys, slot = np.unique(keys, return_inverse=True)
        del keys
        self.slot = slot[: slot.shape[0] - m]  # block of each valid edge block
        r, c = ukeys // max(m, 1), ukeys % max(m, 1)
        per_row = np.bincount(r, minlength=m)  # blocks in each block row
        first = np.concatenate([[0], np.cumsum(per_row)])  # first block of each block row
        q = np.arange(ukeys.shape[0]) - first[r]  # place of each block in its block row
        self.n_blocks = ukeys.shape[0]
        self.nnz = 9 * self.n_blocks
        # scalar row 3 br + a holds the a-th rows of the blocks of block row br, in turn
        row_len = np.repeat(3 * per_row, 3)
        self.indptr = np.concatenate([[0], np.cumsum(row_len)]).astype(np.int32)
        # CSR position of entry (a, b) of each block (n_blocks, 3, 3)
        self.pos = (
            9 * first[r][:, None, None]
            + three[None, :, None] * (3 * per_row[r])[:, None, None]
            + 3 * q[:, None, None]
            + three[None, None, :]
        )
        self.indices = np.empty(self.nnz, dtype=np.int32)
        self.indices[self.pos.reshape(-1)] = np.broadcast_to(
            3 * c[:, None, None] + three[None, None, :], self.pos.shape
        ).reshape(-1)
        self.diag_slot = self.pos[slot[slot.shape[0] - m :]][:, three, three].reshape(-1)
        # b: gradient entries of i and j per edge (E, 2, 3)
        self.b_rows = (3 * np.stack([bi, bj], axis=1)[:, :, None] + three).reshape(-1)
        self.b_valid = np.repeat(np.stack([bi, bj], axis=1) >= 0, 3, axis=1).reshape(-1)

    def assemble(self, a: F64, b: F64, wom: F64, e: F64) -> tuple[F64, F64]:
        """Values of ``H`` (nnz,) in CSR order and ``b`` (3M,) from Jacobians, ``W Omega``."""
        at_om = np.einsum("kba,kbc->kac", a, wom)  # A^T W Omega
        bt_om = np.einsum("kba,kbc->kac", b, wom)
        blocks = np.stack([at_om @ a, at_om @ b, bt_om @ a, bt_om @ b], axis=1)  # (E, 4, 3, 3)
        valid = blocks.reshape(-1, 3, 3)[self.valid]
        h = np.empty(self.nnz)
        for i in range(3):
            for j in range(3):
                h[self.pos[:, i, j]] = np.bincount(
                    self.slot, valid[:, i, j], minlength=self.n_blocks
                )
        g = np.stack([np.einsum("kab,kb->ka", at_om, e), np.einsum("kab,kb->ka", bt_om, e)], 1)
        rows, vals = self.b_rows[self.b_valid], g.reshape(-1)[self.b_valid]
        grad = np.bincount(rows, vals, minlength=self.n).astype(np.float64, copy=False)
        return h, grad

    def solve(self, h: F64, grad: F64, damping: float) -> F64 | None:
        """``dx`` from ``(H + damping * diag(H)) dx = -grad``; None if numerically singular.

        SuperLU with a symmetric minimum-degree ordering of ``H + H^T`` and no pivoting (``H``
        is symmetric positive definite) is the fastest scipy option measured: on city10000
        about 0.15-0.2 s per factorisation against 0.3 s with COLAMD, 0.2-0.4 s with MMD_ATA,
        and a minute with MMD_AT_PLUS_A when SuperLU may pivot (the fill explodes).
        """
        hd = h.copy()
        hd[self.diag_slot] += damping * np.maximum(h[self.diag_slot], 1e-9)
        mat = sp.csc_matrix((hd, self.indices, self.indptr), shape=(self.n, self.n))  # H^T = H
        try:
            lu = spla.splu(
                mat,
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError:  # exactly singular
            return None
        dx = np.asarray(lu.solve(-grad), dtype=np.float64)
        return dx if np.all(np.isfinite(dx)) else None


def optimize(
    graph: PoseGraph,
    *,
    robust: RobustKernel | str = RobustKernel.NONE,
    robust_scale: float = 1.0,
    max_iterations: int = 100,
    tolerance: float = 1e-9,
    fixed: Sequence[int] = (0,),
    initial_damping: float = 1e-4,
    verbose: Callable[[IterationInfo], None] | None = None,
    initialisation: Initialisation | str = Initialisation.GIVEN,
    switchable: ArrayLike | None = None,
    switch_scale: float | ArrayLike = 1.0,
) -> OptimizeResult:
    """Minimise ``sum_k rho(e_k^T Omega_k e_k)`` over the free poses by Levenberg-Marquardt.

    Each iteration solves ``(H + lambda diag(H)) dx = -b`` and accepts the step when the gain
    ratio ``(F(x) - F(x + dx)) / (L(0) - L(dx))`` is positive, with Nielsen's update
    ``lambda *= max(1/3, 1 - (2 rho - 1)^3)``; a rejected step multiplies lambda by
    ``nu`` (2, 4, 8, ...). The robust weights are recomputed at every accepted point (IRLS).
    Converged when an accepted step lowers the cost by less than ``tolerance`` (relative),
    or the step is below ``1e-12`` of the state. ``fixed`` nodes (the gauge) stay put.
    ``initialisation`` picks the start (:class:`Initialisation`; ``chi2_initial`` is the
    given poses' chi2 whatever the start). Does not modify ``graph``; the result's ``poses``
    are a new array.

    ``switchable`` (E,) bools marks edges that may be wrong, loop closures typically: they get
    switchable constraints (:attr:`RobustKernel.DCS` with ``Phi = switch_scale^2``) instead
    of ``robust``, and the result reports their switches (a false closure's goes to 0).
    ``switch_scale`` is one scale for all of them or one per edge (E,) (only the switchable
    edges' entries are used): online SLAM relaxes the prior of new closures only.
    """
    kernel = RobustKernel(robust)
    if robust_scale <= 0.0:
        raise ValueError(f"robust_scale must be positive, got {robust_scale}")
    scales = np.asarray(switch_scale, dtype=np.float64)
    if scales.ndim != 0 and scales.shape != (graph.n_edges,):
        raise ValueError(
            f"switch_scale must be one number or one per edge, shape ({graph.n_edges},); "
            f"got {scales.shape}"
        )
    if not np.all(scales > 0.0) or not np.all(np.isfinite(scales)):
        bad = scales if scales.ndim == 0 else scales[~((scales > 0.0) & np.isfinite(scales))][0]
        raise ValueError(f"switch_scale must be positive and finite, got {bad}")
    switch = np.zeros(graph.n_edges, dtype=bool)
    if switchable is not None:
        switch = np.asarray(switchable, dtype=bool)
        if switch.shape != (graph.n_edges,):
            raise ValueError(
                f"switchable must have one flag per edge, shape ({graph.n_edges},); "
                f"got {switch.shape}"
            )
    any_switch = bool(switch.any())
    sw_scale = np.broadcast_to(scales, (graph.n_edges,))[switch]
    t0 = time.perf_counter()
    chi2_given = chi2(graph) if graph.n_edges else 0.0
    poses = initial_guess(graph, initialisation, fixed)
    ei, ej, z, om = graph.edge_i, graph.edge_j, graph.measurements, graph.information
    neq = _NormalEquations(graph.n_nodes, ei, ej, fixed)
    free_rows = neq.var >= 0

    def evaluate(p: F64, jac: bool) -> tuple[float, float, F64, F64, F64, F64]:
        e, a, b = _errors_jacobians(p, ei, ej, z, jac)
        s = np.einsum("ka,kab,kb->k", e, om, e)
        cost, w = robust_cost_and_weights(s, kernel, robust_scale)
        if any_switch:
            c_sw, w_sw = robust_cost_and_weights(s[switch], RobustKernel.DCS, sw_scale)
            cost, w = cost.copy(), w.copy()
            cost[switch], w[switch] = c_sw, w_sw
        return float(cost.sum()), float(s.sum()), w, e, a, b

    def switches(e: F64) -> F64:
        out = np.ones(graph.n_edges)
        if any_switch:
            s = np.einsum("ka,kab,kb->k", e[switch], om[switch], e[switch])
            out[switch] = switch_values(s, sw_scale)
        return out

    cost, c2, w, e, a, b = evaluate(poses, True)
    cost0, chi2_0 = cost, chi2_given
    lam, nu = initial_damping, 2.0
    converged = False
    it = 0
    if neq.n == 0 or graph.n_edges == 0 or cost == 0.0:  # nothing to move, or an exact fit
        return OptimizeResult(poses, chi2_0, c2, 0, True, cost0, cost0, switches(e))
    h, grad = neq.assemble(a, b, w[:, None, None] * om, e)
    for it in range(1, max_iterations + 1):
        dx = neq.solve(h, grad, lam)
        accepted = False
        if dx is not None:
            step = np.zeros_like(poses)
            step[free_rows] = dx.reshape(-1, 3)
            trial = poses + step
            trial[free_rows, 2] = wrap_angle(trial[free_rows, 2])
            t_cost, t_c2, t_w, t_e, t_a, t_b = evaluate(trial, True)
            # decrease predicted by the (reweighted) quadratic model: -(2 b^T dx + dx^T H dx)
            hdx = sp.csr_matrix((h, neq.indices, neq.indptr), shape=(neq.n, neq.n)) @ dx
            # (sums, not BLAS dots: a threaded OpenBLAS ddot can take ms on a busy machine)
            predicted = -float(np.sum(2.0 * grad * dx + dx * hdx))
            actual = cost - t_cost
            accepted = bool(predicted > 0.0 and actual > 0.0)
        if accepted and dx is not None:
            rho = actual / predicted
            scale = 1.0 + float(np.abs(poses).max())
            converged = actual < tolerance * cost or float(np.abs(dx).max()) < 1e-12 * scale
            poses, cost, c2, w, e, a, b = trial, t_cost, t_c2, t_w, t_e, t_a, t_b
            lam *= float(max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3))
            nu = 2.0
            if not converged:
                h, grad = neq.assemble(a, b, w[:, None, None] * om, e)
        else:
            lam *= nu
            nu *= 2.0
        if verbose is not None:
            verbose(IterationInfo(it, cost, c2, lam, accepted, time.perf_counter() - t0))
        if converged:
            break
        if lam > 1e16:  # no descent direction left: at a (local) minimum to machine precision
            converged = True
            break
    return OptimizeResult(poses, chi2_0, c2, it, converged, cost0, cost, switches(e))
