"""Find a marker with the onboard camera and stop in front of it (the thesis's "future work":
image recognition on the camera view).

``MarkerSearch`` drives a robot that can turn on the spot with nothing but its RGB-D camera and
its odometry:

* **scan**: turn on the spot, a full turn, looking for the wanted ArUco/AprilTag id with
  OpenCV's detector and noting how far the floor ahead is free in each direction;
* **explore**: if the marker was not seen, turn towards the direction that leads furthest from
  the places already scanned (among those free for at least ``min_leg_m``), drive up to
  ``leg_m`` that way (stopping short of obstacles seen in the depth image), and scan again;
* **approach**: once it is seen, back-project the marker's pixels with the depth image to get
  its centre and its wall's normal, and drive to the point ``stop_distance_m`` in front of it
  (measured from the camera), re-aiming at every new detection;
* **align**: turn to face the marker squarely; then **done** (zero twist).

Every decision is made on a new frame (the camera's rate); between frames the robot keeps its
course. Poses come from wheel odometry by default (``pose_source``), as a real robot would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agvsim.control.api import Observation, command_for
from agvsim.control.mobility import PoseSource, check_pose_source, pose_of, wrap
from agvsim.sensors.camera import CameraSpec, pixels_to_robot


@dataclass(frozen=True)
class MarkerTarget:
    """Where to stop: the robot's reference point and heading (world / odometry frame)."""

    x_m: float
    y_m: float
    theta_rad: float
    marker_xy_m: tuple[float, float]  # the marker's centre, same frame


