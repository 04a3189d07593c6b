"""Scan-to-map matching: numba kernels over a likelihood grid (free functions, no RNG).

The map is a likelihood grid ``M[iy, ix]`` in [0, 1] (row ``iy`` grows with y), cell ``res``
metres, lower-left corner ``(ox, oy)``; cell centres sit at ``ox + (ix + 1/2) res``. A scan is
``n`` points ``p_k`` in the robot frame; a pose ``xi = (x, y, theta)`` maps them to
``T(xi) p_k = R(theta) p_k + t``. The match score is the mean likelihood

    s(xi) = (1/n) sum_k M(T(xi) p_k)

and the three stages maximise it (Olson's real-time correlative matching, then Gauss-Newton as
in Hector SLAM / Cartographer's refinement):

1. :func:`correlative_search` -- exhaustive search over a window of whole-cell offsets and angles
   ``theta_0 + j dtheta``, with ``dtheta ~ res / r_max`` so that the farthest point moves about
   one cell per angular step.
2. :func:`branch_and_bound` -- the same search over a large window (loop closure), exact: the
   precomputed :func:`max_pyramid` level ``h`` holds ``max`` of ``M`` over ``2^h x 2^h`` blocks,
   an upper bound on every score of the candidates a node stands for, so a depth-first search
   prunes every node whose bound does not beat the best leaf found (Hess et al. 2016).
3. :func:`gauss_newton` -- sub-cell refinement of ``sum_k (1 - M(T p_k))^2`` with bilinear
   interpolation: ``J_k = grad M . [I_2 | R'(theta) p_k]``, ``(J^T J) dxi = J^T r``. ``J^T J``
   at the optimum is returned as the shape of the information matrix of the match.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "angular_step",
    "branch_and_bound",
    "correlative_search",
    "gauss_newton",
    "match_hessian",
    "max_pyramid",
    "observed_before",
    "score_pose",
]


def angular_step(resolution_m: float, max_point_range_m: float) -> float:
    """Angle (rad) that moves a point at ``max_point_range_m`` by about one cell:
    ``acos(1 - res^2 / (2 r^2))``."""
    r = max(max_point_range_m, resolution_m)
    return float(math.acos(max(-1.0, 1.0 - resolution_m**2 / (2.0 * r * r))))


@njit(cache=True)
def _cell_value(grid: np.ndarray, iy: int, ix: int) -> float:
    if iy < 0 or ix < 0 or iy >= grid.shape[0] or ix >= grid.shape[1]:
        return 0.0
    return grid[iy, ix]


@njit(cache=True)
def observed_before(
    logodds: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    points: np.ndarray,
    pose: np.ndarray,
    origin: np.ndarray,
    back_m: float,
) -> np.ndarray:
    """Which scan ``points`` (robot frame) placed at ``pose`` land where the grid has been
    observed: the cell ``back_m`` short of each point on its ray from ``origin`` (the
    sensor, robot frame) holds a log-odds other than 0 (0: never seen, or as much hit as
    missed: probability 1/2). Short of the point, not at it: a point on a wall seen before
    lies up to the pose's error behind that wall's cells, where no ray has reached; in front
    of the wall the earlier rays swept the cells free. A point closer than ``back_m`` to the
    sensor counts as observed."""
    n = points.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    sx = pose[0] + c * origin[0] - s * origin[1]
    sy = pose[1] + s * origin[0] + c * origin[1]
    for k in range(n):
        px = pose[0] + c * points[k, 0] - s * points[k, 1]
        py = pose[1] + s * points[k, 0] + c * points[k, 1]
        r = math.hypot(px - sx, py - sy)
        if r <= back_m:
            out[k] = True
            continue
        f = (r - back_m) / r
        ix = int(math.floor((sx + f * (px - sx) - ox) / res))
        iy = int(math.floor((sy + f * (py - sy) - oy) / res))
        out[k] = _cell_value(logodds, iy, ix) != 0.0  # off the grid: 0, never seen
    return out


@njit(cache=True)
def _bilinear(
    grid: np.ndarray, ox: float, oy: float, res: float, x: float, y: float
) -> tuple[float, float, float]:
    """Value and gradient (d/dx, d/dy) of the bilinear interpolation of ``grid`` at (x, y)."""
    u = (x - ox) / res - 0.5
    v = (y - oy) / res - 0.5
    i0 = math.floor(u)
    j0 = math.floor(v)
    fu = u - i0
    fv = v - j0
    ix, iy = int(i0), int(j0)
    m00 = _cell_value(grid, iy, ix)
    m10 = _cell_value(grid, iy, ix + 1)
    m01 = _cell_value(grid, iy + 1, ix)
    m11 = _cell_value(grid, iy + 1, ix + 1)
    val = (1 - fv) * ((1 - fu) * m00 + fu * m10) + fv * ((1 - fu) * m01 + fu * m11)
    gx = ((1 - fv) * (m10 - m00) + fv * (m11 - m01)) / res
    gy = ((1 - fu) * (m01 - m00) + fu * (m11 - m10)) / res
    return val, gx, gy


@njit(cache=True)
def score_pose(
    grid: np.ndarray, ox: float, oy: float, res: float, points: np.ndarray, pose: np.ndarray
) -> float:
    """Mean bilinear likelihood ``s(xi)`` of ``points`` (n, 2) placed at ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    total = 0.0
    for k in range(points.shape[0]):
        x = pose[0] + c * points[k, 0] - s * points[k, 1]
        y = pose[1] + s * points[k, 0] + c * points[k, 1]
        total += _bilinear(grid, ox, oy, res, x, y)[0]
    return total / max(points.shape[0], 1)


