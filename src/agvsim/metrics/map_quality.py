"""How well a built map matches the true walls, and a trajectory the true path.

A laser sees the *faces* of walls, never their inside, so the truth a map is scored against is
the **wall surface**: the cells (at the map's own resolution) that are occupied in the true
world and share an edge with free space the robot can reach (a flood fill from its start).
The map's occupied cells are those with probability above 0.65 (the ROS ``map_server``
threshold).

A hit exactly on a wall face falls on either side of the cell border, so a cell counts as
matched when a cell of the other set lies within ``tolerance_cells`` (Chebyshev distance):

* precision = matched map cells / map cells; recall = matched surface cells / surface cells;
* IoU = p r / (p + r - p r) -- the intersection over union of the two sets when matched cells
  pair up one to one; with ``tolerance_cells = 0`` it is the plain set IoU.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from agvsim.world.grid import OccupancyGrid

F64 = NDArray[np.float64]


def truth_raster(
    grid: OccupancyGrid, boxes: np.ndarray, resolution_m: float, margin_m: float = 0.0
) -> tuple[NDArray[np.bool_], tuple[float, float]]:
    """The true world (walls and box obstacles) sampled at cell centres of a raster of
    ``resolution_m`` over the grid's extent (plus ``margin_m`` around it, counted occupied:
    the map edge is a wall to the robot). Returns ``(occupied [iy, ix] row 0 south, origin)``."""
    x0, x1, y0, y1 = grid.extent_m
    ox, oy = x0 - margin_m, y0 - margin_m
    w = int(math.ceil((x1 + margin_m - ox) / resolution_m - 1e-9))
    h = int(math.ceil((y1 + margin_m - oy) / resolution_m - 1e-9))
    xs = ox + (np.arange(w) + 0.5) * resolution_m
    ys = oy + (np.arange(h) + 0.5) * resolution_m
    X, Y = np.meshgrid(xs, ys)
    inside = grid.contains(X, Y)
    occ = ~inside
    occ[inside] = grid.is_occupied_at(X[inside], Y[inside])
    for cx, cy, th, hl, hw in np.asarray(boxes, np.float64).reshape(-1, 5):
        c, s = math.cos(th), math.sin(th)
        u = (X - cx) * c + (Y - cy) * s
        v = -(X - cx) * s + (Y - cy) * c
        occ |= (np.abs(u) <= hl) & (np.abs(v) <= hw)
    return occ, (ox, oy)


def wall_surface(
    occupied: NDArray[np.bool_], origin: tuple[float, float], resolution_m: float, start_xy
) -> NDArray[np.bool_]:
    """Occupied cells sharing an edge with the free region that contains ``start_xy``."""
    labels, _ = ndimage.label(~occupied)  # 4-connected free regions
    ix = int((start_xy[0] - origin[0]) / resolution_m)
    iy = int((start_xy[1] - origin[1]) / resolution_m)
    if not (0 <= iy < occupied.shape[0] and 0 <= ix < occupied.shape[1]) or occupied[iy, ix]:
        raise ValueError(f"start {tuple(start_xy)} is not in free space of the true map")
    reach = labels == labels[iy, ix]
    near = ndimage.binary_dilation(reach, structure=ndimage.generate_binary_structure(2, 1))
    return occupied & near


def map_iou(
    probability: F64,
    map_origin: tuple[float, float],
    resolution_m: float,
    grid: OccupancyGrid,
    boxes: np.ndarray,
    start_xy,
    tolerance_cells: int = 1,
    occupied_threshold: float = 0.65,
) -> dict:
    """Score a probability map (``[iy, ix]`` row 0 south, lower-left corner ``map_origin``, in
    the world frame) against the true wall surface. Returns precision, recall, IoU and the cell
    counts, for ``tolerance_cells`` and for 0 (exact cells)."""
    margin = 2.0 * resolution_m + 1.0
    occ, t_origin = truth_raster(grid, boxes, resolution_m, margin)
    surface = wall_surface(occ, t_origin, resolution_m, start_xy)
    # the map's occupied cells, by their centres, in the truth raster
    iy, ix = np.nonzero(np.asarray(probability) > occupied_threshold)
    cx = map_origin[0] + (ix + 0.5) * resolution_m
    cy = map_origin[1] + (iy + 0.5) * resolution_m
    tx = np.floor((cx - t_origin[0]) / resolution_m).astype(np.int64)
    ty = np.floor((cy - t_origin[1]) / resolution_m).astype(np.int64)
    inside = (tx >= 0) & (ty >= 0) & (tx < occ.shape[1]) & (ty < occ.shape[0])
    pred = np.zeros_like(surface)
    pred[ty[inside], tx[inside]] = True
    n_outside = int((~inside).sum())
    out: dict[str, Any] = {
        "map_cells": int(pred.sum()) + n_outside,
        "surface_cells": int(surface.sum()),
    }
    for tol, key in ((tolerance_cells, "tolerant"), (0, "exact")):
        out[key] = _scores(pred, surface, n_outside, tol)
    out["tolerance_cells"] = int(tolerance_cells)
    out["tolerance_m"] = float(tolerance_cells * resolution_m)
    return out


def _scores(pred: NDArray[np.bool_], truth: NDArray[np.bool_], n_outside: int, tol: int) -> dict:
    if tol > 0:
        square = np.ones((2 * tol + 1, 2 * tol + 1), bool)
        near_truth = ndimage.binary_dilation(truth, structure=square)
        near_pred = ndimage.binary_dilation(pred, structure=square)
    else:
        near_truth, near_pred = truth, pred
    n_pred = int(pred.sum()) + n_outside
    n_truth = int(truth.sum())
    p = float((pred & near_truth).sum()) / n_pred if n_pred else 0.0
    r = float((truth & near_pred).sum()) / n_truth if n_truth else 0.0
    iou = p * r / (p + r - p * r) if p > 0 and r > 0 else 0.0
    return {"precision": round(p, 6), "recall": round(r, 6), "iou": round(iou, 6)}


def trajectory_error(estimate: F64, truth: F64) -> dict:
    """Absolute error of poses ``(n, 3)`` against true poses in the same (world) frame: no
    alignment, because the estimate starts at the robot's known initial pose."""
    e = np.asarray(estimate, np.float64)
    t = np.asarray(truth, np.float64)
    if e.shape != t.shape or e.ndim != 2 or e.shape[1] != 3:
        raise ValueError(f"poses must both be (n, 3), got {e.shape} and {t.shape}")
    if len(e) == 0:
        return {"poses": 0}
    d = np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1])
    a = np.abs(np.angle(np.exp(1j * (e[:, 2] - t[:, 2]))))
    return {
        "poses": len(e),
        "mean_m": float(d.mean()),
        "rmse_m": float(np.sqrt((d**2).mean())),
        "max_m": float(d.max()),
        "final_m": float(d[-1]),
        "mean_deg": float(np.degrees(a.mean())),
        "max_deg": float(np.degrees(a.max())),
    }
