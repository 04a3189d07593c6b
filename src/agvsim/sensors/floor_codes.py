"""Floor codes (the Kiva-style grid): 2-D codes laid on the floor at every grid point, and a
downward camera under the vehicle that reads them for a position fix.

The codes are ArUco or AprilTag fiducials (OpenCV's ``cv2.aruco``, the library that makes and
reads the wall markers of :mod:`agvsim.world.markers`); the code at grid column ``c`` and row
``r`` has id ``r * cols + c``. Seen from above with world +y up, a code stands upright.

The camera looks straight down from ``mount_xy_m`` on the robot and sees a ``width_px`` x
``height_px`` patch at ``m_per_px`` metres per pixel, image up being the robot's forward. The
picture is rendered exactly (each pixel takes the module under its centre) and decoded by
OpenCV; the code's four corners then give the camera's pose relative to the code, and with the
code's known place the robot's pose (a rigid fit of the four corners).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from agvsim.world.markers import aruco_dictionary

FLOOR_GREY = 150
WHITE, BLACK = 255, 0


@dataclass(frozen=True)
class FloorCodeGrid:
    """Codes ``size_m`` wide (the black square) at ``origin_xy_m + (c, r) * spacing_m``."""

    cols: int
    rows: int
    spacing_m: float = 1.0
    size_m: float = 0.05
    origin_xy_m: tuple[float, float] = (0.0, 0.0)
    kind: str = "aruco"
    dictionary: str = "4x4_1000"

    def __post_init__(self) -> None:
        if self.cols < 1 or self.rows < 1:
            raise ValueError(
                f"floor codes: cols and rows must be >= 1, got {self.cols}x{self.rows}"
            )
        if not 0.0 < self.size_m < self.spacing_m:
            raise ValueError(
                f"floor codes: need 0 < size_m < spacing_m, got {self.size_m} and {self.spacing_m}"
            )
        n = self.cols * self.rows
        if self.kind not in ("aruco", "apriltag", "qr"):
            raise ValueError(f"floor codes: kind {self.kind!r} is not aruco, apriltag or qr")
        gap = self.size_m + 2.0 * self.quiet_modules * self.size_m / self.modules.shape[1]
        if gap >= self.spacing_m:
            raise ValueError(
                f"floor codes: codes {self.size_m} m wide with their quiet zone ({gap:.3f} m) "
                f"do not fit the {self.spacing_m} m spacing"
            )
        if self.kind == "qr":
            return  # a QR code's text is its id: any number
        have = int(self._dict.bytesList.shape[0])
        if n > have:
            raise ValueError(
                f"floor codes: {self.cols} x {self.rows} = {n} codes but {self.kind} "
                f"{self.dictionary!r} has only {have} ids (use a larger dictionary)"
            )

    @cached_property
    def _dict(self):  # noqa: ANN202 - OpenCV's type
        return aruco_dictionary(self.kind, self.dictionary)

    @property
    def quiet_modules(self) -> int:
        """The white margin around each code, in modules (ISO 18004 asks 4 for QR)."""
        return 4 if self.kind == "qr" else 1

    @cached_property
    def modules(self) -> np.ndarray:
        """(n_codes, m, m) uint8 module images (black border included, no quiet zone); a QR
        code holds its id as text."""
        import cv2

        if self.kind == "qr":
            enc = cv2.QRCodeEncoder.create()
            codes = []
            for k in range(self.cols * self.rows):
                img = np.asarray(enc.encode(str(k)))
                dark = np.argwhere(img < 128)
                (r0, c0), (r1, c1) = dark.min(axis=0), dark.max(axis=0)
                codes.append(img[r0 : r1 + 1, c0 : c1 + 1])
            if len({c.shape for c in codes}) != 1:  # pragma: no cover - short ids: version 1
                raise ValueError("floor codes: the QR codes differ in size")
            return np.stack(codes)
        side = int(self._dict.markerSize) + 2
        return np.stack(
            [
                np.asarray(cv2.aruco.generateImageMarker(self._dict, k, side, borderBits=1))
                for k in range(self.cols * self.rows)
            ]
        )

    def code_xy(self, code_id: int) -> tuple[float, float]:
        r, c = divmod(code_id, self.cols)
        return (
            self.origin_xy_m[0] + c * self.spacing_m,
            self.origin_xy_m[1] + r * self.spacing_m,
        )

    def shade(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Grey level of the floor at world points (arrays of one shape): the module of the code
        under a point (a white quiet zone of one module around each code), else bare floor."""
        fx = (x - self.origin_xy_m[0]) / self.spacing_m
        fy = (y - self.origin_xy_m[1]) / self.spacing_m
        c, r = np.rint(fx).astype(np.int64), np.rint(fy).astype(np.int64)
        du = x - (self.origin_xy_m[0] + c * self.spacing_m)
        dv = y - (self.origin_xy_m[1] + r * self.spacing_m)
        m = self.modules.shape[1]
        module_m = self.size_m / m
        half = self.size_m / 2.0
        on_grid = (c >= 0) & (c < self.cols) & (r >= 0) & (r < self.rows)
        q = half + self.quiet_modules * module_m
        quiet = on_grid & (np.abs(du) <= q) & (np.abs(dv) <= q)
        inside = on_grid & (np.abs(du) < half) & (np.abs(dv) < half)
        out = np.where(quiet, WHITE, FLOOR_GREY).astype(np.uint8)
        if inside.any():
            ids = (r * self.cols + c)[inside]
            mc = np.clip(((du[inside] + half) / module_m).astype(np.int64), 0, m - 1)
            mr = np.clip(((half - dv[inside]) / module_m).astype(np.int64), 0, m - 1)
            out[inside] = self.modules[ids, mr, mc]
        return out


