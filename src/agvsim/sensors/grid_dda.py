"""The grid part of the ray caster: an Amanatides-Woo DDA over a padded occupancy table (numba).

Cells are closed squares: a beam that grazes a wall face or passes exactly through a wall corner
hits it, and a beam through the shared corner of two diagonal wall cells can never slip between
them; "exactly" means within :func:`corner_eps` (``1e-12`` x the map's size) of the corner or
face, and an origin that close to a face is cast from the face itself (``cast_sensor`` in
:mod:`agvsim.sensors.raycast`). The DDA runs in float64 over a copy of the grid padded with a
ring of "outside" cells (:func:`pad_grid`: no bounds test per step); the distance returned is
recomputed from the entry face of the hit cell, ``(ox + k * res - x) / cos(angle)``, so it does
not accumulate rounding. Empty-space skipping (:func:`mark_empty_space`) lets the DDA jump
across squares of free cells found by a chessboard distance transform; it visits the same hit
cell, so results are identical. The entry point is :func:`grid_beams`, called by
:mod:`agvsim.sensors.raycast` per sensor.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

OUTSIDE = 2  # code of the ring of cells around the map in the kernel's table (see pad_grid)
JUMP = 3  # codes >= JUMP: free cells in the middle of empty space
_JUMP_MIN = 3  # smallest free radius (cells) worth a jump instead of DDA steps
_CORNER_TOL = 1e-12  # relative to the map's size: beams this close to a cell corner touch it


# ---------------------------------------------------------------------------- tables
@njit(cache=True, error_model="numpy")
def pad_grid(grid_bu: np.ndarray) -> np.ndarray:
    """The kernel's table: a flat uint8 copy of ``grid_bu (ny, nx)`` with a one-cell ring around
    it, shape ``((ny + 2) * (nx + 2),)``; cell ``(iy, ix)`` is at ``(iy + 1) * (nx + 2) + ix + 1``.
    Codes: 1 occupied, 0 free, ``OUTSIDE`` (2) the ring; see :func:`mark_empty_space`."""
    ny, nx = grid_bu.shape
    w = nx + 2
    out = np.full((ny + 2) * w, OUTSIDE, dtype=np.uint8)
    for iy in range(ny):
        for ix in range(nx):
            out[(iy + 1) * w + ix + 1] = 1 if grid_bu[iy, ix] != 0 else 0
    return out


@njit(cache=True, error_model="numpy")
def mark_empty_space(cells: np.ndarray, nx: int, ny: int) -> None:
    """Empty-space skipping, in place: a free cell whose every cell within Chebyshev distance
    ``r >= _JUMP_MIN`` is free and on the map gets code ``JUMP + r - _JUMP_MIN`` (capped at 255),
    and the DDA jumps across that square. Radii from a two-pass chessboard distance transform."""
    h, w = ny + 2, nx + 2
    dist = np.where(cells == 0, h + w, 0).astype(np.int32)  # to the nearest wall or ring cell
    for i in range(1, h - 1):
        for j in range(i * w + 1, i * w + w - 1):
            m = min(dist[j - w - 1], dist[j - w], dist[j - w + 1], dist[j - 1]) + 1
            dist[j] = min(dist[j], m)
    for i in range(h - 2, 0, -1):
        for j in range(i * w + w - 2, i * w, -1):
            m = min(dist[j + w + 1], dist[j + w], dist[j + w - 1], dist[j + 1]) + 1
            dist[j] = min(dist[j], m)
    for j in range(h * w):
        r = dist[j] - 1  # free radius
        if cells[j] == 0 and r >= _JUMP_MIN:
            cells[j] = JUMP + min(r - _JUMP_MIN, 255 - JUMP)


# ---------------------------------------------------------------------------- DDA
@njit(cache=True, error_model="numpy")
def _cell_of(v: float, o: float, res: float, n: int) -> tuple[int, bool]:
    """Cell index of coordinate ``v`` (half-open cells ``[o + i res, o + (i + 1) res)``), clamped to
    ``[-2, n + 2]``, and whether ``v`` lies exactly on the cell's low face."""
    g = (v - o) / res
    if not g > -2.0:
        return -2, False
    if g > n + 2.0:
        return n + 2, False
    i = int(math.floor(g))
    if o + i * res > v:
        i -= 1
    elif o + (i + 1) * res <= v:
        i += 1
    return i, o + i * res == v


