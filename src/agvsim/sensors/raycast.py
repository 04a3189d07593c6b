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

Grid part (:mod:`agvsim.sensors.grid_dda`): an Amanatides-Woo DDA in float64 over a padded copy
of the grid, with empty-space skipping; the distance is recomputed from the entry face of the
hit cell, so it does not accumulate rounding. "Exactly" means to float64 rounding: a beam
passing within ``1e-12`` x the map's size of a cell corner, or running that close along a cell
face, touches it, so that the ulp between e.g. cos(pi/4) and sin(pi/4) does not decide whether a
diagonal beam grazes a wall corner.
Box part: a uniform bin grid of box centres (bins ~ max range) picks the boxes near each sensor,
the angular interval of each box's bounding circle picks the beams (when a sensor's beams are
evenly spaced), and an exact slab test gives the distance (:mod:`agvsim.geometry`).

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

from agvsim.angles import wrap_scalar
from agvsim.geometry import bin_window, box_tables, build_center_bins, ray_box, snap_axis
from agvsim.sensors.grid_dda import (  # JUMP, OUTSIDE: re-exported for older imports
    JUMP,  # noqa: F401
    OUTSIDE,  # noqa: F401
    corner_eps,
    grid_beams,
    mark_empty_space,
    origin_cell,
    pad_grid,
)
from agvsim.world.grid import OccupancyGrid

_UNIFORM_TOL = 1e-12  # rad: beams this close to an even spacing are treated as evenly spaced
_TABLE = 16  # beams per exact cos/sin anchor for evenly spaced beams
_TWO_PI = 2.0 * math.pi


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
            e = wrap_scalar(e)
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
        dirs[k, 0], dirs[k, 1] = snap_axis(dirs[k, 0], dirs[k, 1])
    for k in range(n):
        dirs[k, 2] = 1.0 / dirs[k, 0]
        dirs[k, 3] = 1.0 / dirs[k, 1]
    for k in range(n, b):
        dirs[k, :] = np.nan
    return n, uniform, step


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
    ix, onx = origin_cell(x0, ox, res, nx, eps)
    iy, ony = origin_cell(y0, oy, res, ny, eps)
    inside = ox - eps <= x0 <= ox + nx * res + eps and oy - eps <= y0 <= oy + ny * res + eps
    if inside:  # origin in or on a wall cell: 0 on every beam
        for ky in range(iy - 1 if ony else iy, iy + 1):
            for kx in range(ix - 1 if onx else ix, ix + 1):
                if cells[(ky + 1) * w + kx + 1] == 1:
                    row[:n] = 0.0
                    return
    boxes_for_sensor(row, dirs, n, uniform, angles[0], step, x0, y0, r_max, skip, bins)
    # an origin taken as on a cell face (within eps) is cast from the face itself: the DDA walks
    # the cells beyond the face, and a distance measured from the true origin, a hair before it,
    # would count the beam as entering those cells only where it drifts across the face (a
    # beam a hair off north from 3e-11 m west of a face read 16.1 m for a wall 15.45 m away)
    xg = ox + ix * res if onx else x0
    yg = oy + iy * res if ony else y0
    grid_beams(table, xg, yg, (ix, onx, iy, ony, inside), eps, dirs, n, r_max, row)


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
def cast_rays_serial(table, bins, origins, beam_angles, max_range, ignore_box, out):
    """:func:`cast_rays_padded` on the calling thread: for small batches, where waking
    numba's thread pool costs more than the casting (milliseconds on a busy machine)."""
    for si in range(beam_angles.shape[0]):
        x0, y0 = origins[si, 0], origins[si, 1]
        r_max, skip = max_range[si], ignore_box[si]
        cast_sensor(table, bins, x0, y0, beam_angles[si], r_max, skip, out[si])


PARALLEL_MIN_RAYS = 4096  # fewer beams than this in one call: cast on one thread


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
    """0 if the inputs are valid, else 1 + the index of the first broken rule in _INPUT_ERRORS.
    Plain loops: no temporary arrays on the hot path."""
    for v in origins.ravel():
        if not math.isfinite(v):
            return 1
    for v in beam_angles.ravel():
        if math.isinf(v):
            return 2
    for v in max_range:
        if not (v > 0.0 and math.isfinite(v)):
            return 3
    for j in range(boxes.shape[0]):
        for k in range(5):
            if not math.isfinite(boxes[j, k]) or (k >= 3 and boxes[j, k] < 0.0):
                return 4
    for v in ignore_box:
        if v < -1 or v >= boxes.shape[0]:
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
        kernel = cast_rays_padded if ang.size >= PARALLEL_MIN_RAYS else cast_rays_serial
        kernel(self._table, bins, org, ang, rng, ign, out)
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
