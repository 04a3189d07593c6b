"""A fast top (plan) view of a simulation as an RGB image, drawn with NumPy only.

``render_top(sim)`` returns an ``(H, W, 3) uint8`` picture: the floor and the walls of the grid,
the markers on wall faces (each a thin strip on the floor along its face), the static boxes,
every robot as its oriented footprint in its colour with a white heading mark, and optionally
the sensor beams (rangers green, lidar blue, like the 3D app) with their hit points and the
robots' trails. It is used for video export and for Gymnasium ``rgb_array`` rendering, so it is
built for speed: the background (grid, markers and boxes) is drawn once per grid and cached;
each frame copies it and draws a few small polygons and line samples.

Image layout: row 0 is north (largest y), column 0 west (smallest x), as the maps are read.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from agvsim.world.markers import Marker, MarkerKind

FLOOR_RGB = (236, 236, 232)
WALL_RGB = (70, 70, 78)
BOX_RGB = (110, 100, 90)
OUTSIDE_RGB = (200, 200, 200)
RANGER_RGB = (40, 200, 60)
LIDAR_RGB = (40, 110, 235)
HIT_RGB = (230, 40, 40)
TRAIL_RGB = (90, 90, 90)
OUTLINE_RGB = (20, 20, 20)
HEADING_RGB = (255, 255, 255)
# ArUco, AprilTag and QR codes are black on white paper: black would merge with the dark wall the
# strip touches and white with the pale floor, so they are drawn magenta, a colour nothing else
# in the top view uses (colour patches are drawn in their own colour)
TAG_RGB = (230, 0, 230)
MARKER_DEPTH_M = 0.08  # how far a marker's strip reaches from its face onto the floor (>= 2 px)


def hex_rgb(color: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` -> (r, g, b); anything else falls back to the default robot red."""
    c = color.lstrip("#")
    try:
        if len(c) != 6:
            raise ValueError(color)
        return (int(c[0:2], 16), int(c[2:4], 16), int(c[4:6], 16))
    except ValueError:
        return (214, 39, 40)


