"""Drive a route by pure pursuit on an *estimated* pose, the way an industrial vehicle does,
and measure how far the estimate is from the truth (docs/guidance.md).

``localization``:

* ``odometry``: the wheel odometry alone (dead reckoning, the baseline);
* ``floor_codes``: the last floor-code fix of the downward camera ``camera``, moved on by the
  odometry driven since that fix (between codes the vehicle runs on odometry);
* ``reflectors``: a :class:`~agvsim.sensors.reflectors.ReflectorEkf` predicted with the
  odometry's increments and corrected with the reflectors the lidar ``sensor`` sees (runs of
  high intensity).

The ground truth is read only to score the estimate: ``pose_error_m`` every step until the
route's end, reported as mean and max (``report``), and ``estimate`` for trajectory.csv.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.control.api import Observation, command_for
from agvsim.control.mobility import Mobility
from agvsim.control.pure_pursuit import PurePursuit
from agvsim.sensors.reflectors import ReflectorEkf, ReflectorMap, detect

Localization = Literal["odometry", "floor_codes", "reflectors"]
LOCALIZATIONS = ("odometry", "floor_codes", "reflectors")


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose ``b`` in the frame of pose ``a`` (a^-1 b), both (x, y, theta)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_scalar(b[2] - a[2])])


def compose(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Pose ``a`` moved by ``d`` given in its own frame (a d)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array(
        [a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], wrap_scalar(a[2] + d[2])]
    )


class RouteFollower:
    """Follow the polyline ``points`` by pure pursuit on the pose from ``localization``.

    ``state_name``: "follow" or "reached"."""

    def __init__(
        self,
        points: Sequence[Sequence[float]] | np.ndarray,
        localization: Localization = "odometry",
        lookahead_m: float = 0.6,
        speed_m_s: float = 0.5,
        tolerance_m: float = 0.15,
        max_turn_rate_rad_s: float = 1.5,
        camera: str = "floor_camera",
        sensor: str = "lidar",
        reflectors: ReflectorMap | None = None,
        range_std_m: float = 0.02,
        bearing_std_rad: float = 0.005,
        gate_m: float = 0.5,
        odom_noise: tuple[float, float] = (0.02, 0.02),
    ):
        if localization not in LOCALIZATIONS:
            raise ValueError(
                f"localization: {localization!r} is not one of {', '.join(LOCALIZATIONS)}"
            )
        if localization == "reflectors" and reflectors is None:
            raise ValueError("localization: reflectors needs the world's reflectors")
        self.pursuit = PurePursuit(
            points, lookahead_m, speed_m_s, False, tolerance_m, max_turn_rate_rad_s, True
        )
        self.localization, self.camera, self.sensor = localization, camera, sensor
        self.reflectors = reflectors
        self._ekf_args = {
            "range_std_m": range_std_m,
            "bearing_std_rad": bearing_std_rad,
            "gate_m": gate_m,
            "odom_noise": tuple(odom_noise),
        }
        self.reset()

    def reset(self) -> None:
        self.pursuit.reset()
        self.state_name = "follow"
        self.estimate: np.ndarray | None = None  # of the last observation, at its time:
        self.estimate_stamp_s = math.nan
        self.pose_error_m = math.nan
        self._errors: list[float] = []
        self._prev_odom: np.ndarray | None = None
        self._anchor: tuple[np.ndarray, np.ndarray] | None = None  # (fix pose, odom at fix)
        self._fix_seq = 0
        self._scan_stamp = -math.inf
        self.fixes = 0
        self._ekf: ReflectorEkf | None = None

    # ------------------------------------------------------------------ localisation
    def _localize(self, obs: Observation) -> np.ndarray:
        odom = np.asarray(obs.odom_pose, dtype=np.float64)
        if self._prev_odom is None:  # the run starts where the vehicle was put: it knows that
            self._anchor = (odom.copy(), odom.copy())
            if self.localization == "reflectors":
                assert self.reflectors is not None
                self._ekf = ReflectorEkf(self.reflectors, odom.copy(), **self._ekf_args)  # type: ignore[arg-type]
        prev, self._prev_odom = self._prev_odom, odom.copy()
        if self.localization == "odometry":
            return odom.copy()
        if self.localization == "floor_codes":
            fix = obs.floor_fixes.get(self.camera)
            if fix is None:
                raise ValueError(
                    f"route: robot {obs.name!r} has no floor camera {self.camera!r} "
                    f"(it has: {', '.join(obs.floor_fixes) or 'none'})"
                )
            if fix.seq != self._fix_seq:
                self._fix_seq = fix.seq
                self._anchor = (fix.pose.copy(), odom.copy())
                self.fixes += 1
            assert self._anchor is not None
            base, odom_then = self._anchor
            return compose(base, relative(odom_then, odom))
        ekf = self._ekf
        assert ekf is not None
        if prev is not None:
            ekf.predict(relative(prev, odom))
        scan = obs.scans.get(self.sensor)
        if scan is None:
            raise ValueError(
                f"route: robot {obs.name!r} has no range sensor {self.sensor!r} "
                f"(it has: {', '.join(obs.scans) or 'none'})"
            )
        if scan.stamp_s != self._scan_stamp and scan.intensities is not None:
            self._scan_stamp = scan.stamp_s
            dets = detect(
                scan.ranges,
                scan.intensities,
                scan.angles_rad,
                (float(scan.mount_pose[0]), float(scan.mount_pose[1])),
                float(scan.mount_pose[2]),
            )
            if ekf.correct(dets):
                self.fixes += 1
        return ekf.pose.copy()

    # ------------------------------------------------------------------ control
    def step(self, obs: Observation) -> object:
        est = self._localize(obs)
        self.estimate, self.estimate_stamp_s = est, obs.t_s
        truth = obs.true_pose
        self.pose_error_m = math.hypot(est[0] - truth[0], est[1] - truth[1])
        if self.state_name != "reached":
            self._errors.append(self.pose_error_m)
        mob = Mobility.of(obs.model)
        pp = self.pursuit
        v, vy, w = pp.twist(est, mob)
        self.state_name = pp.state_name
        return command_for(obs, *pp.guard(v, vy, w, mob, obs.dt_s))

    def report(self) -> dict:
        e = np.asarray(self._errors)
        return {
            "localization": self.localization,
            "route_reached": self.state_name == "reached",
            "route_length_m": round(self.pursuit.tracker.length_m, 6),
            "pose_error_mean_m": float(e.mean()) if e.size else None,
            "pose_error_max_m": float(e.max()) if e.size else None,
            "pose_error_final_m": float(e[-1]) if e.size else None,
            "fixes": self.fixes,
        }