@njit(cache=True, error_model="numpy")
def origin_cell(v: float, o: float, res: float, n: int, eps: float) -> tuple[int, bool]:
    """:func:`_cell_of` for a sensor origin, taking a coordinate within ``eps`` of a cell face as
    on it (so that a beam running a hair beside a wall face grazes it, like beams passing within
    eps of a corner)."""
    i, on = _cell_of(v, o, res, n)
    if not on and -2 < i < n + 2:
        if o + (i + 1) * res - v <= eps:
            return i + 1, True
        if v - (o + i * res) <= eps:
            return i, True
    return i, on


@njit(cache=True, error_model="numpy")
def _axis_ray(cells, idx, lane, stride, k, n, d, p0, o, res, tlim):
    """Beam parallel to one axis: step along it from cell ``k`` (flat index ``idx``), testing the
    cells at ``idx`` and ``idx + lane`` (the second lane when the beam runs on a cell face)."""
    if (k >= n and d > 0.0) or (k < 0 and d < 0.0):
        return np.inf
    ks = 1 if d > 0.0 else -1
    step = stride * ks
    tm = (o + (k + 1 if d > 0.0 else k) * res - p0) / d
    td = res / abs(d)
    tl = tlim + 1e-9 * (1.0 + tlim)
    while tm <= tl:
        idx += step
        k += ks
        a = cells[idx]
        b = cells[idx + lane]
        if a | b:
            if a == 1 or b == 1:
                t = (o + (k if d > 0.0 else k + 1) * res - p0) / d
                return t if t <= tlim else np.inf
            if a == OUTSIDE and b == OUTSIDE:
                return np.inf
        tm += td
    return np.inf


@njit(cache=True, error_model="numpy")
def corner_eps(nx, ny, res, ox, oy, x0, y0):
    """Corner tolerance for beams from ``(x0, y0)``: a beam passing this close to a cell corner
    touches it (the ulp between cos(pi/4) and sin(pi/4) must not decide whether a diagonal beam
    grazes a wall corner). ``_CORNER_TOL`` times the size of the coordinates involved."""
    return _CORNER_TOL * (res + abs(x0 - ox) + abs(y0 - oy) + (nx + ny) * res)


@njit(cache=True, error_model="numpy")
def _jump(v, idx, sx, sy, tmx, tmy, tdx, tdy, ax, ay, eps):
    """Skip the free square of radius ``r = v - JUMP + _JUMP_MIN`` cells around cell ``idx``: the
    beam leaves it at ``t = min(tmx + r tdx, tmy + r tdy)``; count the x and y faces it crosses
    before ``t - eps`` (at most r each) and advance the DDA state by them. Counting a touch
    before the exit keeps the state on or behind the beam, never ahead of it, so the DDA that
    resumes catches up inside the square (all free) and misses nothing."""
    r = v - JUMP + _JUMP_MIN
    t = min(tmx + r * tdx, tmy + r * tdy)
    kx = min(max(math.floor((t - eps - tmx) * ax) + 1, 0), r)  # ax = 1 / tdx
    ky = min(max(math.floor((t - eps - tmy) * ay) + 1, 0), r)
    return t, idx + kx * sx + ky * sy, tmx + kx * tdx, tmy + ky * tdy


@njit(cache=True, error_model="numpy")
def _axis_beam(cells, nx, ny, res, ox, oy, x0, y0, ix, onx, iy, ony, c, s, tlim):
    """Beam along x (``s == 0``) or y (``c == 0``): see :func:`_axis_ray`."""
    w = nx + 2
    if s == 0.0:
        if iy < 0 or iy > ny or (iy == ny and not ony):
            return np.inf
        k = min(max(ix - 1 if (c < 0.0 and onx) else ix, -1), nx)
        lane = -w if ony else 0
        return _axis_ray(cells, (iy + 1) * w + k + 1, lane, 1, k, nx, c, x0, ox, res, tlim)
    if ix < 0 or ix > nx or (ix == nx and not onx):
        return np.inf
    k = min(max(iy - 1 if (s < 0.0 and ony) else iy, -1), ny)
    lane = -1 if onx else 0
    return _axis_ray(cells, (k + 1) * w + ix + 1, lane, w, k, ny, s, y0, oy, res, tlim)


@njit(cache=True, error_model="numpy")
def _entry_cell(nx, ny, res, ox, oy, x0, y0, c, s, ic, is_, eps, tlim):
    """For an origin off the map: the ring cell ``(cx, cy)`` just before the beam enters the map,
    or ``(-2, -2)`` if it misses the map within ``tlim``. The cell across the beam is taken a
    touch before the entry point, so an entry within eps of a cell corner takes the DDA's corner
    branch."""
    xa, xb = (ox - x0) * ic, (ox + nx * res - x0) * ic
    ya, yb = (oy - y0) * is_, (oy + ny * res - y0) * is_
    txi, txo = min(xa, xb), max(xa, xb)
    tyi, tyo = min(ya, yb), max(ya, yb)
    tin, tout = max(txi, tyi), min(txo, tyo)
    if tin > tout + eps or tout < 0.0 or tin > tlim:
        return -2, -2
    if txi >= tyi:
        cy = _cell_of(y0 + tin * s - math.copysign(eps, s), oy, res, ny)[0]
        return (-1 if c > 0.0 else nx), min(max(cy, 0), ny - 1)
    cx = _cell_of(x0 + tin * c - math.copysign(eps, c), ox, res, nx)[0]
    return min(max(cx, 0), nx - 1), (-1 if s > 0.0 else ny)


