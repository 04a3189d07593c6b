"""Batched 2-D ray casting: every beam of every sensor of every robot in one numba kernel call.

World frame (REP-103), metres and radians. A beam starts at its sensor origin and returns the
distance to the first point where it *touches* an obstacle, where obstacles are

- the occupied cells of an :class:`~agvsim.world.grid.OccupancyGrid`, taken as closed squares:
  a beam that grazes a wall face or passes exactly through a wall corner hits it, and a beam
  through the shared corner of two diagonal wall cells can never slip between them;
- oriented boxes ``(K, 5)``: ``cx, cy, theta, half_length, half_width`` (half_length along the
  box's own x axis), also closed; robot footprints and static box obstacles alike.

Conventions: no return within ``max_range`` reads ``+inf`` (a hit at exactly ``max_range``
counts); a sensor whose origin lies in or on an occupied cell reads ``0.0`` on every beam, and
a beam whose origin lies inside a (not ignored) box reads ``0.0``. The map is surrounded by open
space: a beam that leaves the map sees no more walls but still sees boxes. ``NaN`` beam angles
pad sensors that have fewer beams than the widest one; they read ``+inf``.

Grid part: an Amanatides-Woo DDA in float64 over a copy of the grid padded with a ring of
"outside" cells (no bounds test per step); the distance returned is recomputed from the entry
face of the hit cell, ``(ox + k * res - x) / cos(angle)``, so it does not accumulate rounding.
Empty-space skipping (:func:`mark_empty_space`) lets the DDA jump across squares of free cells
found by a chessboard distance transform; it visits the same hit cell, so results are identical.
"Exactly" means to float64 rounding: a beam passing within ``1e-12`` x the map's size of a cell
corner, or running that close along a cell face, touches it, so that the ulp between e.g.
cos(pi/4) and sin(pi/4) does not decide whether a diagonal beam grazes a wall corner.
Box part: a uniform bin grid of box centres (bins ~ max range) picks the boxes near each sensor,
the angular interval of each box's bounding circle picks the beams (when a sensor's beams are
evenly spaced), and an exact slab test gives the distance.

Beam directions: when a sensor's beams are evenly spaced (to within ``1e-12`` rad, modulo
``2 pi``) their cos/sin come from rotating a few exact anchors by a small table, which is as
exact as calling cos/sin per beam (a few ulp) at a fraction of the cost. Direction components
below ``1e-12`` are snapped to 0 so that beams at multiples of pi/2 are exactly axis-parallel.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit, prange

from agvsim.world.grid import OccupancyGrid

OUTSIDE = 2  # code of the ring of cells around the map in the kernel's table (see pad_grid)
JUMP = 3  # codes >= JUMP: free cells in the middle of empty space
_JUMP_MIN = 3  # smallest free radius (cells) worth a jump instead of DDA steps
_UNIFORM_TOL = 1e-12  # rad: beams this close to an even spacing are treated as evenly spaced
_SNAP = 1e-12  # direction components below this are exactly 0 (axis-parallel beams)
_TABLE = 16  # beams per exact cos/sin anchor for evenly spaced beams
_CORNER_TOL = 1e-12  # relative to the map's size: beams this close to a cell corner touch it
_TWO_PI = 2.0 * math.pi


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
    """``(K, 3)``: cos(theta), sin(theta) (snapped like beam directions) and bounding radius."""
    tab = np.empty((boxes.shape[0], 3))
    for j in range(boxes.shape[0]):
        c, s = math.cos(boxes[j, 2]), math.sin(boxes[j, 2])
        if abs(c) < _SNAP:
            c, s = 0.0, math.copysign(1.0, s)
        elif abs(s) < _SNAP:
            c, s = math.copysign(1.0, c), 0.0
        tab[j, 0], tab[j, 1] = c, s
        tab[j, 2] = math.hypot(boxes[j, 3], boxes[j, 4])
    return tab


# ---------------------------------------------------------------------------- grid part
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
def _origin_cell(v: float, o: float, res: float, n: int, eps: float) -> tuple[int, bool]:
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

    ``org = (ix, onx, iy, ony, inside)``: the origin's cell (:func:`_origin_cell`) and whether it
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


# ---------------------------------------------------------------------------- beams and boxes
@njit(cache=True, error_model="numpy")
def beam_directions(angles: np.ndarray, dirs: np.ndarray) -> tuple[int, bool, float]:
    """Unit directions of one sensor's beams into ``dirs (B, 4)``: cos, sin, 1 / cos, 1 / sin.

    Returns ``n`` (beams before the first NaN when all later ones are NaN, else ``B``), whether
    beams ``0..n-1`` are evenly spaced (``angles[k] = angles[0] + k * step`` within
    ``_UNIFORM_TOL`` modulo 2 pi) and that step. NaN beams get direction NaN.
    """
    b = angles.shape[0]
    n = b
    for k in range(b):
        if math.isnan(angles[k]):
            n = k
            break
    for k in range(n, b):
        if not math.isnan(angles[k]):
            n = b
            break
    step = (angles[n - 1] - angles[0]) / (n - 1) if n >= 2 else 0.0
    uniform = n >= 2 and 1e-9 < abs(step) < 1e3  # the broad phase divides by the step
    if uniform:
        for k in range(n):
            e = angles[k] - (angles[0] + k * step)
            e -= _TWO_PI * math.floor(e / _TWO_PI + 0.5)
            if not abs(e) <= _UNIFORM_TOL:
                uniform = False
                break
    if uniform:
        m = min(_TABLE, n)
        tc, ts = np.empty(m), np.empty(m)
        for j in range(m):
            tc[j], ts[j] = math.cos(j * step), math.sin(j * step)
        ca = sa = 0.0
        j = 0
        for k in range(n):
            if j == 0:
                ca, sa = math.cos(angles[k]), math.sin(angles[k])
            dirs[k, 0] = ca * tc[j] - sa * ts[j]
            dirs[k, 1] = sa * tc[j] + ca * ts[j]
            j = j + 1 if j + 1 < m else 0
    else:
        for k in range(n):
            dirs[k, 0], dirs[k, 1] = math.cos(angles[k]), math.sin(angles[k])
    for k in range(n):
        if abs(dirs[k, 0]) < _SNAP:
            dirs[k, 0], dirs[k, 1] = 0.0, math.copysign(1.0, dirs[k, 1])
        elif abs(dirs[k, 1]) < _SNAP:
            dirs[k, 0], dirs[k, 1] = math.copysign(1.0, dirs[k, 0]), 0.0
    for k in range(n):
        dirs[k, 2] = 1.0 / dirs[k, 0]
        dirs[k, 3] = 1.0 / dirs[k, 1]
    for k in range(n, b):
        dirs[k, :] = np.nan
    return n, uniform, step


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


@njit(cache=True, error_model="numpy")
def _hit_box(out, dirs, k, box, cs, px, py, r_max):
    c, s = dirs[k, 0], dirs[k, 1]
    lc, ls = c * cs[0] + s * cs[1], s * cs[0] - c * cs[1]  # the beam in the box frame
    t = ray_box(px, py, lc, ls, box[3], box[4])
    if t <= r_max and t < out[k]:
        out[k] = t


@njit(cache=True, error_model="numpy")
def boxes_for_sensor(out, dirs, n, uniform, a0, step, x0, y0, r_max, skip, bins):
    """Lower ``out[:n]`` to the distance of the nearest box along each beam (broad phase by bins
    and, for evenly spaced beams, by the angle the box's bounding circle subtends).
    ``bins = (boxes, btab, start, items, geom)`` (:func:`box_tables`, :func:`build_center_bins`)."""
    boxes, btab, start, items, geom = bins
    bx0, bx1, by0, by1 = bin_window(geom, x0, y0)
    nbx = int(geom[3])
    for by in range(by0, by1 + 1):
        for bx in range(bx0, bx1 + 1):
            b = by * nbx + bx
            for q in range(start[b], start[b + 1]):
                j = items[q]
                if j == skip:
                    continue
                dx, dy = boxes[j, 0] - x0, boxes[j, 1] - y0
                rad = btab[j, 2] * (1.0 + 1e-12) + 1e-12
                d = math.hypot(dx, dy)
                if d > r_max + rad:
                    continue
                box, cs = boxes[j], btab[j]
                px = -(dx * cs[0] + dy * cs[1])  # sensor origin in the box frame
                py = dx * cs[1] - dy * cs[0]
                if uniform and d > rad:
                    half = math.asin(rad / d) + 1e-9
                    mid = math.atan2(dy, dx)
                    ua, ub = (mid - half - a0) / step, (mid + half - a0) / step
                    lo, hi = min(ua, ub) - 1e-6, max(ua, ub) + 1e-6
                    per = _TWO_PI / abs(step)
                    sh = math.floor(lo / per) * per + per
                    lo, hi = lo - sh, hi - sh  # now lo is in [-per, 0)
                    while lo <= n - 1:
                        k0, k1 = max(int(math.ceil(lo)), 0), min(int(math.floor(hi)), n - 1)
                        for k in range(k0, k1 + 1):
                            _hit_box(out, dirs, k, box, cs, px, py, r_max)
                        lo += per
                        hi += per
                else:
                    for k in range(n):
                        _hit_box(out, dirs, k, box, cs, px, py, r_max)


# ---------------------------------------------------------------------------- kernels
@njit(cache=True, error_model="numpy")
def cast_sensor(table, bins, x0, y0, angles, r_max, skip, row):
    """All beams of one sensor at ``(x0, y0)`` with beams ``angles (B,)``, writing ``row (B,)``;
    see :func:`cast_rays_padded`."""
    cells, nx, ny, res, ox, oy = table
    w = nx + 2
    dirs = np.empty((angles.shape[0], 4))
    n, uniform, step = beam_directions(angles, dirs)
    row[:] = np.inf
    eps = corner_eps(nx, ny, res, ox, oy, x0, y0)
    ix, onx = _origin_cell(x0, ox, res, nx, eps)
    iy, ony = _origin_cell(y0, oy, res, ny, eps)
    inside = ox - eps <= x0 <= ox + nx * res + eps and oy - eps <= y0 <= oy + ny * res + eps
    if inside:  # origin in or on a wall cell: 0 on every beam
        for ky in range(iy - 1 if ony else iy, iy + 1):
            for kx in range(ix - 1 if onx else ix, ix + 1):
                if cells[(ky + 1) * w + kx + 1] == 1:
                    row[:n] = 0.0
                    return
    boxes_for_sensor(row, dirs, n, uniform, angles[0], step, x0, y0, r_max, skip, bins)
    grid_beams(table, x0, y0, (ix, onx, iy, ony, inside), eps, dirs, n, r_max, row)


@njit(cache=True, parallel=True, fastmath=False, error_model="numpy")
def cast_rays_padded(table, bins, origins, beam_angles, max_range, ignore_box, out):
    """Core kernel, parallel over sensors; shapes and conventions as :func:`cast_rays`.

    ``table = (cells, nx, ny, res, ox, oy)``: the padded table (:func:`pad_grid`, optionally
    :func:`mark_empty_space`) and the map's size, cell size and origin. ``bins = (boxes, btab,
    start, items, geom)``: the boxes, :func:`box_tables` and :func:`build_center_bins` of their
    centres with bin size >= max range + largest box radius."""
    for si in prange(beam_angles.shape[0]):
        x0, y0 = origins[si, 0], origins[si, 1]
        r_max, skip = max_range[si], ignore_box[si]
        cast_sensor(table, bins, x0, y0, beam_angles[si], r_max, skip, out[si])


@njit(cache=True, error_model="numpy")
def cast_rays(grid_bu, res, ox, oy, origins, beam_angles, max_range, boxes, ignore_box, out):
    """Cast every beam of every sensor in one call; writes ``out (S, B)``, metres.

    grid_bu (ny, nx) uint8: occupancy, ``grid_bu[iy, ix]`` nonzero = wall, iy = 0 at the south edge;
        cell (iy, ix) covers ``[ox + ix res, ox + (ix + 1) res) x [oy + iy res, ...)``.
    origins (S, 2): sensor positions, world frame. beam_angles (S, B): absolute world angles (rad),
        NaN-padded. max_range (S,): metres, > 0 and finite. boxes (K, 5): ``cx, cy, theta,
        half_length, half_width``. ignore_box (S,) int64: box each sensor skips (its own
        footprint) or -1. out (S, B): distance to the first wall or box touched, inf without a
        return within max range or for a NaN beam, 0 from inside a wall cell or a box.

    Pads the grid and bins the boxes on every call, then runs the parallel kernel
    :func:`cast_rays_padded` (prange over sensors); :class:`RayCaster` keeps the padded table.
    """
    btab = box_tables(boxes)
    size = max_range.max() if max_range.shape[0] > 0 else 1.0
    size += btab[:, 2].max() if boxes.shape[0] > 0 else 0.0
    start, items, geom = build_center_bins(boxes, size)
    ny, nx = grid_bu.shape
    table = (pad_grid(grid_bu), nx, ny, res, ox, oy)
    bins = (boxes, btab, start, items, geom)
    cast_rays_padded(table, bins, origins, beam_angles, max_range, ignore_box, out)


# ---------------------------------------------------------------------------- wrapper
def _as_array(a, dtype) -> np.ndarray:
    """C-contiguous, writeable (one compiled kernel signature for every caller)."""
    arr = np.ascontiguousarray(a, dtype=dtype)
    return arr if arr.flags.writeable else arr.copy()


def _as_f64(name: str, a, shape_tail: tuple[int, ...]) -> np.ndarray:
    arr = _as_array(a, np.float64)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = ", ".join(["N", *map(str, shape_tail)])
        raise ValueError(f"{name} must have shape ({want}), got {arr.shape}")
    return arr


_EMPTY_BOXES = np.zeros((0, 5))
_INPUT_ERRORS = (
    "origins must be finite",
    "beam_angles must be finite or NaN (padding)",
    "max_range must be positive and finite",
    "boxes must be finite with half sizes >= 0",
    "ignore_box entries must be -1 or a box index < {k}",
)


@njit(cache=True, error_model="numpy")
def _check_inputs(origins, beam_angles, max_range, boxes, ignore_box) -> int:
    """0 if the inputs are valid, else 1 + the index of the first broken rule in _INPUT_ERRORS."""
    if not np.all(np.isfinite(origins)):
        return 1
    if np.any(np.isinf(beam_angles)):
        return 2
    if not np.all((max_range > 0.0) & np.isfinite(max_range)):
        return 3
    if not np.all(np.isfinite(boxes)) or np.any(boxes[:, 3:] < 0.0):
        return 4
    if np.any((ignore_box < -1) | (ignore_box >= boxes.shape[0])):
        return 5
    return 0


class RayCaster:
    """Owns the padded grid; casts batches of beams against it and against boxes.

    Threads: the kernel runs in parallel over sensors on numba's thread pool; limit it with
    ``numba.set_num_threads(n)`` before calling :meth:`cast`.
    """

    def __init__(self, grid: OccupancyGrid, skip_empty: bool = True) -> None:
        self.skip_empty = bool(skip_empty)  # jump across empty space (same results, faster)
        self.set_grid(grid)

    def set_grid(self, grid: OccupancyGrid) -> None:
        """Use a new map (rebuilds the kernel's table, O(cells))."""
        self.grid = grid
        ny, nx = grid.cells_bu.shape
        cells = pad_grid(np.ascontiguousarray(grid.cells_bu, dtype=np.uint8))
        if self.skip_empty:
            mark_empty_space(cells, nx, ny)
        ox, oy = (float(v) for v in grid.origin_xy_m)
        self._table = (cells, int(nx), int(ny), float(grid.resolution_m), ox, oy)

    def cast(
        self,
        origins: np.ndarray,
        beam_angles: np.ndarray,
        max_range: np.ndarray | float,
        boxes: np.ndarray | None = None,
        ignore_box: np.ndarray | None = None,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """Ranges ``(S, B)`` in metres for sensors at ``origins (S, 2)`` (world frame) with beams at
        absolute world angles ``beam_angles (S, B)`` (rad, NaN-padded), up to ``max_range``
        (scalar or ``(S,)``). ``boxes (K, 5)``: ``cx, cy, theta, half_length, half_width``;
        ``ignore_box (S,)``: the box each sensor does not see (its own footprint) or -1.
        No return reads inf; see the module docstring for the 0 and NaN conventions."""
        org = _as_f64("origins", origins, (2,))
        ang = _as_array(beam_angles, np.float64)
        s = org.shape[0]
        if ang.ndim != 2 or ang.shape[0] != s:
            raise ValueError(f"beam_angles must have shape (S, B), S = {s}, got {ang.shape}")
        if np.ndim(max_range) == 0:
            rng = np.full(s, max_range, dtype=np.float64)
        elif np.shape(max_range) == (s,):
            rng = _as_array(max_range, np.float64)
        else:
            raise ValueError(f"max_range must be a number or have shape ({s},)")
        bx = _EMPTY_BOXES if boxes is None else _as_f64("boxes", boxes, (5,))
        if ignore_box is None:
            ign = np.full(s, -1, dtype=np.int64)
        else:
            ign = _as_array(ignore_box, np.int64)
            if ign.shape != (s,):
                raise ValueError(f"ignore_box must have shape ({s},), got {ign.shape}")
        bad = _check_inputs(org, ang, rng, bx, ign)
        if bad:
            raise ValueError(_INPUT_ERRORS[bad - 1].format(k=len(bx)))
        if out is None:
            out = np.empty(ang.shape)
        elif (
            out.shape != ang.shape
            or out.dtype != np.float64
            or not (out.flags.c_contiguous and out.flags.writeable)
        ):
            raise ValueError(f"out must be a C-contiguous float64 array of shape {ang.shape}")
        if s == 0 or ang.shape[1] == 0:
            out[...] = np.inf
            return out
        btab = box_tables(bx)
        size = float(rng.max()) + (float(btab[:, 2].max()) if len(bx) else 0.0)
        start, items, geom = build_center_bins(bx, size)
        bins = (bx, btab, start, items, geom)
        cast_rays_padded(self._table, bins, org, ang, rng, ign, out)
        return out

    def cast_single(
        self,
        x: float,
        y: float,
        angles: np.ndarray,
        max_range: float,
        boxes: np.ndarray | None = None,
    ) -> np.ndarray:
        """Ranges ``(B,)`` of one sensor at ``(x, y)`` with beams at world ``angles`` (rad)."""
        ang = np.atleast_1d(np.asarray(angles, dtype=np.float64))
        if ang.ndim != 1:
            raise ValueError(f"angles must be 1-D, got shape {ang.shape}")
        return self.cast(np.array([[x, y]], dtype=np.float64), ang[None, :], max_range, boxes)[0]


def warmup() -> float:
    """Compile (or load from numba's cache) the ray-casting kernels on tiny inputs; returns the
    seconds it took."""
    t0 = time.perf_counter()
    grid = OccupancyGrid(np.array([[0, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=bool), 1.0, (0.0, 0.0))
    caster = RayCaster(grid)
    boxes = np.array([[0.5, 0.5, 0.3, 0.2, 0.1], [2.5, 2.5, 0.0, 0.2, 0.1]])
    ang = np.array([[0.0, 1.0, 2.0], [0.5, np.nan, np.nan]])
    org = np.array([[0.5, 0.5], [2.5, 0.5]])
    own, r_max, out = np.array([0, -1]), np.full(2, 2.0), np.empty(ang.shape)
    caster.cast(org, ang, 2.0, boxes, own)
    cast_rays(grid.cells_bu, 1.0, 0.0, 0.0, org, ang, r_max, boxes, own, out)
    return time.perf_counter() - t0