class MarkerSearch:
    """See the module docstring. ``camera`` is the robot's camera spec (intrinsics and mount);
    ``dictionary`` an OpenCV ArUco dictionary name (``4x4_50``) or an AprilTag family prefixed
    ``apriltag_`` (``apriltag_36h11``)."""

    def __init__(
        self,
        camera: CameraSpec,
        marker_id: int,
        dictionary: str = "4x4_50",
        stop_distance_m: float = 0.8,
        speed_m_s: float = 0.4,
        turn_rate_rad_s: float = 0.8,
        body_half_width_m: float = 0.225,
        body_front_m: float = 0.3,
        body_height_m: float = 0.35,
        clearance_m: float = 0.25,
        leg_m: float = 2.5,
        min_leg_m: float = 0.6,
        position_tolerance_m: float = 0.02,
        heading_tolerance_rad: float = 0.005,
        pose_source: PoseSource = "odometry",
    ) -> None:
        check_pose_source(pose_source)
        if marker_id < 0:
            raise ValueError(f"marker_id must be >= 0, got {marker_id}")
        if not stop_distance_m > 0:
            raise ValueError(f"stop_distance_m must be > 0, got {stop_distance_m}")
        self.camera = camera
        self.marker_id = int(marker_id)
        self.dictionary = dictionary
        self.stop_distance_m = float(stop_distance_m)
        self.speed_m_s, self.turn_rate_rad_s = float(speed_m_s), float(turn_rate_rad_s)
        self.half_width_m, self.front_m = float(body_half_width_m), float(body_front_m)
        self.height_m, self.clearance_m = float(body_height_m), float(clearance_m)
        self.leg_m, self.min_leg_m = float(leg_m), float(min_leg_m)
        self.pos_tol, self.head_tol = float(position_tolerance_m), float(heading_tolerance_rad)
        self.pose_source = pose_source
        self._detector = _make_detector(dictionary)
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        self.state_name = "scan"
        self.target: MarkerTarget | None = None
        self._stamp = -1.0
        self._scan_turned = 0.0
        self._last_theta: float | None = None
        self._samples: list[tuple[float, float]] = []  # (heading, free distance) while scanning
        self._visited: list[tuple[float, float]] = []
        self._heading: float | None = None  # explore: the heading chosen
        self._leg_start: tuple[float, float] | None = None
        self._free_ahead = math.inf
        self._t_s = 0.0
        self.found_at_s: float | None = None  # when the marker was first seen

    def report(self) -> dict:
        """What the search came to, for the run's summary."""
        t = self.target
        return {
            "marker_id": self.marker_id,
            "marker_found": t is not None,
            "found_at_s": self.found_at_s,
            "stopped_in_front": self.state_name == "done",
            "marker_xy_m": None if t is None else [round(v, 4) for v in t.marker_xy_m],
            "state": self.state_name,
        }

    # ------------------------------------------------------------------ step
    def step(self, obs: Observation):
        pose = pose_of(obs, self.pose_source)
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        images = getattr(obs, "images", {})
        if self.camera.name not in images:
            raise ValueError(
                f"marker_search needs the camera {self.camera.name!r}; the observation has "
                f"{sorted(images) or 'no cameras'}"
            )
        self._t_s = float(obs.t_s)
        stamp = float(obs.image_stamps[self.camera.name])  # type: ignore[attr-defined]
        if stamp != self._stamp and self.state_name != "done":
            self._stamp = stamp
            rgb = images[self.camera.name]
            depth = obs.depth[self.camera.name]  # type: ignore[attr-defined]
            self._on_frame(rgb, depth, x, y, th)
        if obs.bump and self.state_name == "explore":
            self._start_scan(x, y)
        vx, omega = self._drive(x, y, th)
        return command_for(obs, vx, 0.0, omega)

    def _on_frame(self, rgb: np.ndarray, depth: np.ndarray, x: float, y: float, th: float):
        target = self.locate(rgb, depth, (x, y, th))
        if target is not None and self.state_name != "align":
            if self.found_at_s is None:
                self.found_at_s = self._t_s
            self.target = target
            if self.state_name in ("scan", "explore"):
                self.state_name = "approach"
        self._free_ahead = self.free_ahead_m(depth)
        if self.state_name == "scan":
            self._samples.append((th, self._free_ahead))

    def _start_scan(self, x: float, y: float) -> None:
        self.state_name = "scan"
        self._scan_turned = 0.0
        self._last_theta = None
        self._samples = []
        self._visited.append((x, y))

    def _drive(self, x: float, y: float, th: float) -> tuple[float, float]:
        """(vx, omega) for the current state."""
        if self.state_name == "scan":
            if self._last_theta is None:
                self._visited.append((x, y))
            else:
                self._scan_turned += abs(wrap(th - self._last_theta))
            self._last_theta = th
            if self._scan_turned >= 2.0 * math.pi:
                self._heading = self._choose_heading(x, y)
                self._leg_start = (x, y)
                self.state_name = "explore"
            else:
                return 0.0, self.turn_rate_rad_s
        if self.state_name == "explore":
            assert self._heading is not None and self._leg_start is not None
            err = wrap(self._heading - th)
            if abs(err) > 0.05:
                return 0.0, self._turn(err)
            driven = math.hypot(x - self._leg_start[0], y - self._leg_start[1])
            if driven >= self.leg_m or self._free_ahead < self.clearance_m + 0.1:
                self._start_scan(x, y)
                return 0.0, 0.0
            return self.speed_m_s, self._turn(err)
        if self.state_name == "approach":
            assert self.target is not None
            dx, dy = self.target.x_m - x, self.target.y_m - y
            dist = math.hypot(dx, dy)
            if dist <= self.pos_tol:
                self.state_name = "align"
            else:
                err = wrap(math.atan2(dy, dx) - th)
                if abs(err) > 0.4:
                    return 0.0, self._turn(err)
                v = min(self.speed_m_s, 1.2 * dist) * math.cos(err)
                return v, self._turn(err)
        if self.state_name == "align":
            assert self.target is not None
            err = wrap(self.target.theta_rad - th)
            if abs(err) <= self.head_tol:
                self.state_name = "done"
            else:
                return 0.0, self._turn(err)
        return 0.0, 0.0

    def _turn(self, err: float) -> float:
        return float(np.clip(2.5 * err, -self.turn_rate_rad_s, self.turn_rate_rad_s))

    def _choose_heading(self, x: float, y: float) -> float:
        """The scanned heading whose leg ends furthest from every place scanned before (ties to
        the longer free leg); a quarter turn when nothing is free enough."""
        best, best_score = None, -math.inf
        visited = np.array(self._visited) if self._visited else np.zeros((0, 2))
        for th, free in self._samples:
            reach = min(free - self.clearance_m - 0.1, self.leg_m)
            if reach < self.min_leg_m:
                continue
            end = np.array([x + reach * math.cos(th), y + reach * math.sin(th)])
            novelty = float(np.min(np.hypot(*(visited - end).T))) if len(visited) else 0.0
            score = novelty + 0.25 * reach
            if score > best_score:
                best, best_score = th, score
        if best is None:
            last = self._samples[-1][0] if self._samples else 0.0
            return wrap(last + math.pi / 2)
        return best

    # ------------------------------------------------------------------ vision
    def free_ahead_m(self, depth: np.ndarray, step: int = 4) -> float:
        """How far the robot can drive straight on before its body (widened by
        ``clearance_m``) meets what the depth image shows at body height (m; inf: nothing)."""
        d = np.asarray(depth)[::step, ::step]
        v, u = np.mgrid[0 : depth.shape[0] : step, 0 : depth.shape[1] : step]
        ok = np.isfinite(d)
        if not ok.any():
            return math.inf
        pts = pixels_to_robot(self.camera, u[ok], v[ok], d[ok])
        body = (
            (pts[:, 2] > 0.05)
            & (pts[:, 2] < self.height_m + 0.2)
            & (np.abs(pts[:, 1]) <= self.half_width_m + self.clearance_m)
            & (pts[:, 0] > 0.0)
        )
        if not body.any():
            return math.inf
        return float(pts[body, 0].min() - self.front_m)

    def detect(self, rgb: np.ndarray) -> np.ndarray | None:
        """(4, 2) pixel corners of the wanted marker (top-left first, clockwise) or None."""
        import cv2

        gray = cv2.cvtColor(np.asarray(rgb), cv2.COLOR_RGB2GRAY)
        corners, ids, _ = self._detector.detectMarkers(gray)
        if ids is None:
            return None
        for c, i in zip(corners, ids.ravel(), strict=True):
            if int(i) == self.marker_id:
                return np.asarray(c, dtype=np.float64).reshape(4, 2)
        return None

    def locate(
        self, rgb: np.ndarray, depth: np.ndarray, pose: tuple[float, float, float]
    ) -> MarkerTarget | None:
        """Detect the wanted marker and turn it into the stop pose (in the frame of ``pose``),
        or None when it is not in the image."""
        corners = self.detect(rgb)
        if corners is None:
            return None
        # sample points inside the marker (bilinear in its corners), back-projected with depth
        g = np.linspace(0.2, 0.8, 5)
        s, t = np.meshgrid(g, g)
        s, t = s.ravel()[:, None], t.ravel()[:, None]
        tl, tr, br, bl = corners
        px = (1 - t) * ((1 - s) * tl + s * tr) + t * ((1 - s) * bl + s * br)
        h, w = depth.shape
        u = np.clip(np.rint(px[:, 0]).astype(int), 0, w - 1)
        v = np.clip(np.rint(px[:, 1]).astype(int), 0, h - 1)
        d = np.asarray(depth)[v, u].astype(np.float64)
        ok = np.isfinite(d)
        if ok.sum() < 6:
            return None
        pts = pixels_to_robot(self.camera, u[ok], v[ok], d[ok])[:, :2]
        mean = pts.mean(axis=0)
        # the wall's direction: the principal axis of the points; the normal faces the camera
        _, _, vt = np.linalg.svd(pts - mean)
        along = vt[0]
        normal = np.array([-along[1], along[0]])
        cam = np.array(self.camera.mount_xy_m)
        if np.dot(cam - mean, normal) < 0:
            normal = -normal
        # the centre: where the ray through the crossing of the diagonals meets the wall
        # (the mean of the samples is off it in a slanted view)
        uc, vc = _diagonals_crossing(corners)
        ray = pixels_to_robot(self.camera, np.array([uc]), np.array([vc]), np.ones(1))[0, :2] - cam
        centre = cam + ray * float(np.dot(normal, mean - cam) / np.dot(normal, ray))
        heading_r = math.atan2(-normal[1], -normal[0])  # facing the marker, robot frame
        cam_goal = centre + self.stop_distance_m * normal
        c, sn = math.cos(heading_r), math.sin(heading_r)
        mx, my = self.camera.mount_xy_m
        goal = cam_goal - np.array([c * mx - sn * my, sn * mx + c * my])
        x, y, th = pose
        cw, sw = math.cos(th), math.sin(th)

        def to_world(p: np.ndarray) -> tuple[float, float]:
            return (x + cw * p[0] - sw * p[1], y + sw * p[0] + cw * p[1])

        gx, gy = to_world(goal)
        return MarkerTarget(gx, gy, wrap(th + heading_r), to_world(centre))


def _diagonals_crossing(corners: np.ndarray) -> tuple[float, float]:
    """Pixel where the diagonals of a quadrilateral (4, 2) cross: the image of the centre of
    the square it is a perspective view of."""
    p, r = corners[0], corners[2] - corners[0]
    q, t = corners[1], corners[3] - corners[1]
    den = r[0] * t[1] - r[1] * t[0]
    if abs(den) < 1e-12:
        return float(corners[:, 0].mean()), float(corners[:, 1].mean())
    k = ((q[0] - p[0]) * t[1] - (q[1] - p[1]) * t[0]) / den
    return float(p[0] + k * r[0]), float(p[1] + k * r[1])


def _make_detector(dictionary: str):
    """OpenCV's ArUco detector for ``dictionary`` (``4x4_50``, ..., ``apriltag_36h11``)."""
    import cv2

    from agvsim.world.markers import MarkerKind, aruco_dictionary

    if dictionary.startswith("apriltag_"):
        d = aruco_dictionary(MarkerKind.APRILTAG, dictionary.removeprefix("apriltag_"))
    else:
        d = aruco_dictionary(MarkerKind.ARUCO, dictionary)
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return cv2.aruco.ArucoDetector(d, params)