@njit(cache=True)
def _rotated_cells(
    points: np.ndarray, pose: np.ndarray, ox: float, oy: float, res: float, angles: np.ndarray
) -> np.ndarray:
    """Integer cells ``(n_angles, n, 2)`` [ix, iy] of the points rotated by each absolute angle
    and translated to ``pose[:2]``."""
    n = points.shape[0]
    out = np.empty((angles.shape[0], n, 2), dtype=np.int64)
    for a in range(angles.shape[0]):
        c, s = math.cos(angles[a]), math.sin(angles[a])
        for k in range(n):
            x = pose[0] + c * points[k, 0] - s * points[k, 1]
            y = pose[1] + s * points[k, 0] + c * points[k, 1]
            out[a, k, 0] = int(math.floor((x - ox) / res))
            out[a, k, 1] = int(math.floor((y - oy) / res))
    return out


@njit(cache=True)
def _offset_score(grid: np.ndarray, cells: np.ndarray, a: int, dx: int, dy: int) -> float:
    total = 0.0
    for k in range(cells.shape[1]):
        total += _cell_value(grid, cells[a, k, 1] + dy, cells[a, k, 0] + dx)
    return total / max(cells.shape[1], 1)


@njit(cache=True)
def _block_score(
    level: np.ndarray, cells: np.ndarray, a: int, dx: int, dy: int, size: int
) -> float:
    """Upper bound of the score of every offset in ``[dx, dx + size) x [dy, dy + size)``: the
    mean of the pyramid ``level`` (blocks of ``size`` cells). A block that starts below the
    grid's first row or column but reaches into it is bounded by the block at index 0, which
    contains its part inside the grid (looking up the negative index would give 0, no bound)."""
    total = 0.0
    for k in range(cells.shape[1]):
        ix = cells[a, k, 0] + dx
        iy = cells[a, k, 1] + dy
        if ix + size <= 0 or iy + size <= 0:
            continue
        total += _cell_value(level, max(iy, 0), max(ix, 0))
    return total / max(cells.shape[1], 1)


