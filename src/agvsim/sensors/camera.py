"""The onboard camera: RGB and depth images ray cast column by column (numba).

The scene is the occupancy grid extruded to the wall height, static boxes and the other robots
as coloured boxes standing on the floor, the floor, and the sky; walls carry per-cell colours,
face shading and markers (:mod:`agvsim.world.markers`).

Camera model (pinhole, OpenCV pixel convention): the camera frame is x forward, y left, z up at
the mount (robot frame ``mount_xy_m``, ``mount_z_m`` above the floor), turned by
``mount_yaw_rad`` about z, then tilted down by ``pitch_rad`` (positive = looking down). Square
pixels, focal length ``f = (W / 2) / tan(hfov / 2)``, principal point ``((W - 1) / 2,
(H - 1) / 2)`` with pixel centres at integer coordinates, so pixel ``(u, v)`` (column, row)
looks along ``(1, -(u - cx) / f, -(v - cy) / f)`` in the camera frame (:attr:`CameraSpec.K`).

Images: ``rgb (H, W, 3)`` uint8; ``depth (H, W)`` float32 z-depth in metres (distance along the
optical axis, as an RGB-D camera reports), ``+inf`` where nothing lies within ``range_max_m``
(measured horizontally, like a lidar beam; such pixels show the sky colour). With
``noise_std`` > 0 the RGB image gets Gaussian pixel noise (:func:`add_pixel_noise`, from the
simulation's seeded generator, rounded and clipped to 0..255); the depth image stays exact.

How it renders (one vertical plane per column): every pixel's ray lies in a vertical plane of
some azimuth. Per azimuth the renderer casts ONE 2-D ray through the grid (the lidar's DDA,
:func:`agvsim.sensors.grid_dda.grid_beams`) and against the boxes (slab test), then shades every
pixel of that azimuth from the elevation of its ray: floor below, a wall or box face, a box top
seen from above, or sky. With ``pitch = 0`` each image column is one azimuth and the image is
exact; with a pitched camera the columns lean, and pixels use the nearest of ``2 W`` azimuths
(at most a quarter of a pixel sideways). The camera must sit below the wall tops (then a ray can
never pass over a wall: walls are never seen from above).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numba import njit

from agvsim.sensors.grid_dda import corner_eps, grid_beams, origin_cell
from agvsim.sensors.raycast import beam_directions
from agvsim.world.markers import Marker

_MAX_PITCH_VIEW = math.radians(85.0)  # |pitch| + vfov / 2 must stay below this


@dataclass(frozen=True)
class CameraSpec:
    name: str = "camera"
    width_px: int = 320
    height_px: int = 240
    hfov_rad: float = math.radians(60.0)
    rate_hz: float = 10.0
    mount_xy_m: tuple[float, float] = (0.0, 0.0)
    mount_z_m: float = 0.4
    mount_yaw_rad: float = 0.0
    pitch_rad: float = 0.0  # positive: looking down
    range_max_m: float = 30.0
    noise_std: float = 0.0  # Gaussian pixel noise, std in 0..255 intensity levels (0: off)

    def __post_init__(self) -> None:
        n = f"camera {self.name!r}"
        if not (8 <= self.width_px <= 4096 and 8 <= self.height_px <= 4096):
            raise ValueError(
                f"{n}: width_px and height_px must be 8..4096, got "
                f"{self.width_px} x {self.height_px}"
            )
        if not 0.0 < self.hfov_rad < math.radians(170.0):
            raise ValueError(
                f"{n}: hfov must be in (0, 170) deg, got {math.degrees(self.hfov_rad):g}"
            )
        if not (self.rate_hz > 0 and math.isfinite(self.rate_hz)):
            raise ValueError(f"{n}: rate_hz must be > 0, got {self.rate_hz}")
        if not (self.range_max_m > 0 and math.isfinite(self.range_max_m)):
            raise ValueError(f"{n}: range_max_m must be > 0, got {self.range_max_m}")
        if not 0.0 <= self.noise_std <= 255.0:
            raise ValueError(
                f"{n}: noise_std must be 0..255 (intensity levels), got {self.noise_std}"
            )
        if not self.mount_z_m > 0:
            raise ValueError(f"{n}: mount_z_m must be above the floor (> 0), got {self.mount_z_m}")
        if abs(self.pitch_rad) + self.vfov_rad / 2 >= _MAX_PITCH_VIEW:
            raise ValueError(
                f"{n}: pitch {math.degrees(self.pitch_rad):g} deg with a vertical field of view "
                f"of {math.degrees(self.vfov_rad):.1f} deg looks within 5 deg of straight up or "
                f"down; allowed |pitch| < {math.degrees(_MAX_PITCH_VIEW - self.vfov_rad / 2):.1f}"
            )

    @property
    def focal_px(self) -> float:
        return (self.width_px / 2.0) / math.tan(self.hfov_rad / 2.0)

    @property
    def vfov_rad(self) -> float:
        return 2.0 * math.atan((self.height_px / 2.0) / self.focal_px)

    @property
    def principal_point_px(self) -> tuple[float, float]:
        return ((self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) OpenCV camera matrix (x right, y down, z forward optical frame)."""
        f = self.focal_px
        cx, cy = self.principal_point_px
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz

    def column_azimuths_rad(self) -> np.ndarray:
        """(W,) azimuth of each column's rays relative to the camera's heading (pitch 0)."""
        cx = self.principal_point_px[0]
        return np.arctan(-(np.arange(self.width_px) - cx) / self.focal_px)

    def pose_world(self, robot_pose: np.ndarray) -> tuple[float, float, float, float]:
        """Camera (x, y, z, yaw) in the world for a robot at ``robot_pose`` (x, y, theta)."""
        x, y, th = (float(v) for v in robot_pose[:3])
        c, s = math.cos(th), math.sin(th)
        mx, my = self.mount_xy_m
        return (x + c * mx - s * my, y + s * mx + c * my, self.mount_z_m, th + self.mount_yaw_rad)


