"""One laser scan, the one type for what a simulated sensor measured, what a recording holds
and what SLAM reads: :class:`LaserScan`, in ``sensor_msgs/LaserScan`` layout.

Angles are in the **sensor frame**, as a recording stores them: beam ``k`` points at
``angle_min_rad + k * angle_increment_rad`` from the sensor's own x axis. Where the sensor sits
on the robot is ``mount_pose`` (x m, y m, yaw rad in the robot frame, ``T_robot_sensor``;
``/tf_static`` in a recording), so a beam's direction in the robot frame starts at
:attr:`LaserScan.robot_angle_min_rad`. Ranges in m: ``inf`` no return, ``-inf`` closer than
``range_min_m`` (REP-117). A scan read from a log carries the robot's wheel-odometry pose at
its stamp in ``odom_pose``; a live simulated scan has none (the observation holds it).

A recording's whole topic is the batch form, :class:`agvsim.record.mcap_reader.ScanSeries`,
with the same field names. This module imports numpy only; every layer may use it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

__all__ = ["LaserScan"]


def _no_mount() -> NDArray[np.float64]:
    return np.zeros(3)


@dataclass(frozen=True)
class LaserScan:
    """One scan of one sensor (see the module docstring for frames and units)."""

    stamp_s: float  # when the scan was taken
    angle_min_rad: float  # first beam, sensor frame
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges: NDArray[np.float64]  # (B,) m; inf no return, -inf closer than range_min_m
    mount_pose: NDArray[np.float64] = field(default_factory=_no_mount)  # (3,) T_robot_sensor
    odom_pose: NDArray[np.float64] | None = None  # (3,) robot base, odometry frame (logs)
    # (B,) return strength (sensor_msgs/LaserScan.intensities): high on a retro-reflector,
    # 0 without a return; None when the sensor reports none (a world without reflectors)
    intensities: NDArray[np.float64] | None = None

    @property
    def angles_rad(self) -> NDArray[np.float64]:
        """(B,) beam directions in the sensor frame."""
        steps = np.arange(len(self.ranges))
        return np.asarray(self.angle_min_rad + self.angle_increment_rad * steps, dtype=np.float64)

    @property
    def robot_angle_min_rad(self) -> float:
        """The first beam's direction in the robot frame: ``angle_min_rad`` + the mount yaw."""
        return self.angle_min_rad + float(self.mount_pose[2])

    @property
    def hits(self) -> NDArray[np.bool_]:
        """(B,) bool: the thesis rangers' hit flag (a return within range)."""
        return np.isfinite(self.ranges) | (self.ranges == -np.inf)