@njit(cache=True)
def correlative_search(
    grid: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    points: np.ndarray,
    pose0: np.ndarray,
    lin_window_m: float,
    ang_window_rad: float,
    ang_step_rad: float,
    lin_weight: float,
    ang_weight: float,
) -> tuple[np.ndarray, float]:
    """Best pose over whole-cell offsets within ``+-lin_window_m`` and angles within
    ``+-ang_window_rad`` of ``pose0``, maximising the score minus a motion prior
    ``s(xi) - w_t |t - t_0|^2 - w_th (theta - theta_0)^2`` (ties go to the candidate nearest
    ``pose0``); returns the pose and its score ``s``."""
    na = int(math.ceil(ang_window_rad / ang_step_rad))
    angles = pose0[2] + ang_step_rad * np.arange(-na, na + 1).astype(np.float64)
    cells = _rotated_cells(points, pose0, ox, oy, res, angles)
    w = int(math.ceil(lin_window_m / res))
    best, best_sc, best_a, best_dx, best_dy, best_cost = -1e30, 0.0, na, 0, 0, 0.0
    for a in range(angles.shape[0]):
        pen_a = ang_weight * ((a - na) * ang_step_rad) ** 2
        for dy in range(-w, w + 1):
            for dx in range(-w, w + 1):
                sc = _offset_score(grid, cells, a, dx, dy)
                val = sc - pen_a - lin_weight * (dx * dx + dy * dy) * res * res
                cost = (a - na) ** 2 + dx * dx + dy * dy
                if val > best or (val == best and cost < best_cost):
                    best, best_sc, best_a, best_dx, best_dy, best_cost = val, sc, a, dx, dy, cost
    out = np.array([pose0[0] + best_dx * res, pose0[1] + best_dy * res, angles[best_a]])
    return out, best_sc


@njit(cache=True)
def max_pyramid(grid: np.ndarray, levels: int) -> np.ndarray:
    """``(levels, H, W)``: level ``h`` holds ``max`` of ``grid`` over the block
    ``[iy, iy + 2^h) x [ix, ix + 2^h)`` (cells beyond the grid count as 0)."""
    h_, w_ = grid.shape
    pyr = np.zeros((levels, h_, w_), dtype=grid.dtype)
    pyr[0] = grid
    for lvl in range(1, levels):
        half = 1 << (lvl - 1)
        prev = pyr[lvl - 1]
        cur = pyr[lvl]
        for iy in range(h_):
            for ix in range(w_):
                m = prev[iy, ix]
                if ix + half < w_:
                    m = max(m, prev[iy, ix + half])
                if iy + half < h_:
                    m = max(m, prev[iy + half, ix])
                    if ix + half < w_:
                        m = max(m, prev[iy + half, ix + half])
                cur[iy, ix] = m
    return pyr


@njit(cache=True)
def _sort_desc(scores: np.ndarray) -> np.ndarray:
    return np.argsort(-scores, kind="mergesort")


@njit(cache=True)
def branch_and_bound(
    pyramid: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    points: np.ndarray,
    pose0: np.ndarray,
    lin_window_m: float,
    ang_window_rad: float,
    ang_step_rad: float,
    min_score: float,
) -> tuple[np.ndarray, float]:
    """Exact best whole-cell pose within the window (as :func:`correlative_search`), or score -1
    when no candidate reaches ``min_score``. Depth-first, best child first, pruning by bound."""
    levels = pyramid.shape[0]
    top = levels - 1
    step = 1 << top
    na = int(math.ceil(ang_window_rad / ang_step_rad))
    angles = pose0[2] + ang_step_rad * np.arange(-na, na + 1).astype(np.float64)
    cells = _rotated_cells(points, pose0, ox, oy, res, angles)
    w = int(math.ceil(lin_window_m / res))
    nside = (2 * w + 1 + step - 1) // step
    n_root = angles.shape[0] * nside * nside
    cap = n_root + 4 * levels + 8
    st_a = np.empty(cap, np.int64)
    st_x = np.empty(cap, np.int64)
    st_y = np.empty(cap, np.int64)
    st_l = np.empty(cap, np.int64)
    st_s = np.empty(cap, np.float64)
    root_s = np.empty(n_root, np.float64)
    root_a = np.empty(n_root, np.int64)
    root_x = np.empty(n_root, np.int64)
    root_y = np.empty(n_root, np.int64)
    r = 0
    for a in range(angles.shape[0]):
        for j in range(nside):
            for i in range(nside):
                dx, dy = -w + i * step, -w + j * step
                root_a[r], root_x[r], root_y[r] = a, dx, dy
                root_s[r] = _block_score(pyramid[top], cells, a, dx, dy, step)
                r += 1
    order = _sort_desc(root_s)
    n = 0
    for q in range(n_root - 1, -1, -1):  # worst first, so the best is popped first
        k = order[q]
        st_a[n], st_x[n], st_y[n], st_l[n], st_s[n] = (
            root_a[k],
            root_x[k],
            root_y[k],
            top,
            root_s[k],
        )
        n += 1
    best, best_a, best_x, best_y = min_score, -1, 0, 0
    ch_s = np.empty(4, np.float64)
    ch_x = np.empty(4, np.int64)
    ch_y = np.empty(4, np.int64)
    while n > 0:
        n -= 1
        a, dx, dy, lvl, sc = st_a[n], st_x[n], st_y[n], st_l[n], st_s[n]
        if sc <= best:
            continue
        if lvl == 0:
            best, best_a, best_x, best_y = sc, a, dx, dy
            continue
        half = 1 << (lvl - 1)
        m = 0
        for oy_ in range(2):
            for ox_ in range(2):
                cx, cy = dx + ox_ * half, dy + oy_ * half
                if cx > w or cy > w:
                    continue
                ch_x[m], ch_y[m] = cx, cy
                ch_s[m] = _block_score(pyramid[lvl - 1], cells, a, cx, cy, half)
                m += 1
        order4 = np.argsort(ch_s[:m])  # ascending: best pushed last, popped first
        for q in range(m):
            k = order4[q]
            if ch_s[k] > best:
                st_a[n], st_x[n], st_y[n], st_l[n], st_s[n] = a, ch_x[k], ch_y[k], lvl - 1, ch_s[k]
                n += 1
    if best_a < 0:
        return pose0.copy(), -1.0
    out = np.array([pose0[0] + best_x * res, pose0[1] + best_y * res, angles[best_a]])
    return out, best