# ---------------------------------------------------------------------------------- pixel rays
@dataclass(frozen=True)
class PixelRays:
    """Per camera spec, once: the azimuths to cast and, per pixel in azimuth order, its flat
    index ``v * W + u``, its ray's rise per metre of horizontal travel and its z-depth per metre
    of horizontal travel."""

    bin_rel_az: np.ndarray  # (K,) rad, relative to the camera's heading
    bin_start: np.ndarray  # (K + 1,) pixels of bin k: order[bin_start[k]:bin_start[k + 1]]
    order: np.ndarray  # (H W,) int64 flat pixel indices
    slope: np.ndarray  # (H W,) dz / dh of each pixel's ray, in `order`
    inv_h: np.ndarray  # (H W,) z-depth / horizontal distance, in `order`
    exact: bool = field(default=True)  # every pixel on its own azimuth (pitch 0)


@lru_cache(maxsize=64)
def pixel_rays(spec: CameraSpec) -> PixelRays:
    w, h = spec.width_px, spec.height_px
    f = spec.focal_px
    cx, cy = spec.principal_point_px
    a = -(np.arange(w) - cx) / f  # (W,) left
    b = -(np.arange(h) - cy) / f  # (H,) up
    cp, sp = math.cos(spec.pitch_rad), math.sin(spec.pitch_rad)
    fwd = cp + b[:, None] * sp  # (H, 1): Ry(pitch) (1, a, b), x
    up = -sp + b[:, None] * cp  # (H, 1): z
    fwd, side = np.broadcast_arrays(fwd, a[None, :])
    up = np.broadcast_to(up, (h, w))
    hor = np.hypot(fwd, side)
    slope, inv_h = (up / hor).ravel(), (1.0 / hor).ravel()
    if spec.pitch_rad == 0.0:
        rel = np.arctan(a)
        bins = np.broadcast_to(np.arange(w), (h, w)).ravel()
        exact = True
    else:
        az = np.arctan2(side, fwd).ravel()
        k = 2 * w
        lo, hi = float(az.min()), float(az.max())
        rel = np.linspace(hi, lo, k)  # left to right, like columns
        bins = np.clip(np.rint((hi - az) / (hi - lo) * (k - 1)), 0, k - 1).astype(np.int64)
        exact = False
    order = np.argsort(bins, kind="stable")
    start = np.searchsorted(bins[order], np.arange(len(rel) + 1))
    return PixelRays(
        bin_rel_az=np.ascontiguousarray(rel, dtype=np.float64),
        bin_start=start.astype(np.int64),
        order=order.astype(np.int64),
        slope=np.ascontiguousarray(slope[order]),
        inv_h=np.ascontiguousarray(inv_h[order]),
        exact=exact,
    )