@dataclass(frozen=True)
class FloorCameraSpec:
    name: str = "floor_camera"
    width_px: int = 160
    height_px: int = 160
    m_per_px: float = 0.001  # 1 mm a pixel: a 16 cm square patch
    mount_xy_m: tuple[float, float] = (0.0, 0.0)
    rate_hz: float = 10.0

    def __post_init__(self) -> None:
        if not (16 <= self.width_px <= 2048 and 16 <= self.height_px <= 2048):
            raise ValueError("floor camera: width_px and height_px must be 16..2048")
        if not 0.0 < self.m_per_px <= 0.05:
            raise ValueError(f"floor camera: m_per_px must be in (0, 0.05], got {self.m_per_px}")
        if not self.rate_hz > 0:
            raise ValueError(f"floor camera: rate_hz must be > 0, got {self.rate_hz}")

    def pixel_to_robot(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Robot-frame points (..., 2) of image points (``u`` column, ``v`` row, OpenCV's
        continuous pixel coordinates: pixel (i, j) covers [j, j + 1) x [i, i + 1))."""
        s = self.m_per_px
        x = self.mount_xy_m[0] + (self.height_px / 2.0 - v) * s
        y = self.mount_xy_m[1] - (u - self.width_px / 2.0) * s
        return np.stack([x, y], axis=-1)


def render(spec: FloorCameraSpec, grid: FloorCodeGrid, pose: np.ndarray) -> np.ndarray:
    """The (height_px, width_px) uint8 image the downward camera takes at ``pose``."""
    j, i = np.meshgrid(np.arange(spec.width_px) + 0.5, np.arange(spec.height_px) + 0.5)
    p = spec.pixel_to_robot(j, i)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    wx = pose[0] + c * p[..., 0] - s * p[..., 1]
    wy = pose[1] + s * p[..., 0] + c * p[..., 1]
    return grid.shade(wx, wy)


@dataclass(frozen=True)
class CodeFix:
    code_id: int
    pose: np.ndarray  # (3,) the robot's pose from the code
    corners_px: np.ndarray  # (4, 2)


@dataclass(frozen=True)
class FloorFixReading:
    """A floor camera's latest fix: ``seq`` fixes so far (0: none yet), the last at
    ``stamp_s`` from code ``code_id`` giving the robot's ``pose`` (x, y, theta, world)."""

    stamp_s: float
    seq: int
    code_id: int
    pose: np.ndarray


def read_fix(spec: FloorCameraSpec, grid: FloorCodeGrid, image: np.ndarray) -> CodeFix | None:
    """Decode the image (OpenCV's ArUco or QR detector); from the first whole code with an id
    on the grid, the robot's pose. None when no code is read."""
    import cv2

    if grid.kind == "qr":
        text, points, _ = cv2.QRCodeDetector().detectAndDecode(image)
        if not text or points is None or not text.isdigit():
            return None
        found = [(np.asarray(points, dtype=np.float64).reshape(4, 2), int(text))]
    else:
        found = _aruco_codes(grid, image)
    for px, k in found:
        if not 0 <= k < grid.cols * grid.rows:
            continue
        robot = spec.pixel_to_robot(px[:, 0], px[:, 1])
        cx, cy = grid.code_xy(k)
        h = grid.size_m / 2.0
        # OpenCV's corner order: top-left, top-right, bottom-right, bottom-left of the code
        world = np.array([[cx - h, cy + h], [cx + h, cy + h], [cx + h, cy - h], [cx - h, cy - h]])
        return CodeFix(k, _rigid_fit(robot, world), px)
    return None


def _aruco_codes(grid: FloorCodeGrid, image: np.ndarray) -> list[tuple[np.ndarray, int]]:
    import cv2

    detector = cv2.aruco.ArucoDetector(grid._dict, cv2.aruco.DetectorParameters())
    corners, ids, _ = detector.detectMarkers(image)
    if ids is None:
        return []
    return [
        (np.asarray(quad, dtype=np.float64).reshape(4, 2), int(code))
        for quad, code in zip(corners, ids.ravel(), strict=True)
    ]


def _rigid_fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The pose (x, y, theta) whose rotation and translation carry points ``a`` onto ``b``
    best in least squares (2-D Kabsch): b ~ R(theta) a + (x, y)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    p, q = a - ca, b - cb
    theta = math.atan2(
        float((p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]).sum()),
        float((p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]).sum()),
    )
    c, s = math.cos(theta), math.sin(theta)
    t = cb - np.array([c * ca[0] - s * ca[1], s * ca[0] + c * ca[1]])
    return np.array([t[0], t[1], theta])