@njit(cache=True)
def match_hessian(
    grid: np.ndarray, ox: float, oy: float, res: float, points: np.ndarray, pose: np.ndarray
) -> np.ndarray:
    """``J^T J / n`` (3, 3) of the match residuals at ``pose`` (as :func:`gauss_newton`
    returns it): how sharply the scan's fit changes with each pose increment."""
    n = points.shape[0]
    h = np.zeros((3, 3))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for k in range(n):
        px, py = points[k, 0], points[k, 1]
        _, gx, gy = _bilinear(
            grid, ox, oy, res, pose[0] + c * px - s * py, pose[1] + s * px + c * py
        )
        j = (gx, gy, gx * (-s * px - c * py) + gy * (c * px - s * py))
        for a in range(3):
            for b in range(3):
                h[a, b] += j[a] * j[b]
    return h / max(n, 1)


@njit(cache=True)
def gauss_newton(
    grid: np.ndarray,
    ox: float,
    oy: float,
    res: float,
    points: np.ndarray,
    pose0: np.ndarray,
    iterations: int,
    prior_weight: float,
) -> tuple[np.ndarray, float, np.ndarray]:
    """Refine ``pose0``: minimise ``sum_k (1 - M(T(xi) p_k))^2 + w n |xi - xi_0|^2`` (a weak pull
    towards the start keeps flat directions, e.g. along a corridor, in place). Returns the pose,
    the score ``s(xi)`` and ``J^T J / n`` (3, 3) of the data term at the result."""
    pose = pose0.copy()
    n = points.shape[0]
    h = np.zeros((3, 3))
    for _ in range(iterations):
        h[:] = 0.0
        g = np.zeros(3)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        for k in range(n):
            px, py = points[k, 0], points[k, 1]
            x = pose[0] + c * px - s * py
            y = pose[1] + s * px + c * py
            val, gx, gy = _bilinear(grid, ox, oy, res, x, y)
            j0, j1 = gx, gy
            j2 = gx * (-s * px - c * py) + gy * (c * px - s * py)
            r = 1.0 - val
            h[0, 0] += j0 * j0
            h[0, 1] += j0 * j1
            h[0, 2] += j0 * j2
            h[1, 1] += j1 * j1
            h[1, 2] += j1 * j2
            h[2, 2] += j2 * j2
            g[0] += j0 * r
            g[1] += j1 * r
            g[2] += j2 * r
        h[1, 0], h[2, 0], h[2, 1] = h[0, 1], h[0, 2], h[1, 2]
        a = h.copy()
        lam = prior_weight * n
        for d in range(3):
            a[d, d] += lam + 1e-9
            g[d] -= lam * (pose[d] - pose0[d])
        delta = np.linalg.solve(a, g)
        pose += delta
        if abs(delta[0]) < 1e-5 and abs(delta[1]) < 1e-5 and abs(delta[2]) < 1e-6:
            break
    return pose, score_pose(grid, ox, oy, res, points, pose), h / max(n, 1)
