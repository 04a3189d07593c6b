"""Geometry for the 3D view, as plain arrays (no viewer here, so it is tested directly).

- ``wall_mesh``: every wall cell of a grid as one triangle mesh. Only faces that border free
  space (or the map edge) are kept, and runs of equal faces along a row or a column are merged
  into one long quad, so a 200 x 200 maze stays a few tens of thousands of triangles.
- ``robot_parts``: the body box and each wheel (position, radius, width, axle direction) of a
  robot, from its kinematic model's own wheel positions.
- ``wheel_quaternions``: each wheel's orientation from its steering angle and rotation angle.
- ``beam_segments``: the rays of every sensor from the mount to the hit (or the range limit).
- ``marker_quad``, ``marker_pose``, ``marker_image``: a vision marker on its wall face, as the
  corners of its printed square, the pose of the image that shows it and that image.
- ``camera_*``: viewpoints (panoramic, top plan, chase behind a robot).

World frame: x east, y north, z up, metres; quaternions are (w, x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agvsim.sim.spec import BODY_HEIGHT_M, WALL_HEIGHT_M, RobotSpec
from agvsim.sim.state import SensorTable
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Marker

MARKER_OFFSET_M = 0.01  # markers float this far in front of their wall (no z-fighting)


# ---------------------------------------------------------------------------------- walls
def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along axis 1: (row, first col, last col + 1) of each run."""
    m = np.zeros((mask.shape[0], mask.shape[1] + 2), dtype=np.int8)
    m[:, 1:-1] = mask
    d = np.diff(m, axis=1)
    r0, c0 = np.nonzero(d == 1)
    r1, c1 = np.nonzero(d == -1)
    assert np.array_equal(r0, r1)
    return r0, c0, c1