@njit(cache=True, error_model="numpy")
def grid_beams(table, x0, y0, org, eps, dirs, n, r_max, row):
    """Lower ``row[k]`` (``k < n``) to the distance from ``(x0, y0)`` along the unit direction
    ``dirs[k, :2]`` (``dirs[k, 2:] = 1 / dirs[k, :2]``) to the first occupied cell, if within
    ``min(r_max, row[k])``. ``table = (cells, nx, ny, res, ox, oy)`` (:func:`pad_grid`).

    ``org = (ix, onx, iy, ony, inside)``: the origin's cell (:func:`origin_cell`) and whether it
    is in the closed map rectangle, in which case the caller has checked that it touches no
    occupied cell. Beams passing within ``eps`` (:func:`corner_eps`) of a cell corner touch it.
    """
    cells, nx, ny, res, ox, oy = table
    ix, onx, iy, ony, inside = org
    w = nx + 2
    inv_res, inv_w = 1.0 / res, 1.0 / w
    for k in range(n):
        c, s, ic, is_ = dirs[k, 0], dirs[k, 1], dirs[k, 2], dirs[k, 3]
        tlim = min(r_max, row[k])
        if s == 0.0 or c == 0.0:  # axis-parallel: may run along a face, touching two lanes
            t = _axis_beam(cells, nx, ny, res, ox, oy, x0, y0, ix, onx, iy, ony, c, s, tlim)
            row[k] = min(row[k], t)
            continue
        if inside:
            cx = ix - 1 if (c < 0.0 and onx) else ix
            cy = iy - 1 if (s < 0.0 and ony) else iy
        else:  # start in the ring cell before the entry face
            cx, cy = _entry_cell(nx, ny, res, ox, oy, x0, y0, c, s, ic, is_, eps, tlim)
            if cx == -2:
                continue
        out_x = (cx >= nx and c > 0.0) or (cx < 0 and c < 0.0)
        if out_x or (cy >= ny and s > 0.0) or (cy < 0 and s < 0.0):
            continue  # starts on the map border heading out
        sx = 1 if c > 0.0 else -1
        sy = w if s > 0.0 else -w
        tmx = (ox + (cx + 1 if c > 0.0 else cx) * res - x0) * ic
        tmy = (oy + (cy + 1 if s > 0.0 else cy) * res - y0) * is_
        tdx, tdy = res * abs(ic), res * abs(is_)
        ax, ay = abs(c) * inv_res, abs(s) * inv_res
        tl = tlim + 1e-9 * (1.0 + tlim)
        idx = (cy + 1) * w + cx + 1
        v = cells[idx] if inside else 0
        if v >= JUMP:
            t, idx, tmx, tmy = _jump(v, idx, sx, sy, tmx, tmy, tdx, tdy, ax, ay, eps)
            if t > tl:
                continue
        hit = False
        while True:
            d = tmx - tmy
            if d < -eps:
                if tmx > tl:
                    break
                idx += sx
                tmx += tdx
            elif d > eps:
                if tmy > tl:
                    break
                idx += sy
                tmy += tdy
            else:  # through a cell corner: the two side cells touch the beam too
                if tmx > tl:
                    break
                hit = cells[idx + sx] == 1 or cells[idx + sy] == 1
                idx += sx + sy
                tmx += tdx
                tmy += tdy
                if hit:
                    break
            v = cells[idx]
            if v != 0:
                hit = v == 1
                if v < JUMP:
                    break
                t, idx, tmx, tmy = _jump(v, idx, sx, sy, tmx, tmy, tdx, tdy, ax, ay, eps)
                if t > tl:
                    break
        if hit:  # entry distance of the hit cell (its later entry face), correctly rounded
            gy = int((idx + 0.5) * inv_w) - 1
            gx = idx - (gy + 1) * w - 1
            tx = (ox + (gx if c > 0.0 else gx + 1) * res - x0) / c
            t = max(tx, (oy + (gy if s > 0.0 else gy + 1) * res - y0) / s)
            if t <= tlim:
                row[k] = min(row[k], t)