@dataclass(frozen=True)
class View:
    """Pixel <-> world mapping: pixel (row, col) centre is at world
    (xmin + (col + 0.5) / px_per_m, ymax - (row + 0.5) / px_per_m)."""

    xmin: float
    ymax: float
    px_per_m: float
    width_px: int
    height_px: int

    @classmethod
    def fit(
        cls,
        extent: tuple[float, float, float, float],
        width_px: int,
        height_px: int | None = None,
    ) -> View:
        """A view of ``extent`` (xmin, xmax, ymin, ymax) ``width_px`` wide; the height keeps the
        aspect unless given (then the extent is fitted inside and centred)."""
        xmin, xmax, ymin, ymax = (float(v) for v in extent)
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(f"view extent must have xmax > xmin and ymax > ymin, got {extent}")
        if int(width_px) < 2 or (height_px is not None and int(height_px) < 2):
            raise ValueError(f"image size must be at least 2 px, got {width_px} x {height_px}")
        w = int(width_px)
        if height_px is None:
            scale = w / (xmax - xmin)
            h = max(2, int(round((ymax - ymin) * scale)))
            return cls(xmin, ymax, scale, w, h)
        h = int(height_px)
        scale = min(w / (xmax - xmin), h / (ymax - ymin))
        cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
        return cls(cx - w / (2 * scale), cy + h / (2 * scale), scale, w, h)

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World (..., 2) x, y -> continuous pixel (..., 2) col, row (pixel centres at .5)."""
        xy = np.asarray(xy, dtype=np.float64)
        col = (xy[..., 0] - self.xmin) * self.px_per_m
        row = (self.ymax - xy[..., 1]) * self.px_per_m
        return np.stack([col, row], axis=-1)


# ---------------------------------------------------------------------- drawing primitives
def fill_polygon(img: np.ndarray, poly_px: np.ndarray, rgb: Sequence[int]) -> None:
    """Fill a convex polygon (K, 2) of pixel coordinates (col, row), any winding, in place.
    A pixel is filled when its centre is inside or on the edge."""
    h, w = img.shape[:2]
    p = np.asarray(poly_px, dtype=np.float64)
    c0 = max(int(np.floor(p[:, 0].min())), 0)
    c1 = min(int(np.ceil(p[:, 0].max())), w)
    r0 = max(int(np.floor(p[:, 1].min())), 0)
    r1 = min(int(np.ceil(p[:, 1].max())), h)
    if c1 <= c0 or r1 <= r0:
        return
    cc = np.arange(c0, c1) + 0.5
    rr = np.arange(r0, r1) + 0.5
    e = np.roll(p, -1, axis=0) - p  # edges
    # cross(edge, point - vertex) for every edge and pixel; inside if all share one sign
    cross = e[:, 0, None, None] * (rr[None, :, None] - p[:, 1, None, None]) - e[
        :, 1, None, None
    ] * (cc[None, None, :] - p[:, 0, None, None])
    inside = np.all(cross >= -1e-9, axis=0) | np.all(cross <= 1e-9, axis=0)
    img[r0:r1, c0:c1][inside] = rgb


def draw_segments(
    img: np.ndarray,
    a_px: np.ndarray,
    b_px: np.ndarray,
    rgb: Sequence[int] | np.ndarray,
    alpha: float = 1.0,
) -> None:
    """Draw segments from (M, 2) to (M, 2) pixel points (col, row), one sample per pixel step
    along the longer axis; ``rgb`` is one colour or (M, 3). ``alpha`` < 1 blends with the
    image. Segments are clipped to the image first, so long ones cost only what is seen."""
    a = np.ascontiguousarray(np.asarray(a_px, dtype=np.float64).reshape(-1, 2))
    b = np.ascontiguousarray(np.asarray(b_px, dtype=np.float64).reshape(-1, 2))
    if len(a) == 0:
        return
    color = np.asarray(rgb, dtype=np.float64)
    colors = np.ascontiguousarray(np.broadcast_to(color, (len(a), 3)) if color.ndim == 1 else color)
    _segments_kernel(img, a, b, colors, float(min(max(alpha, 0.0), 1.0)))


@njit(cache=True)
def _clip(p0: float, p1: float, lo: float, hi: float, t0: float, t1: float):
    """Liang-Barsky along one axis: narrow [t0, t1] so that p0 + t (p1 - p0) is in [lo, hi]."""
    d = p1 - p0
    if d == 0.0:
        if p0 < lo or p0 > hi:
            return 1.0, 0.0
        return t0, t1
    ta, tb = (lo - p0) / d, (hi - p0) / d
    if ta > tb:
        ta, tb = tb, ta
    return max(t0, ta), min(t1, tb)


@njit(cache=True)
def _segments_kernel(img, a, b, colors, alpha):  # pragma: no cover - numba
    h, w = img.shape[0], img.shape[1]
    for m in range(a.shape[0]):
        ax, ay, bx, by = a[m, 0], a[m, 1], b[m, 0], b[m, 1]
        if not (np.isfinite(ax) and np.isfinite(ay) and np.isfinite(bx) and np.isfinite(by)):
            continue
        t0, t1 = _clip(ax, bx, 0.0, w - 1e-9, 0.0, 1.0)
        t0, t1 = _clip(ay, by, 0.0, h - 1e-9, t0, t1)
        if t0 > t1:
            continue
        x0, y0 = ax + t0 * (bx - ax), ay + t0 * (by - ay)
        x1, y1 = ax + t1 * (bx - ax), ay + t1 * (by - ay)
        n = int(np.ceil(max(abs(x1 - x0), abs(y1 - y0)))) + 1
        for k in range(n):
            f = k / (n - 1) if n > 1 else 0.0
            col = int(np.floor(x0 + (x1 - x0) * f))
            row = int(np.floor(y0 + (y1 - y0) * f))
            if 0 <= col < w and 0 <= row < h:
                for ch in range(3):
                    v = img[row, col, ch] * (1.0 - alpha) + colors[m, ch] * alpha
                    img[row, col, ch] = np.uint8(min(max(v + 0.5, 0.0), 255.0))


def draw_dots(img: np.ndarray, pts_px: np.ndarray, rgb: Sequence[int], radius_px: int = 1) -> None:
    """Square dots of side ``2 radius + 1`` pixels centred on (M, 2) pixel points (col, row)."""
    p = np.floor(np.asarray(pts_px, dtype=np.float64).reshape(-1, 2)).astype(np.int64)
    if len(p) == 0:
        return
    h, w = img.shape[:2]
    d = np.arange(-radius_px, radius_px + 1)
    col = (p[:, 0, None, None] + d[None, None, :]).repeat(len(d), axis=1).ravel()
    row = (p[:, 1, None, None] + d[None, :, None]).repeat(len(d), axis=2).ravel()
    ok = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    img[row[ok], col[ok]] = rgb


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """(K, 5) cx, cy, theta, half_length, half_width -> (K, 4, 2) world corners (CCW)."""
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)
    c, s = np.cos(b[:, 2]), np.sin(b[:, 2])
    local = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]], dtype=np.float64)
    lx = local[None, :, 0] * b[:, 3, None]
    ly = local[None, :, 1] * b[:, 4, None]
    x = b[:, 0, None] + c[:, None] * lx - s[:, None] * ly
    y = b[:, 1, None] + s[:, None] * lx + c[:, None] * ly
    return np.stack([x, y], axis=-1)


def marker_strips(markers: Sequence[Marker], view: View) -> tuple[np.ndarray, np.ndarray]:
    """Where markers are drawn: ``boxes (M, 4)`` int64 pixel ranges ``row0, row1, col0, col1``
    (half-open, may reach outside the image) and ``colors (M, 3)`` uint8.

    A marker's strip spans its printed square along the face (quiet zone included) and reaches
    ``MARKER_DEPTH_M`` (at least 2 px) from the face onto the free side; a pixel is in it when its
    centre is in the half-open strip, so the strip is exactly that many pixels thick."""
    boxes = np.zeros((len(markers), 4), dtype=np.int64)
    colors = np.zeros((len(markers), 3), dtype=np.uint8)
    depth_m = max(2, round(MARKER_DEPTH_M * view.px_per_m)) / view.px_per_m
    for k, mk in enumerate(markers):
        c = np.asarray(mk.center_xyz_m[:2], dtype=np.float64)
        half = 0.5 * mk.extent_m * np.asarray(mk.right_xy)
        normal = np.asarray(mk.normal_xy)
        px = view.to_px(np.array([c - half, c + half + depth_m * normal]))  # opposite corners
        (c0, r0), (c1, r1) = px.min(axis=0), px.max(axis=0)
        boxes[k] = np.ceil(np.array([r0, r1, c0, c1]) - 0.5 - 1e-9)
        colors[k] = mk.rgb if mk.kind == MarkerKind.PATCH else TAG_RGB
    return boxes, colors


# ---------------------------------------------------------------------- the renderer
def render_background(
    grid, boxes: np.ndarray, view: View, markers: Sequence[Marker] = ()
) -> np.ndarray:
    """The static picture: floor, walls (nearest cell per pixel centre), outside, the markers'
    strips (on floor pixels only) and boxes."""
    xs = view.xmin + (np.arange(view.width_px) + 0.5) / view.px_per_m
    ys = view.ymax - (np.arange(view.height_px) + 0.5) / view.px_per_m
    ox, oy = grid.origin_xy_m
    col = np.floor((xs - ox) / grid.resolution_m).astype(np.int64)
    row = grid.rows - 1 - np.floor((ys - oy) / grid.resolution_m).astype(np.int64)
    cin = (col >= 0) & (col < grid.cols)
    rin = (row >= 0) & (row < grid.rows)
    occ = grid.occupied[np.clip(row, 0, grid.rows - 1)][:, np.clip(col, 0, grid.cols - 1)]
    inside = rin[:, None] & cin[None, :]
    img = np.empty((view.height_px, view.width_px, 3), dtype=np.uint8)
    img[:] = OUTSIDE_RGB
    floor = inside & ~occ
    img[floor] = FLOOR_RGB
    img[inside & occ] = WALL_RGB
    strips, colors = marker_strips(markers, view)
    for box, rgb in zip(np.maximum(strips, 0), colors, strict=True):  # no negative slice ends
        r0, r1, c0, c1 = box
        img[r0:r1, c0:c1][floor[r0:r1, c0:c1]] = rgb
    for corners in box_corners(boxes):
        fill_polygon(img, view.to_px(corners), BOX_RGB)
    return img


class TopView:
    """A renderer bound to one image size; caches the background until the grid, the boxes or
    the markers change.

    ``extent`` (xmin, xmax, ymin, ymax) defaults to the map's extent."""

    def __init__(
        self,
        width_px: int = 640,
        height_px: int | None = None,
        extent: tuple[float, float, float, float] | None = None,
    ):
        self.width_px, self.height_px, self.extent = int(width_px), height_px, extent
        self._key: tuple | None = None
        self._bg: np.ndarray | None = None
        self.view: View | None = None

    def _background(self, sim) -> np.ndarray:
        grid, boxes = sim.world.grid, sim.world.boxes
        markers = sim.world.appearance.markers
        key = (id(grid), id(boxes), len(boxes), id(markers))
        if self._key != key or self._bg is None:
            self.view = View.fit(self.extent or grid.extent_m, self.width_px, self.height_px)
            self._bg = render_background(grid, boxes, self.view, markers)
            self._key = key
            # keep them alive, so their ids cannot be reused while cached
            self._grid, self._boxes, self._markers = grid, boxes, markers
        return self._bg

    def render(
        self,
        sim,
        *,
        beams: bool = True,
        trails: Mapping[str, np.ndarray] | Sequence[np.ndarray] | None = None,
        poses: np.ndarray | None = None,
        scans: np.ndarray | None = None,
    ) -> np.ndarray:
        """The current frame of ``sim`` (or of the given ``poses`` (N, 3) and ``scans``
        (S, B), e.g. from a recording)."""
        img = self._background(sim).copy()
        view = self.view
        assert view is not None
        poses = sim.state.poses if poses is None else np.asarray(poses, dtype=np.float64)
        if trails is not None:
            seq = (
                [trails.get(r.name) for r in sim.robots]
                if isinstance(trails, Mapping)
                else list(trails)
            )
            for k, t in enumerate(seq):
                if t is None or len(t) < 2:
                    continue
                p = view.to_px(np.asarray(t, dtype=np.float64)[:, :2])
                rgb = hex_rgb(sim.robots[k].color) if k < len(sim.robots) else TRAIL_RGB
                draw_segments(img, p[:-1], p[1:], rgb, alpha=0.55)
        if beams:
            self._draw_beams(img, sim, poses, sim.state.scans if scans is None else scans)
        fps = sim.footprints(poses)
        corners = box_corners(fps)
        scale = view.px_per_m
        for i, robot in enumerate(sim.robots):
            px = view.to_px(corners[i])
            fill_polygon(img, px, hex_rgb(robot.color))
            closed = np.vstack([px, px[:1]])
            draw_segments(img, closed[:-1], closed[1:], OUTLINE_RGB)
            # heading mark: a triangle from the footprint's centre to its front edge
            cx, cy, th, hl, hw = fps[i]
            if hl * scale >= 3:
                c, s = np.cos(th), np.sin(th)
                tip = (cx + c * hl * 0.9, cy + s * hl * 0.9)
                side = min(hw, hl) * 0.5
                b1 = (cx - s * side, cy + c * side)
                b2 = (cx + s * side, cy - c * side)
                fill_polygon(img, view.to_px(np.array([tip, b1, b2])), HEADING_RGB)
        return img

    def _draw_beams(self, img, sim, poses: np.ndarray, scans: np.ndarray) -> None:
        tab = sim.sensors
        if tab.count == 0:
            return
        view = self.view
        assert view is not None, "the view is set when the image is drawn"
        pose = poses[tab.owner]
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        mx, my = tab.mount[:, 0], tab.mount[:, 1]
        ox = pose[:, 0] + c * mx - s * my
        oy = pose[:, 1] + s * mx + c * my
        ang = tab.rel_angles + (pose[:, 2] + tab.mount[:, 2])[:, None]  # (S, B) NaN padded
        r = np.asarray(scans, dtype=np.float64)[:, : ang.shape[1]]
        # +inf: no return, drawn to range_max; 0 (origin in a wall) and -inf (too close): skipped
        hit = np.isfinite(ang) & np.isfinite(r) & (r > 0)
        drawn = hit | (np.isfinite(ang) & np.isposinf(r))
        length = np.where(hit, r, tab.range_max[:, None])
        slot, beam = np.nonzero(drawn)
        if slot.size == 0:
            return
        a = np.column_stack([ox[slot], oy[slot]])
        th = ang[slot, beam]
        b = a + length[slot, beam, None] * np.column_stack([np.cos(th), np.sin(th)])
        lidar = tab.num_beams[slot] > 8
        colors = np.where(lidar[:, None], LIDAR_RGB, RANGER_RGB)
        draw_segments(img, view.to_px(a), view.to_px(b), colors, alpha=0.45)
        h = hit[slot, beam]
        if h.any():
            draw_dots(img, view.to_px(b[h]), HIT_RGB, radius_px=1 if view.px_per_m >= 20 else 0)