def wall_mesh(
    grid: OccupancyGrid, height_m: float = WALL_HEIGHT_M
) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float32, faces (F, 3) uint32) of the walls, outward-facing (counter-
    clockwise seen from outside). Empty arrays for a map without walls."""
    occ = np.asarray(grid.occupied, dtype=bool)
    rows, cols = occ.shape
    res = grid.resolution_m
    ox, oy = grid.origin_xy_m
    pad = np.zeros((rows + 2, cols + 2), dtype=bool)
    pad[1:-1, 1:-1] = occ
    quads: list[np.ndarray] = []  # each (k, 4, 3): corners in counter-clockwise order

    def x_of(c: np.ndarray) -> np.ndarray:
        return ox + c * res

    def y_of(r: np.ndarray) -> np.ndarray:  # north edge of row r
        return oy + (rows - r) * res

    h = float(height_m)
    # tops: runs along rows
    r, c0, c1 = _runs(occ)
    if len(r):
        xa, xb, yn, ys = x_of(c0), x_of(c1), y_of(r), y_of(r + 1)
        z = np.full_like(xa, h)
        quads.append(
            np.stack([_pts(xa, ys, z), _pts(xb, ys, z), _pts(xb, yn, z), _pts(xa, yn, z)], axis=1)
        )
    # north faces (free cell above, i.e. row - 1) and south faces: runs along rows
    for side in ("north", "south"):
        nb = pad[:-2, 1:-1] if side == "north" else pad[2:, 1:-1]
        r, c0, c1 = _runs(occ & ~nb)
        if not len(r):
            continue
        xa, xb = x_of(c0), x_of(c1)
        y = y_of(r) if side == "north" else y_of(r + 1)
        z0, z1 = np.zeros_like(xa), np.full_like(xa, h)
        if side == "north":  # normal +y: seen from the north, x runs right to left
            q = [_pts(xb, y, z0), _pts(xa, y, z0), _pts(xa, y, z1), _pts(xb, y, z1)]
        else:
            q = [_pts(xa, y, z0), _pts(xb, y, z0), _pts(xb, y, z1), _pts(xa, y, z1)]
        quads.append(np.stack(q, axis=1))
    # west and east faces: runs along columns (transpose)
    for side in ("west", "east"):
        nb = pad[1:-1, :-2] if side == "west" else pad[1:-1, 2:]
        c, r0, r1 = _runs((occ & ~nb).T)
        if not len(c):
            continue
        x = x_of(c) if side == "west" else x_of(c + 1)
        yn, ys = y_of(r0), y_of(r1)
        z0, z1 = np.zeros_like(x), np.full_like(x, h)
        if side == "west":  # normal -x
            q = [_pts(x, yn, z0), _pts(x, ys, z0), _pts(x, ys, z1), _pts(x, yn, z1)]
        else:
            q = [_pts(x, ys, z0), _pts(x, yn, z0), _pts(x, yn, z1), _pts(x, ys, z1)]
        quads.append(np.stack(q, axis=1))
    if not quads:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)
    allq = np.concatenate(quads)  # (Q, 4, 3)
    verts = allq.reshape(-1, 3).astype(np.float32)
    base = (np.arange(len(allq)) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).astype(np.uint32)
    return verts, faces


def _pts(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    x, y, z = np.broadcast_arrays(x, y, z)
    return np.stack([x, y, z], axis=-1).astype(np.float64)


# ---------------------------------------------------------------------------------- robots
@dataclass(frozen=True)
class WheelPart:
    name: str
    x_m: float  # robot frame, relative to the reference point P
    y_m: float
    radius_m: float
    width_m: float
    axle_yaw_rad: float  # direction of the axle in the robot frame (pi/2: a standard wheel)
    steered: int  # index into the robot's steered wheels, -1 when fixed
    rollers: int  # +1 / -1: Mecanum rollers at +-45 deg, 0 none


@dataclass(frozen=True)
class RobotParts:
    body_center_m: tuple[float, float, float]  # robot frame
    body_size_m: tuple[float, float, float]
    wheels: tuple[WheelPart, ...]


def robot_parts(spec: RobotSpec) -> RobotParts:
    """Body and wheels of a robot at their real positions."""
    m = spec.model
    pos = np.asarray(m.wheel_positions_m(), dtype=np.float64).reshape(-1, 2)
    radius = float(np.asarray(m.wheel_radius_m).reshape(-1)[0])
    kind = type(m).__name__.lower()
    wheels = []
    for k, name in enumerate(m.wheel_names):
        x, y = pos[k]
        if "omni" in kind:  # omni wheels roll tangentially: axle along the radius
            axle = float(np.arctan2(y, x))
        else:
            axle = np.pi / 2
        steered = list(m.steered_wheels).index(k) if k in m.steered_wheels else -1
        # Mecanum rollers: front-left and rear-right one way, the others the other way
        rollers = 0
        if "mecanum" in kind:
            rollers = 1 if k in (0, 3) else -1
        wheels.append(
            WheelPart(name, float(x), float(y), radius, 0.6 * radius, axle, steered, rollers)
        )
    lift = radius  # the body sits on the axles
    return RobotParts(
        body_center_m=(spec.body_offset_x_m, 0.0, lift + BODY_HEIGHT_M / 2),
        body_size_m=(spec.body_length_m, spec.body_width_m, BODY_HEIGHT_M),
        wheels=tuple(wheels),
    )


def quat_z(yaw: np.ndarray | float) -> np.ndarray:
    """(..., 4) quaternions of rotations by ``yaw`` about +z."""
    h = 0.5 * np.asarray(yaw, dtype=np.float64)
    out = np.zeros(h.shape + (4,))
    out[..., 0], out[..., 3] = np.cos(h), np.sin(h)
    return out


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) quaternions (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


# a cylinder's axis is its local z; this turns z onto the local y (the axle of a wheel)
_Z_TO_Y = np.array([np.cos(-np.pi / 4), np.sin(-np.pi / 4), 0.0, 0.0])


def wheel_quaternions(
    parts: RobotParts, wheel_angles: np.ndarray, steer_angles: np.ndarray
) -> np.ndarray:
    """(W, 4) orientation of each wheel in the robot frame: turned by its steering angle, then
    spun about its axle by its accumulated rotation angle (positive rolls it forward)."""
    out = np.empty((len(parts.wheels), 4))
    for k, w in enumerate(parts.wheels):
        steer = float(steer_angles[w.steered]) if w.steered >= 0 else 0.0
        yaw = w.axle_yaw_rad - np.pi / 2 + steer
        spin = quat_z(float(wheel_angles[k]))
        out[k] = quat_mul(quat_mul(quat_z(yaw), _Z_TO_Y), spin)
    return out


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vector ``v`` (3,) rotated by unit quaternion ``q`` (4,)."""
    w, u = q[0], np.asarray(q[1:])
    v = np.asarray(v, dtype=np.float64)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


# ---------------------------------------------------------------------------------- sensors
def beam_segments(
    table: SensorTable, poses: np.ndarray, scans: np.ndarray, z_m: float = 0.3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(segments (K, 2, 3), slot of each segment (K,), hit (K,) bool) for every beam of
    every sensor: from the sensor to the hit, or to its range limit when nothing is hit
    (+inf), or to range_min for a too-close reading (-inf)."""
    if table.count == 0:
        return np.zeros((0, 2, 3)), np.zeros(0, np.int64), np.zeros(0, bool)
    owner = table.owner
    px, py, pth = poses[owner, 0], poses[owner, 1], poses[owner, 2]
    mx, my, myaw = table.mount[:, 0], table.mount[:, 1], table.mount[:, 2]
    c, s = np.cos(pth), np.sin(pth)
    sx, sy = px + c * mx - s * my, py + s * mx + c * my  # sensor origins (S,)
    ang = (pth + myaw)[:, None] + table.rel_angles  # (S, B), NaN padded
    valid = ~np.isnan(table.rel_angles)
    r = np.where(np.isposinf(scans), table.range_max[:, None], scans)
    r = np.where(np.isneginf(r), table.range_min[:, None], r)
    hit = np.isfinite(scans) & valid
    slot, beam = np.nonzero(valid)
    rr, aa = r[slot, beam], ang[slot, beam]
    seg = np.empty((len(slot), 2, 3))
    seg[:, 0, 0], seg[:, 0, 1] = sx[slot], sy[slot]
    seg[:, 1, 0] = sx[slot] + rr * np.cos(aa)
    seg[:, 1, 1] = sy[slot] + rr * np.sin(aa)
    seg[:, :, 2] = z_m
    return seg, slot, hit[slot, beam]


# ---------------------------------------------------------------------------------- markers
def marker_quad(marker: Marker, offset_m: float = MARKER_OFFSET_M) -> np.ndarray:
    """(4, 3) corners of ``marker``'s printed square (quiet zone included), moved ``offset_m``
    out of its wall along the face's normal: top-left, top-right, bottom-right, bottom-left as
    seen from the front (texture row 0 at the top, column 0 on the left)."""
    nx, ny = marker.normal_xy
    return marker.corners_world(quiet_zone=True) + offset_m * np.array([nx, ny, 0.0])


def image_corners_local(width_m: float, height_m: float) -> np.ndarray:
    """(4, 3) where the viewer draws the top-left, top-right, bottom-right and bottom-left
    pixel corners of an image node (viser's ``add_image``: a plane in the node's x-y plane,
    column 0 at -x, row 0 at -y, read the right way round looking along the node's +z)."""
    w, h = 0.5 * width_m, 0.5 * height_m
    return np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])