# ---------------------------------------------------------------------------------- kernel
SKY, FLOOR, WALL, SIDE, TOP = 0, 1, 2, 3, 4  # what a pixel shows


@njit(cache=True, error_model="numpy")
def _slab(px, py, lc, ls, hl, hw):
    """Entry and exit distances of the ray ``(px, py) + t (lc, ls)`` through the closed
    rectangle ``|x| <= hl, |y| <= hw`` (box frame) and the axis of the entry face (0 x, 1 y);
    ``(inf, inf, 0)`` on a miss. Entry as :func:`agvsim.geometry.ray_box` computes it."""
    tn, tf = -np.inf, np.inf
    axis = 0
    if lc == 0.0:
        if px < -hl or px > hl:
            return np.inf, np.inf, 0
    else:
        ta, tb = (-hl - px) / lc, (hl - px) / lc
        tn, tf = min(ta, tb), max(ta, tb)
    if ls == 0.0:
        if py < -hw or py > hw:
            return np.inf, np.inf, 0
    else:
        ta, tb = (-hw - py) / ls, (hw - py) / ls
        if min(ta, tb) > tn:
            axis = 1
        tn, tf = max(tn, min(ta, tb)), min(tf, max(ta, tb))
    if tn > tf or tf < 0.0:
        return np.inf, np.inf, 0
    return max(tn, 0.0), tf, axis


@njit(cache=True, error_model="numpy")
def _wall_face(nx, ny, res, ox, oy, hx, hy, c, s):
    """Face code (0 N, 1 E, 2 S, 3 W), bottom-up cell (iy, ix), the face's line coordinate and
    the position along it, for a ray of direction (c, s) that hit a wall at (hx, hy)."""
    gx = (hx - ox) / res
    gy = (hy - oy) / res
    lx, ly = round(gx), round(gy)
    dx = abs(gx - lx) if c != 0.0 else np.inf
    dy = abs(gy - ly) if s != 0.0 else np.inf
    if dx <= dy:  # an x face: the ray ran east (hits a west face) or west (an east face)
        face = 3 if c > 0.0 else 1
        ix = int(lx) if c > 0.0 else int(lx) - 1
        iy = int(math.floor(gy))
        line, along = ox + lx * res, hy
    else:
        face = 2 if s > 0.0 else 0
        iy = int(ly) if s > 0.0 else int(ly) - 1
        ix = int(math.floor(gx))
        line, along = oy + ly * res, hx
    ix = min(max(ix, 0), nx - 1)
    iy = min(max(iy, 0), ny - 1)
    return face, iy, ix, line, along


