"""Collision tests between oriented boxes and the walls, static boxes and each other (numba).

Boxes are ``(K, 5)`` float64 rows ``cx, cy, theta, half_length, half_width`` (metres, radians,
world frame; half_length along the box's own x axis), for robot footprints and static obstacles
alike. Two shapes *overlap* when their intersection has positive area: shapes that only touch
along an edge or at a corner do not collide. Every test is an exact separating-axis test (SAT)
in float64; orientations within ``1e-12`` of a multiple of pi/2 are snapped so that axis-aligned
boxes touch exactly.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from agvsim.geometry import bin_window, box_tables, build_center_bins
from agvsim.world.grid import OccupancyGrid


@njit(cache=True, error_model="numpy")
def rects_overlap(ax, ay, ac, as_, ahl, ahw, bx, by, bc, bs, bhl, bhw) -> bool:
    """SAT: do the oriented rectangles (centre, cos/sin of heading, half sizes) overlap with
    positive area? Touching rectangles do not."""
    dx, dy = bx - ax, by - ay
    cc = abs(ac * bc + as_ * bs)  # |cos(theta_b - theta_a)|
    ss = abs(as_ * bc - ac * bs)  # |sin(theta_b - theta_a)|
    # axes of a
    if not abs(dx * ac + dy * as_) < ahl + bhl * cc + bhw * ss:
        return False
    if not abs(-dx * as_ + dy * ac) < ahw + bhl * ss + bhw * cc:
        return False
    # axes of b
    if not abs(dx * bc + dy * bs) < bhl + ahl * cc + ahw * ss:
        return False
    return abs(-dx * bs + dy * bc) < bhw + ahl * ss + ahw * cc


@njit(cache=True, error_model="numpy")
def _box_hits_grid(grid_bu, res, ox, oy, x, y, c, s, hl, hw) -> bool:
    ny, nx = grid_bu.shape
    ex = hl * abs(c) + hw * abs(s)  # half extents of the box's axis-aligned bounding box
    ey = hl * abs(s) + hw * abs(c)
    x0, x1, y0, y1 = x - ex, x + ex, y - ey, y + ey
    if x0 < ox or y0 < oy or x1 > ox + nx * res or y1 > oy + ny * res:
        return True  # leaves the map
    i0 = max(int(math.floor((x0 - ox) / res)) - 1, 0)
    i1 = min(int(math.floor((x1 - ox) / res)) + 1, nx - 1)
    j0 = max(int(math.floor((y0 - oy) / res)) - 1, 0)
    j1 = min(int(math.floor((y1 - oy) / res)) + 1, ny - 1)
    h = 0.5 * res
    for j in range(j0, j1 + 1):
        cy0, cy1 = oy + j * res, oy + (j + 1) * res
        if not (y1 > cy0 and cy1 > y0):
            continue
        for i in range(i0, i1 + 1):
            if grid_bu[j, i] == 0:
                continue
            cx0, cx1 = ox + i * res, ox + (i + 1) * res
            if not (x1 > cx0 and cx1 > x0):
                continue  # the world axes, exactly on the cell faces
            dx, dy = 0.5 * (cx0 + cx1) - x, 0.5 * (cy0 + cy1) - y
            if abs(dx * c + dy * s) < hl + h * (abs(c) + abs(s)) and abs(
                -dx * s + dy * c
            ) < hw + h * (abs(c) + abs(s)):
                return True
    return False


@njit(cache=True, parallel=True, error_model="numpy")
def boxes_hit_grid(grid_bu, res, ox, oy, boxes):
    """``(N,)`` bool: box i overlaps an occupied cell of ``grid_bu (ny, nx)`` (bottom-up, cell
    (iy, ix) covers ``[ox + ix res, ox + (ix + 1) res) x [oy + iy res, ...)``), or reaches
    outside the map rectangle (touching its border from inside is fine)."""
    n = boxes.shape[0]
    hit = np.zeros(n, dtype=np.bool_)
    tab = box_tables(boxes)
    for i in prange(n):
        hit[i] = _box_hits_grid(
            grid_bu,
            res,
            ox,
            oy,
            boxes[i, 0],
            boxes[i, 1],
            tab[i, 0],
            tab[i, 1],
            boxes[i, 3],
            boxes[i, 4],
        )
    return hit


@njit(cache=True, error_model="numpy")
def _overlap(boxes, tab, i, others, otab, j) -> bool:
    dx, dy = others[j, 0] - boxes[i, 0], others[j, 1] - boxes[i, 1]
    r = tab[i, 2] + otab[j, 2]
    if dx * dx + dy * dy >= r * r * (1.0 + 1e-12):
        return False  # bounding circles apart
    return rects_overlap(
        boxes[i, 0],
        boxes[i, 1],
        tab[i, 0],
        tab[i, 1],
        boxes[i, 3],
        boxes[i, 4],
        others[j, 0],
        others[j, 1],
        otab[j, 0],
        otab[j, 1],
        others[j, 3],
        others[j, 4],
    )


@njit(cache=True, error_model="numpy")
def boxes_hit_boxes(boxes, others):
    """``(N,)`` bool: box i overlaps any of ``others (M, 5)`` (static obstacles)."""
    n = boxes.shape[0]
    hit = np.zeros(n, dtype=np.bool_)
    if n == 0 or others.shape[0] == 0:
        return hit
    tab, otab = box_tables(boxes), box_tables(others)
    size = tab[:, 2].max() + otab[:, 2].max()
    start, items, geom = build_center_bins(others, size)
    nbx = int(geom[3])
    for i in range(n):
        bx0, bx1, by0, by1 = bin_window(geom, boxes[i, 0], boxes[i, 1])
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                b = by * nbx + bx
                for q in range(start[b], start[b + 1]):
                    if not hit[i] and _overlap(boxes, tab, i, others, otab, items[q]):
                        hit[i] = True
    return hit


@njit(cache=True, error_model="numpy")
def _pairs_of(i, boxes, tab, start, items, geom, dst, at):
    """Count the boxes j > i overlapping box i; write them to ``dst[at:]`` as pairs (i, j) when
    ``at >= 0``."""
    bx0, bx1, by0, by1 = bin_window(geom, boxes[i, 0], boxes[i, 1])
    nbx = int(geom[3])
    m = 0
    for by in range(by0, by1 + 1):
        for bx in range(bx0, bx1 + 1):
            b = by * nbx + bx
            for q in range(start[b], start[b + 1]):
                j = items[q]
                if j > i and _overlap(boxes, tab, i, boxes, tab, j):
                    if at >= 0:
                        dst[at + m, 0], dst[at + m, 1] = i, j
                    m += 1
    return m


@njit(cache=True, error_model="numpy")
def box_pairs_overlapping(boxes):
    """``(P, 2)`` int64: every pair ``i < j`` of ``boxes (N, 5)`` that overlap, sorted by
    ``(i, j)``. Broad phase: bins of box centres (see below), a 3 x 3 window of bins each."""
    n = boxes.shape[0]
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    tab = box_tables(boxes)
    # bins at least 2 bounding radii wide (a 3 x 3 window then finds every partner), and
    # wide enough that there are about as many bins as boxes: few empty bins to clear
    span = max(boxes[:, 0].max() - boxes[:, 0].min(), boxes[:, 1].max() - boxes[:, 1].min())
    start, items, geom = build_center_bins(boxes, max(2.0 * tab[:, 2].max(), span / math.sqrt(n)))
    dummy = np.empty((0, 2), dtype=np.int64)
    m = 0
    for i in range(n):  # count first, so the output is allocated once
        m += _pairs_of(i, boxes, tab, start, items, geom, dummy, -1)
    pairs = np.empty((m, 2), dtype=np.int64)
    m = 0
    for i in range(n):
        k = _pairs_of(i, boxes, tab, start, items, geom, pairs, m)
        for q in range(m + 1, m + k):  # insertion sort of the few partners j of box i
            j, p = pairs[q, 1], q
            while p > m and pairs[p - 1, 1] > j:
                pairs[p, 1] = pairs[p - 1, 1]
                p -= 1
            pairs[p, 1] = j
        m += k
    return pairs


def _boxes(name: str, a) -> np.ndarray:
    arr = np.ascontiguousarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 5:
        raise ValueError(
            f"{name} must have shape (N, 5): cx, cy, theta, half_length, half_width;"
            f" got {arr.shape}"
        )
    if not np.all(np.isfinite(arr)) or np.any(arr[:, 3:] < 0):
        raise ValueError(f"{name} must be finite with half sizes >= 0")
    return arr


class Collider:
    """Collision queries against one occupancy grid; boxes are ``(N, 5)`` as above."""

    def __init__(self, grid: OccupancyGrid) -> None:
        self.set_grid(grid)

    def set_grid(self, grid: OccupancyGrid) -> None:
        self.grid = grid
        self._cells = np.ascontiguousarray(grid.cells_bu, dtype=np.uint8)
        self._res = float(grid.resolution_m)
        self._ox, self._oy = (float(v) for v in grid.origin_xy_m)

    def hit_walls(self, boxes: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: box overlaps a wall cell or leaves the map."""
        return boxes_hit_grid(self._cells, self._res, self._ox, self._oy, _boxes("boxes", boxes))

    def hit_static(self, boxes: np.ndarray, static: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: box overlaps one of the ``static (M, 5)`` boxes."""
        return boxes_hit_boxes(_boxes("boxes", boxes), _boxes("static", static))

    def overlapping_pairs(self, boxes: np.ndarray) -> np.ndarray:
        """``(P, 2)`` int64 sorted pairs ``i < j`` of overlapping boxes."""
        return box_pairs_overlapping(_boxes("boxes", boxes))


def warmup() -> float:
    """Compile (or load from cache) the collision kernels; returns the seconds it took."""
    import time

    t0 = time.perf_counter()
    col = Collider(OccupancyGrid(np.array([[0, 0], [0, 1]], dtype=bool), 1.0, (0.0, 0.0)))
    b = np.array([[0.5, 1.5, 0.1, 0.3, 0.2], [0.7, 1.5, 0.0, 0.3, 0.2]])
    col.hit_walls(b)
    col.hit_static(b, b[:1])
    col.overlapping_pairs(b)
    return time.perf_counter() - t0
