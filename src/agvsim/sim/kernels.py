"""Numba kernels of the step loop: moving every body in collision-checked sub-steps."""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from agvsim.geometry import snap_axis
from agvsim.kinematics.base import se2_step
from agvsim.sim.collide import _box_hits_grid, rects_overlap
from agvsim.world.grid import OccupancyGrid


@njit(cache=True, error_model="numpy")
def _blocked(world, x, y, th, off, hl, hw) -> bool:
    """Would a body (centre ``off`` ahead of pose x, y, th; half sizes hl, hw) overlap a wall,
    leave the map or overlap a static box? ``world = (grid_bu, res, ox, oy, static, tab)``."""
    grid_bu, res, ox, oy, static, tab = world
    # snap near-axis headings like the collision module does, so square bodies touch exactly
    c, s = snap_axis(math.cos(th), math.sin(th))
    cx, cy = x + c * off, y + s * off
    if _box_hits_grid(grid_bu, res, ox, oy, cx, cy, c, s, hl, hw):
        return True
    for j in range(static.shape[0]):
        b = static[j]
        dx, dy = b[0] - cx, b[1] - cy
        r = tab[j, 2] + math.hypot(hl, hw)
        if dx * dx + dy * dy < r * r and rects_overlap(
            cx, cy, c, s, hl, hw, b[0], b[1], tab[j, 0], tab[j, 1], b[3], b[4]
        ):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _move_one(i, world, poses, twists, dt, n_sub, body, outs):
    """Move body i; ``body = (offset, half)``, ``outs = (poses, bump, dist, boxes)``."""
    offset, half = body
    out, bump, dist, boxes = outs
    x, y, th = poses[i, 0], poses[i, 1], poses[i, 2]
    out[i, 0], out[i, 1], out[i, 2] = x, y, th
    bump[i] = False
    dist[i] = 0.0
    vx, vy, w = twists[i, 0], twists[i, 1], twists[i, 2]
    if not (vx == 0.0 and vy == 0.0 and w == 0.0):
        for k in range(1, n_sub + 1):
            nx, ny, nth = se2_step(x, y, th, vx, vy, w, dt * k / n_sub)
            if _blocked(world, nx, ny, nth, offset[i], half[i, 0], half[i, 1]):
                bump[i] = True
                break
            out[i, 0], out[i, 1], out[i, 2] = nx, ny, nth
        # path length: the exact arc for a free move, the chord for a move cut short
        if bump[i]:
            dist[i] = math.hypot(out[i, 0] - x, out[i, 1] - y)
        else:
            dist[i] = math.hypot(vx, vy) * dt
    c, s = math.cos(out[i, 2]), math.sin(out[i, 2])
    boxes[i, 0] = out[i, 0] + c * offset[i]
    boxes[i, 1] = out[i, 1] + s * offset[i]
    boxes[i, 2] = out[i, 2]
    boxes[i, 3] = half[i, 0]
    boxes[i, 4] = half[i, 1]


@njit(cache=True)
def _move_serial(world, poses, twists, dt, n_sub, body, outs):
    for i in range(poses.shape[0]):
        _move_one(i, world, poses, twists, dt, n_sub, body, outs)


@njit(cache=True, parallel=True)
def _move_parallel(world, poses, twists, dt, n_sub, body, outs):
    for i in prange(poses.shape[0]):
        _move_one(i, world, poses, twists, dt, n_sub, body, outs)


PARALLEL_MIN_BODIES = 256  # below this, thread start-up costs more than it saves


def move_bodies(
    grid: OccupancyGrid,
    poses: np.ndarray,
    twists: np.ndarray,
    dt: float,
    n_sub: int,
    offset: np.ndarray,
    half: np.ndarray,
    static: np.ndarray,
    static_tab: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Integrate every body ``(N, 3)`` by its twist over ``dt`` in ``n_sub`` exact sub-steps;
    a body whose footprint (centre ``offset`` m ahead of the pose, half sizes ``half (N, 2)``)
    would overlap a wall, leave the map or overlap a static box stops at its last free
    sub-step. Returns the new poses, the ``(N,)`` bump flags, the ``(N,)`` path lengths and
    the ``(N, 5)`` footprints at the new poses."""
    n = poses.shape[0]
    out = np.empty_like(poses)
    bump = np.zeros(n, dtype=np.bool_)
    dist = np.zeros(n)
    boxes = np.empty((n, 5))
    kernel = _move_parallel if n >= PARALLEL_MIN_BODIES else _move_serial
    ox, oy = grid.origin_xy_m
    world = (grid.cells_bu, grid.resolution_m, ox, oy, static, static_tab)
    kernel(world, poses, twists, dt, n_sub, (offset, half), (out, bump, dist, boxes))
    return out, bump, dist, boxes


@njit(cache=True, error_model="numpy")
def _box_overlap(a, b) -> bool:
    """Do boxes a and b (rows cx, cy, theta, half_length, half_width) overlap?"""
    ca, sa = math.cos(a[2]), math.sin(a[2])
    cb, sb = math.cos(b[2]), math.sin(b[2])
    return rects_overlap(a[0], a[1], ca, sa, a[3], a[4], b[0], b[1], cb, sb, b[3], b[4])


@njit(cache=True)
def pair_faults(new_boxes: np.ndarray, old_boxes: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """For each overlapping pair (i, j) of new footprints: ``(P, 2)`` bool, whether i's move
    ran into j's old place and whether j's ran into i's. A robot that did not run into the
    other one may keep its move (it may be backing away)."""
    out = np.zeros((pairs.shape[0], 2), dtype=np.bool_)
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        out[k, 0] = _box_overlap(new_boxes[i], old_boxes[j])
        out[k, 1] = _box_overlap(new_boxes[j], old_boxes[i])
    return out