@njit(cache=True, error_model="numpy")
def render_view(table, rays, cam, scene, marks, boxes, rgb, depth):
    """Render one camera view into ``rgb (H W, 3)`` uint8 and ``depth (H W,)`` float32.

    ``table = (cells, nx, ny, res, ox, oy)``: the padded grid (:func:`grid_dda.pad_grid`).
    ``rays = (bin_rel_az, bin_start, order, slope, inv_h)`` (:class:`PixelRays`).
    ``cam = (x, y, z, yaw, range_max)`` in the world. ``scene = (cell_rgb (C, 3) uint8,
    face_shade (4,), floor_rgb (3,), sky_rgb (3,), wall_h, checker)``. ``marks = (geom (M, 7),
    tex_index (M, 3), texels (T, 3))`` (:meth:`Appearance.marker_tables`). ``boxes = (bx (K,
    5), btab (K, 3), height (K,), box_rgb (K, 3) uint8, skip)``: boxes (robot footprints and
    static boxes, :func:`agvsim.geometry.box_tables`) and the one the camera's robot is.
    """
    cells, nx, ny, res, ox, oy = table
    bin_rel, bin_start, order, slope, inv_h = rays
    x0, y0, zc, yaw, r_max = cam
    cell_rgb, shade, floor_rgb, sky_rgb, wall_h, checker = scene
    mgeom, mtex, texels = marks
    bx, btab, bheight, brgb, skip = boxes
    nbins = bin_rel.shape[0]
    w = nx + 2
    angles = np.empty(nbins)
    for k in range(nbins):
        angles[k] = yaw + bin_rel[k]
    dirs = np.empty((nbins, 4))
    beam_directions(angles, dirs)
    walls = np.full(nbins, np.inf)
    eps = corner_eps(nx, ny, res, ox, oy, x0, y0)
    ix, onx = origin_cell(x0, ox, res, nx, eps)
    iy, ony = origin_cell(y0, oy, res, ny, eps)
    inside = ox - eps <= x0 <= ox + nx * res + eps and oy - eps <= y0 <= oy + ny * res + eps
    in_wall = False
    if inside:
        for ky in range(iy - 1 if ony else iy, iy + 1):
            for kx in range(ix - 1 if onx else ix, ix + 1):
                if cells[(ky + 1) * w + kx + 1] == 1:
                    in_wall = True
    if in_wall:
        walls[:] = 0.0
    else:
        grid_beams(table, x0, y0, (ix, onx, iy, ony, inside), eps, dirs, nbins, r_max, walls)
    # boxes that can be seen at all: not our own, within range and within the view's wedge
    nbox = bx.shape[0]
    cand = np.empty(nbox, dtype=np.int64)
    nc = 0
    rel_lo, rel_hi = bin_rel.min(), bin_rel.max()
    for j in range(nbox):
        if j == skip:
            continue
        dx, dy = bx[j, 0] - x0, bx[j, 1] - y0
        d, rad = math.hypot(dx, dy), btab[j, 2] * (1.0 + 1e-9) + 1e-9
        if d - rad > r_max:
            continue
        if d > rad:
            mid = math.atan2(dy, dx) - yaw
            mid -= 2.0 * math.pi * math.floor(mid / (2.0 * math.pi) + 0.5)  # to [-pi, pi)
            half = math.asin(rad / d) + 1e-9
            if mid + half < rel_lo or mid - half > rel_hi:
                continue
        cand[nc] = j
        nc += 1
    tin = np.empty(nc)
    tout = np.empty(nc)
    bax = np.empty(nc, dtype=np.int64)
    bj = np.empty(nc, dtype=np.int64)
    nmark = mgeom.shape[0]
    multi = cell_rgb.shape[0] > 1
    for k in range(nbins):
        c, s = dirs[k, 0], dirs[k, 1]
        tw = walls[k]
        wr = wg = wb = 0.0
        mk = -1
        along = 0.0
        if tw < np.inf:
            hx, hy = x0 + tw * c, y0 + tw * s
            face, giy, gix, line, along = _wall_face(nx, ny, res, ox, oy, hx, hy, c, s)
            ci = giy * nx + gix if multi else 0
            f = shade[face]
            wr, wg, wb = cell_rgb[ci, 0] * f, cell_rgb[ci, 1] * f, cell_rgb[ci, 2] * f
            tol = 1e-9 * (res + abs(line))
            for m in range(nmark):
                if (
                    mgeom[m, 0] == face
                    and abs(mgeom[m, 1] - line) <= tol
                    and mgeom[m, 2] <= along <= mgeom[m, 3]
                ):
                    mk = m
                    break
        # boxes this azimuth meets before the wall
        nb = 0
        lim = min(tw, r_max)
        for q in range(nc):
            j = cand[q]
            cs0, cs1 = btab[j, 0], btab[j, 1]
            dx, dy = bx[j, 0] - x0, bx[j, 1] - y0
            px = -(dx * cs0 + dy * cs1)
            py = dx * cs1 - dy * cs0
            lc, ls = c * cs0 + s * cs1, s * cs0 - c * cs1
            t0, t1, ax = _slab(px, py, lc, ls, bx[j, 3], bx[j, 4])
            if t0 <= lim:
                tin[nb], tout[nb], bax[nb], bj[nb] = t0, t1, ax, j
                nb += 1
        for q in range(bin_start[k], bin_start[k + 1]):
            m = slope[q]
            best = np.inf
            what = SKY
            hit = -1
            if m < 0.0:
                best = -zc / m
                what = FLOOR
            if tw < best and zc + m * tw <= wall_h:
                best = tw
                what = WALL
            for b in range(nb):
                t0 = tin[b]
                if t0 >= best:
                    continue
                hb = bheight[bj[b]]
                if zc + m * t0 <= hb:
                    best, what, hit = t0, SIDE, b
                elif m < 0.0:
                    ttop = (hb - zc) / m
                    if ttop <= tout[b] and ttop < best:
                        best, what, hit = ttop, TOP, b
            p = order[q]
            if best > r_max:
                what = SKY
            if what == SKY:
                rgb[p, 0], rgb[p, 1], rgb[p, 2] = sky_rgb[0], sky_rgb[1], sky_rgb[2]
                depth[p] = np.inf
                continue
            depth[p] = best * inv_h[q]
            if what == FLOOR:
                g = 1.0
                if checker:
                    fx = math.floor((x0 + best * c - ox) / res)
                    fy = math.floor((y0 + best * s - oy) / res)
                    if (int(fx) + int(fy)) % 2 != 0:
                        g = 0.93
                rgb[p, 0] = floor_rgb[0] * g
                rgb[p, 1] = floor_rgb[1] * g
                rgb[p, 2] = floor_rgb[2] * g
            elif what == WALL:
                z = zc + m * best
                if mk >= 0 and mgeom[mk, 4] <= z <= mgeom[mk, 5]:
                    span = mgeom[mk, 3] - mgeom[mk, 2]
                    fu = mgeom[mk, 3] - along if mgeom[mk, 6] > 0.0 else along - mgeom[mk, 2]
                    off, tw_, th_ = mtex[mk, 0], mtex[mk, 1], mtex[mk, 2]
                    tu = min(max(int(fu / span * tw_), 0), tw_ - 1)
                    tv = min(max(int((mgeom[mk, 5] - z) / span * th_), 0), th_ - 1)
                    t = off + tv * tw_ + tu
                    rgb[p, 0], rgb[p, 1], rgb[p, 2] = texels[t, 0], texels[t, 1], texels[t, 2]
                else:
                    rgb[p, 0], rgb[p, 1], rgb[p, 2] = wr, wg, wb
            else:
                j = bj[hit]
                g = 1.0 if what == TOP else (0.8 if bax[hit] == 0 else 0.92)
                rgb[p, 0] = min(brgb[j, 0] * g, 255.0)
                rgb[p, 1] = min(brgb[j, 1] * g, 255.0)
                rgb[p, 2] = min(brgb[j, 2] * g, 255.0)


