"""Shared 2-D geometry kernels (numba, free functions) for ray casting and collisions.

Boxes are ``(K, 5)`` float64 rows ``cx, cy, theta, half_length, half_width`` (metres, radians,
world frame; half_length along the box's own x axis). Headings within :data:`SNAP` of a multiple
of pi/2 are snapped to exact axis directions (:func:`snap_axis`), so that axis-aligned boxes and
beams touch exactly. A uniform bin grid of points (:func:`build_center_bins`, queried with
:func:`bin_window`) is the broad phase of both the ray caster's box part and the collider.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SNAP = 1e-12  # direction components below this are exactly 0 (axis-parallel beams and boxes)


@njit(cache=True, error_model="numpy")
def snap_axis(c: float, s: float) -> tuple[float, float]:
    """The unit direction ``(c, s)`` with a component below :data:`SNAP` in magnitude snapped to
    0 (and the other to +-1), so that near-axis directions are exactly axis-parallel."""
    if abs(c) < SNAP:
        return 0.0, math.copysign(1.0, s)
    if abs(s) < SNAP:
        return math.copysign(1.0, c), 0.0
    return c, s


@njit(cache=True, error_model="numpy")
def build_center_bins(xy: np.ndarray, bin_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform bin grid (counting sort) over the points ``xy[:, 0], xy[:, 1]`` (metres).

    Returns ``start (nbins + 1,)`` and ``items (K,)`` (the indices in bin ``b`` are
    ``items[start[b]:start[b + 1]]``, ascending) and ``geom = [xmin, ymin, size, nbx, nby]``.
    Bins are at least ``bin_size`` wide (grown so that there are at most ``4 K + 16``), so every
    point within ``bin_size`` of a query point lies in the 3x3 bins around it.
    """
    k = xy.shape[0]
    geom = np.zeros(5)
    if k == 0:
        return np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), geom
    xmin, xmax, ymin, ymax = xy[0, 0], xy[0, 0], xy[0, 1], xy[0, 1]
    for i in range(1, k):
        xmin, xmax = min(xmin, xy[i, 0]), max(xmax, xy[i, 0])
        ymin, ymax = min(ymin, xy[i, 1]), max(ymax, xy[i, 1])
    size = max(bin_size, 1e-9 * max(1.0, xmax - xmin, ymax - ymin))
    cap = 4.0 * k + 16.0
    while (math.floor((xmax - xmin) / size) + 1.0) * (math.floor((ymax - ymin) / size) + 1.0) > cap:
        size *= 2.0
    nbx = int(math.floor((xmax - xmin) / size)) + 1
    nby = int(math.floor((ymax - ymin) / size)) + 1
    geom[0], geom[1], geom[2], geom[3], geom[4] = xmin, ymin, size, nbx, nby
    bin_of = np.empty(k, dtype=np.int64)
    start = np.zeros(nbx * nby + 1, dtype=np.int64)
    for i in range(k):
        bx = min(int((xy[i, 0] - xmin) / size), nbx - 1)
        by = min(int((xy[i, 1] - ymin) / size), nby - 1)
        bin_of[i] = by * nbx + bx
        start[bin_of[i] + 1] += 1
    for b in range(nbx * nby):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    items = np.empty(k, dtype=np.int64)
    for i in range(k):
        items[fill[bin_of[i]]] = i
        fill[bin_of[i]] += 1
    return start, items, geom


@njit(cache=True, error_model="numpy")
def bin_window(geom: np.ndarray, x: float, y: float) -> tuple[int, int, int, int]:
    """Inclusive bin ranges ``bx0, bx1, by0, by1`` of the 3x3 bins around ``(x, y)`` clipped to
    the bin grid (empty when ``bx0 > bx1``)."""
    size, nbx, nby = geom[2], geom[3], geom[4]
    if nbx == 0.0:
        return 0, -1, 0, -1
    fx = min(max((x - geom[0]) / size, -2.0), nbx + 2.0)
    fy = min(max((y - geom[1]) / size, -2.0), nby + 2.0)
    bx, by = int(math.floor(fx)), int(math.floor(fy))
    return max(bx - 1, 0), min(bx + 1, int(nbx) - 1), max(by - 1, 0), min(by + 1, int(nby) - 1)


@njit(cache=True, error_model="numpy")
def box_tables(boxes: np.ndarray) -> np.ndarray:
    """``(K, 3)``: cos(theta), sin(theta) (:func:`snap_axis`, like beam directions) and bounding
    radius."""
    tab = np.empty((boxes.shape[0], 3))
    for j in range(boxes.shape[0]):
        tab[j, 0], tab[j, 1] = snap_axis(math.cos(boxes[j, 2]), math.sin(boxes[j, 2]))
        tab[j, 2] = math.hypot(boxes[j, 3], boxes[j, 4])
    return tab


@njit(cache=True, error_model="numpy")
def ray_box(px: float, py: float, lc: float, ls: float, hl: float, hw: float) -> float:
    """Slab test in the box frame: distance along the unit direction ``(lc, ls)`` from ``(px, py)``
    to the closed rectangle ``|x| <= hl, |y| <= hw``; 0 from inside, inf on a miss."""
    tn, tf = -np.inf, np.inf
    if lc == 0.0:
        if px < -hl or px > hl:
            return np.inf
    else:
        ta, tb = (-hl - px) / lc, (hl - px) / lc
        tn, tf = min(ta, tb), max(ta, tb)
    if ls == 0.0:
        if py < -hw or py > hw:
            return np.inf
    else:
        ta, tb = (-hw - py) / ls, (hw - py) / ls
        tn, tf = max(tn, min(ta, tb)), min(tf, max(ta, tb))
    if tn > tf or tf < 0.0:
        return np.inf
    return max(tn, 0.0)
