"""Reflector-based laser navigation: retro-reflectors on walls and columns, the lidar's
intensity channel, detection, triangulation and a localisation filter.

* **Intensity**: a beam whose return lies within a reflector's half-width of its centre reads
  a high intensity (``REFLECTOR_INTENSITY``), any other return a low one that falls with range
  (a diffuse surface), no return reads 0; as ``sensor_msgs/LaserScan.intensities``.
* **Detection**: consecutive high-intensity beams form one reflector; its range and bearing
  are the means over the run (in the sensor frame).
* **Association**: each detection is matched to the known reflector nearest to where the
  current pose estimate puts it, within a gate.
* **Triangulation**: from three or more matched reflectors the pose is found by Gauss-Newton
  on range and bearing residuals (a closed pose fix, no prior).
* **Filter**: an extended Kalman filter on (x, y, theta), predicted with the wheel odometry's
  increments and corrected with each matched reflector's range and bearing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from agvsim.angles import wrap_angle

REFLECTOR_INTENSITY = 1000.0
DIFFUSE_INTENSITY = 100.0  # at 1 m; falls with 1 / r^2, capped at this


@dataclass(frozen=True)
class ReflectorMap:
    """Known reflector centres ``xy`` (R, 2) in the world frame, each ``width_m`` wide."""

    xy: np.ndarray
    width_m: float = 0.08

    def __post_init__(self) -> None:
        xy = np.asarray(self.xy, dtype=np.float64).reshape(-1, 2)
        if not np.isfinite(xy).all():
            raise ValueError("reflector positions must be finite numbers")
        if not 0.0 < self.width_m <= 2.0:
            raise ValueError(f"reflector width_m must be in (0, 2] m, got {self.width_m}")
        object.__setattr__(self, "xy", xy)


def intensities(
    pose: np.ndarray,
    ranges: np.ndarray,
    beam_angles_rad: np.ndarray,
    mount_xy_m: tuple[float, float],
    mount_yaw_rad: float,
    reflectors: ReflectorMap,
) -> np.ndarray:
    """(B,) intensities of one scan taken at ``pose`` (see the module's text)."""
    r = np.asarray(ranges, dtype=np.float64)
    hit = np.isfinite(r) & (r > 0)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    ox = pose[0] + c * mount_xy_m[0] - s * mount_xy_m[1]
    oy = pose[1] + s * mount_xy_m[0] + c * mount_xy_m[1]
    a = pose[2] + mount_yaw_rad + np.asarray(beam_angles_rad, dtype=np.float64)
    rr = np.where(hit, r, 0.0)
    pts = np.column_stack([ox + rr * np.cos(a), oy + rr * np.sin(a)])
    out = np.where(
        hit, np.minimum(DIFFUSE_INTENSITY, DIFFUSE_INTENSITY / np.maximum(rr, 1e-3) ** 2), 0.0
    )
    if len(reflectors.xy) and hit.any():
        d = np.hypot(*(pts[:, None, :] - reflectors.xy[None, :, :]).transpose(2, 0, 1))
        on = (d.min(axis=1) <= reflectors.width_m / 2.0) & hit
        out[on] = REFLECTOR_INTENSITY
    return out


@dataclass(frozen=True)
class Detection:
    range_m: float
    bearing_rad: float  # in the robot frame (the mount's yaw included)
    beams: int


def detect(
    ranges: np.ndarray,
    intensity: np.ndarray,
    beam_angles_rad: np.ndarray,
    mount_xy_m: tuple[float, float] = (0.0, 0.0),
    mount_yaw_rad: float = 0.0,
    threshold: float = 0.5 * REFLECTOR_INTENSITY,
) -> list[Detection]:
    """Reflectors in one scan: runs of consecutive beams above ``threshold`` (a run may wrap
    around a full-circle scan's ends), as range and bearing from the robot's reference point."""
    bright = np.asarray(intensity) >= threshold
    n = len(bright)
    if not bright.any():
        return []
    # start the walk just after a dark beam, so a run over the scan's ends stays whole
    first_dark = int(np.argmin(bright)) if not bright.all() else 0
    order = (np.arange(n) + first_dark) % n
    runs: list[list[int]] = []
    cur: list[int] = []
    for i in order:
        if bright[i]:
            cur.append(int(i))
        elif cur:
            runs.append(cur)
            cur = []
    if cur:
        runs.append(cur)
    out = []
    r = np.asarray(ranges, dtype=np.float64)
    a = np.asarray(beam_angles_rad, dtype=np.float64) + mount_yaw_rad
    for run in runs:
        idx = np.array(run)
        # the mean point of the run's returns, in the robot frame
        px = mount_xy_m[0] + (r[idx] * np.cos(a[idx])).mean()
        py = mount_xy_m[1] + (r[idx] * np.sin(a[idx])).mean()
        out.append(Detection(math.hypot(px, py), math.atan2(py, px), len(run)))
    return out


def associate(
    pose: np.ndarray, detections: list[Detection], reflectors: ReflectorMap, gate_m: float
) -> list[tuple[Detection, int]]:
    """Pairs (detection, reflector index): each detection placed in the world by ``pose`` and
    matched to the nearest reflector within ``gate_m``; a reflector is matched at most once
    (the closer detection wins)."""
    if not detections or len(reflectors.xy) == 0:
        return []
    pairs: dict[int, tuple[float, Detection]] = {}
    for det in detections:
        a = pose[2] + det.bearing_rad
        p = np.array([pose[0] + det.range_m * math.cos(a), pose[1] + det.range_m * math.sin(a)])
        d = np.hypot(*(reflectors.xy - p).T)
        k = int(d.argmin())
        if d[k] <= gate_m and (k not in pairs or d[k] < pairs[k][0]):
            pairs[k] = (float(d[k]), det)
    return [(det, k) for k, (_, det) in sorted(pairs.items())]


def _measure(pose: np.ndarray, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Predicted (range, bearing) of reflectors ``xy`` (K, 2) from ``pose`` and the Jacobian
    (2K, 3) of [r_0, b_0, r_1, b_1, ...] with respect to (x, y, theta)."""
    dx, dy = xy[:, 0] - pose[0], xy[:, 1] - pose[1]
    q = np.maximum(dx * dx + dy * dy, 1e-12)
    r = np.sqrt(q)
    b = wrap_angle(np.arctan2(dy, dx) - pose[2])
    z = np.column_stack([r, b]).ravel()
    h = np.zeros((2 * len(xy), 3))
    h[0::2, 0], h[0::2, 1] = -dx / r, -dy / r
    h[1::2, 0], h[1::2, 1], h[1::2, 2] = dy / q, -dx / q, -1.0
    return z, h


def triangulate(
    matches: list[tuple[Detection, int]],
    reflectors: ReflectorMap,
    guess: np.ndarray,
    iterations: int = 20,
) -> np.ndarray | None:
    """The pose that best explains three or more matched reflectors (Gauss-Newton from
    ``guess``); None with fewer than three or when the geometry is degenerate (all
    reflectors on one line through the robot)."""
    if len(matches) < 3:
        return None
    xy = reflectors.xy[[k for _, k in matches]]
    meas = np.array([[d.range_m, d.bearing_rad] for d, _ in matches]).ravel()
    x = np.asarray(guess, dtype=np.float64).copy()
    for _ in range(iterations):
        z, h = _measure(x, xy)
        res = meas - z
        res[1::2] = wrap_angle(res[1::2])
        try:
            step = np.linalg.lstsq(h, res, rcond=None)[0]
        except np.linalg.LinAlgError:
            return None
        if np.linalg.matrix_rank(h) < 3:
            return None
        x += step
        x[2] = float(wrap_angle(x[2]))
        if np.abs(step).max() < 1e-10:
            break
    return x


@dataclass
class ReflectorEkf:
    """An extended Kalman filter on the pose, predicted with odometry increments (in the
    robot frame) and corrected with matched reflectors' range and bearing."""

    reflectors: ReflectorMap
    pose: np.ndarray
    cov: np.ndarray = field(default_factory=lambda: np.diag([0.01, 0.01, 0.001]))
    odom_noise: tuple[float, float] = (0.02, 0.02)  # std per metre driven, per radian turned
    range_std_m: float = 0.02
    bearing_std_rad: float = 0.005
    gate_m: float = 0.5
    updates: int = 0

    def predict(self, delta: np.ndarray) -> None:
        """Move by the odometry increment ``delta`` = (dx, dy, dtheta) in the robot frame."""
        dx, dy, dth = (float(v) for v in delta)
        th = float(self.pose[2])
        c, s = math.cos(th), math.sin(th)
        self.pose = np.array(
            [self.pose[0] + c * dx - s * dy, self.pose[1] + s * dx + c * dy, wrap_angle(th + dth)]
        )
        f = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
        dist = math.hypot(dx, dy)
        kt, kr = self.odom_noise
        q = np.diag(
            [
                (kt * dist) ** 2 + 1e-10,
                (kt * dist) ** 2 + 1e-10,
                (kr * abs(dth) + 0.1 * kt * dist) ** 2 + 1e-12,
            ]
        )
        self.cov = f @ self.cov @ f.T + q

    def correct(self, detections: list[Detection]) -> int:
        """Update with the detections that match a reflector; returns how many did."""
        matches = associate(self.pose, detections, self.reflectors, self.gate_m)
        if not matches:
            return 0
        xy = self.reflectors.xy[[k for _, k in matches]]
        z, h = _measure(self.pose, xy)
        meas = np.array([[d.range_m, d.bearing_rad] for d, _ in matches]).ravel()
        res = meas - z
        res[1::2] = wrap_angle(res[1::2])
        r = np.diag(np.tile([self.range_std_m**2, self.bearing_std_rad**2], len(matches)))
        s = h @ self.cov @ h.T + r
        k = np.linalg.solve(s, h @ self.cov).T
        self.pose = self.pose + k @ res
        self.pose[2] = float(wrap_angle(self.pose[2]))
        self.cov = (np.eye(3) - k @ h) @ self.cov
        self.cov = 0.5 * (self.cov + self.cov.T)
        self.updates += 1
        return len(matches)