def add_pixel_noise(rgb: np.ndarray, std: float, rng: np.random.Generator) -> np.ndarray:
    """``rgb`` (H, W, 3) uint8 plus independent Gaussian noise of ``std`` intensity levels on
    every channel of every pixel, rounded and clipped to 0..255 (a new array). The noise comes
    from ``rng`` (the simulation's generator), so the same seed gives the same frames."""
    noise = rng.standard_normal(rgb.shape, dtype=np.float32)
    out = rgb.astype(np.float32) + np.float32(std) * noise
    return np.clip(np.rint(out), 0.0, 255.0).astype(np.uint8)


# ---------------------------------------------------------------------------------- geometry
def _rotation_world_camera(yaw: float, pitch: float) -> np.ndarray:
    """R (3, 3) taking camera-frame vectors (x forward, y left, z up) to the world."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return rz @ ry


def project_points(
    spec: CameraSpec, robot_pose: np.ndarray, points_xyz: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(n, 2)`` (u, v; OpenCV convention) and z-depth ``(n,)`` of world
    points ``(n, 3)`` seen by the camera of a robot at ``robot_pose``; points behind the camera
    get depth <= 0 and NaN pixels."""
    x, y, z, yaw = spec.pose_world(robot_pose)
    r = _rotation_world_camera(yaw, spec.pitch_rad)
    pc = (np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3) - (x, y, z)) @ r  # R^T p
    f = spec.focal_px
    cx, cy = spec.principal_point_px
    d = pc[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.column_stack([cx - f * pc[:, 1] / d, cy - f * pc[:, 2] / d])
    uv[d <= 0] = np.nan
    return uv, d


def pixels_to_robot(
    spec: CameraSpec, u: np.ndarray, v: np.ndarray, depth: np.ndarray
) -> np.ndarray:
    """Back-projection: robot-frame points ``(n, 3)`` (x forward, y left, z up from the floor
    under the reference point) of pixels ``(u, v)`` at z-depth ``depth`` (metres)."""
    f = spec.focal_px
    cx, cy = spec.principal_point_px
    u, v, d = (np.asarray(a, dtype=np.float64).ravel() for a in (u, v, depth))
    ray = np.column_stack([np.ones_like(u), -(u - cx) / f, -(v - cy) / f]) * d[:, None]
    pts = ray @ _rotation_world_camera(spec.mount_yaw_rad, spec.pitch_rad).T
    pts[:, 0] += spec.mount_xy_m[0]
    pts[:, 1] += spec.mount_xy_m[1]
    pts[:, 2] += spec.mount_z_m
    return pts


# ---------------------------------------------------------------------------------- ground truth
@dataclass(frozen=True)
class MarkerView:
    """Where a marker shows in one frame (ground truth, for checking detectors)."""

    name: str
    kind: str
    marker_id: int
    text: str
    corners_px: np.ndarray  # (4, 2) u, v of the code's corners: TL, TR, BR, BL seen from the front
    center_px: np.ndarray  # (2,)
    depth_m: float  # z-depth of the code's centre
    visible_fraction: float  # share of sample points on the code seen unoccluded in the image


def marker_views(
    spec: CameraSpec,
    robot_pose: np.ndarray,
    markers: tuple[Marker, ...] | list[Marker],
    depth: np.ndarray,
    samples: int = 5,
    only_visible: bool = True,
) -> list[MarkerView]:
    """The markers in a frame taken from ``robot_pose`` with depth image ``depth (H, W)``:
    their projected corners and how much of each is visible (``samples`` x ``samples`` points
    on the code, each seen when it projects into the image, faces the camera and the depth
    image there agrees with its own depth, so walls, boxes and robots in front occlude it)."""
    out = []
    h, w = depth.shape
    cam_xy = np.array(spec.pose_world(robot_pose)[:2])
    g = (np.arange(samples) + 0.5) / samples - 0.5  # in (-0.5, 0.5)
    for mk in markers:
        corners = mk.corners_world()
        uv, d = project_points(spec, robot_pose, corners)
        centre = np.asarray(mk.center_xyz_m)
        cuv, cd = project_points(spec, robot_pose, centre[None, :])
        facing = float(np.dot(cam_xy - centre[:2], mk.normal_xy)) > 0.0
        frac = 0.0
        if facing:
            rx, ry = mk.right_xy
            a, b = np.meshgrid(g * mk.size_m, g * mk.size_m)
            pts = np.column_stack(
                [centre[0] + a.ravel() * rx, centre[1] + a.ravel() * ry, centre[2] + b.ravel()]
            )
            puv, pd = project_points(spec, robot_pose, pts)
            ok = np.isfinite(puv).all(axis=1) & (pd > 0)
            u = np.rint(np.where(ok, puv[:, 0], -1)).astype(np.int64)
            v = np.rint(np.where(ok, puv[:, 1], -1)).astype(np.int64)
            ok &= (u >= 0) & (u < w) & (v >= 0) & (v < h)
            seen = np.zeros(len(pts), dtype=bool)
            dimg = depth[v[ok], u[ok]].astype(np.float64)
            seen[ok] = np.abs(dimg - pd[ok]) <= 0.02 + 0.03 * pd[ok]
            frac = float(seen.mean())
        if only_visible and frac == 0.0:
            continue
        out.append(
            MarkerView(
                name=mk.name,
                kind=mk.kind.value,
                marker_id=mk.marker_id,
                text=mk.text,
                corners_px=uv,
                center_px=cuv[0],
                depth_m=float(cd[0]),
                visible_fraction=frac,
            )
        )
    return out