_CACHE: dict[tuple, TopView] = {}


def render_top(
    sim,
    width_px: int = 640,
    height_px: int | None = None,
    *,
    beams: bool = True,
    trails: Mapping[str, np.ndarray] | Sequence[np.ndarray] | None = None,
    extent: tuple[float, float, float, float] | None = None,
) -> np.ndarray:
    """Top view of ``sim`` now: an ``(H, W, 3) uint8`` RGB image, row 0 north.

    ``width_px`` sets the width; the height follows the map's aspect unless ``height_px`` is
    given (the map is then fitted and centred). ``beams`` draws the sensor beams and hit points;
    ``trails`` maps robot name (or index) -> (T, 2) visited x, y. ``extent`` (xmin, xmax, ymin,
    ymax) shows a part of the world instead of the whole map. The background is cached per
    size and grid, so calling this every step is cheap."""
    # one renderer per size and grid: environments side by side keep their own backgrounds
    # (a renderer holds its grid, so the id cannot be reused while it is cached)
    key = (int(width_px), None if height_px is None else int(height_px), extent, id(sim.world.grid))
    tv = _CACHE.get(key)
    if tv is None:
        if len(_CACHE) > 16:
            _CACHE.clear()
        tv = _CACHE[key] = TopView(width_px, height_px, extent)
    return tv.render(sim, beams=beams, trails=trails)