def marker_pose(marker: Marker, offset_m: float = MARKER_OFFSET_M) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), wxyz (4,)) of the image node that shows ``marker``: centred on it,
    ``offset_m`` out of the wall, its x to the right and y down as seen from the front and its
    z into the wall, so :func:`image_corners_local` lands on :func:`marker_quad`."""
    nx, ny = marker.normal_xy
    rx, ry = marker.right_xy
    rot = np.array([[rx, 0.0, -nx], [ry, 0.0, -ny], [0.0, -1.0, 0.0]])  # columns: x, y, z
    position = np.asarray(marker.center_xyz_m, dtype=np.float64) + offset_m * np.array(
        [nx, ny, 0.0]
    )
    return position, _quat_of(rot)


def marker_image(marker: Marker, min_px: int = 128) -> np.ndarray:
    """The marker's texture (quiet zone included) scaled up by whole pixels to at least
    ``min_px`` on a side, so that the browser's texture filtering keeps the modules sharp."""
    tex = marker.texture
    k = max(1, -(-int(min_px) // max(tex.shape[:2])))
    return np.ascontiguousarray(np.repeat(np.repeat(tex, k, axis=0), k, axis=1))


def _quat_of(r: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (3, 3) (Shepperd's method)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    out = np.array(q)
    return out / np.linalg.norm(out)


# ---------------------------------------------------------------------------------- views
@dataclass(frozen=True)
class CameraPose:
    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)


def camera_panoramic(grid: OccupancyGrid) -> CameraPose:
    """From the south-west, above, looking at the map's centre (the thesis's default view)."""
    xmin, xmax, ymin, ymax = grid.extent_m
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    size = max(xmax - xmin, ymax - ymin)
    return CameraPose(
        (cx - 0.45 * size, cy - 0.62 * size, 0.55 * size), (cx + 0.08 * size, cy, 0.0)
    )


def camera_top(grid: OccupancyGrid, fov_rad: float = np.deg2rad(50.0)) -> CameraPose:
    """Straight down on the map's centre, high enough to see all of it, north up."""
    xmin, xmax, ymin, ymax = grid.extent_m
    cx, cy = (xmin + xmax) / 2, (ymin + ymax) / 2
    half = 0.5 * max(xmax - xmin, ymax - ymin) * 1.08
    height = half / np.tan(fov_rad / 2)
    return CameraPose((cx, cy, height), (cx, cy, 0.0), up=(0.0, 1.0, 0.0))


def camera_chase(pose: np.ndarray, distance_m: float = 3.0, height_m: float = 1.8) -> CameraPose:
    """Behind and above a robot at ``pose`` (x, y, theta), looking past it."""
    x, y, th = (float(v) for v in pose[:3])
    c, s = np.cos(th), np.sin(th)
    return CameraPose(
        (x - distance_m * c, y - distance_m * s, height_m), (x + 1.5 * c, y + 1.5 * s, 0.3)
    )


def camera_onboard(pose: np.ndarray, spec: Any) -> CameraPose:
    """Where a robot's onboard camera (a ``CameraSpec``: mount x, y, height, yaw, pitch down)
    is and what it looks at, for a robot at ``pose`` (x, y, theta): the thesis's sensor view."""
    x, y, th = (float(v) for v in pose[:3])
    c, s = np.cos(th), np.sin(th)
    mx, my = (float(v) for v in spec.mount_xy_m)
    px, py, pz = x + c * mx - s * my, y + s * mx + c * my, float(spec.mount_z_m)
    yaw, pitch = th + float(spec.mount_yaw_rad), float(spec.pitch_rad)
    d = (np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), -np.sin(pitch))
    return CameraPose((px, py, pz), (px + d[0], py + d[1], pz + d[2]))
