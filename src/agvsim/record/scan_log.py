"""Our own recordings as SLAM logs: :class:`McapScanLog` reads ``run.mcap`` (``agvsim run``),
and :func:`open_scan_log` opens any log the offline SLAM reads, by its file ending.

Each scan of the chosen robot's lidar (``/<robot>/<sensor>``, ``sensor_msgs/LaserScan``)
becomes an :class:`agvsim.scan.LaserScan` as recorded: its header stamp, ranges (``inf`` kept for
no return), angles in the laser frame, the laser's mount pose (``/tf_static``:
``<robot>/base_link`` -> ``<robot>/<sensor>``) and, in ``odom_pose``, the wheel-odometry pose
of the robot at the scan's time (``/<robot>/odom``, interpolated between its two neighbours).
By default the first robot (scenario order) with a lidar is used.

Reading goes through :mod:`agvsim.record.mcap_reader` (rosbags); the simulator is never
imported. This module sits in the record layer, above :mod:`agvsim.slam`: the SLAM package
imports nothing of ``agvsim.record``, so the pose-graph optimiser loads no MCAP reader.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from agvsim.angles import wrap_angle
from agvsim.record.mcap_reader import Recording, RecordingError
from agvsim.record.ros2msg import topic_name
from agvsim.scan import LaserScan
from agvsim.slam.offline import READERS as SLAM_READERS
from agvsim.slam.offline import ScanLog, open_log

__all__ = ["READERS", "McapScanLog", "interpolate_poses", "open_scan_log"]


def interpolate_poses(t_query: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Planar poses (T, 3) sampled at increasing times ``t`` (T,), read at ``t_query``:
    linear in x, y and in the (unwrapped) heading, clamped to the ends, heading wrapped back
    to (-pi, pi]."""
    t = np.asarray(t, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    th = np.unwrap(poses[:, 2])
    x = np.interp(t_query, t, poses[:, 0])
    y = np.interp(t_query, t, poses[:, 1])
    a = np.interp(t_query, t, th)
    a = wrap_angle(a)
    return np.column_stack([x, y, a])


class McapScanLog:
    """A recording's lidar scans with odometry, as the offline SLAM reads them.

    ``robot`` and ``sensor`` pick the scans (names as in the scenario); by default the first
    robot with a lidar and its first lidar."""

    def __init__(self, path: str | Path, robot: str | None = None, sensor: str | None = None):
        self.path = Path(path)
        rec = Recording(self.path)
        choices = rec.lidar_topics()
        if not choices:
            raise RecordingError(f"{self.path}: the recording holds no laser scans")
        pick = [
            c
            for c in choices
            if (robot is None or topic_name(robot) == topic_name(c[0]))
            and (sensor is None or topic_name(sensor) == c[1])
        ]
        if not pick:
            have = ", ".join(f"{r}/{s}" for r, s, _ in choices)
            raise RecordingError(
                f"{self.path}: no scans for robot {robot!r} sensor {sensor!r}; have {have}"
            )
        self.robot, self.sensor, self.topic = pick[0]
        rt = topic_name(self.robot)
        self.scans = rec.laser_scans(self.topic)
        odom_topic = f"/{rt}/odom"
        t_odom, odom, _ = rec.odometry(odom_topic)
        if len(t_odom) == 0:
            raise RecordingError(f"{self.path}: {odom_topic} holds no odometry")
        self.odom_poses = interpolate_poses(self.scans.stamp_s, t_odom, odom)

    def __len__(self) -> int:
        return len(self.scans)

    def __iter__(self) -> Iterator[LaserScan]:
        for k in range(len(self.scans)):
            scan = self.scans.scan(k)
            # -inf (closer than range_min) and 0 (inside a wall) carry no usable distance
            scan.ranges[~(scan.ranges > 0)] = np.inf
            yield replace(scan, odom_pose=self.odom_poses[k].copy())


READERS: dict[str, Callable[[Path], ScanLog]] = {
    **SLAM_READERS,  # CARMEN .clf / .clf.gz
    ".mcap": McapScanLog,  # agvsim's own recordings (run.mcap)
}


def open_scan_log(path: str | Path, robot: str | None = None, sensor: str | None = None) -> ScanLog:
    """The reader registered for the file's ending (:data:`READERS`). ``robot`` and ``sensor``
    pick the scans of a recording of several (agvsim's ``.mcap``); other logs hold one laser."""
    p = Path(path)
    if p.name.lower().endswith(".mcap"):
        return McapScanLog(p, robot, sensor)
    if robot is not None or sensor is not None:
        raise ValueError(
            f"{p}: --robot and --sensor pick the scans of an agvsim recording (.mcap); "
            "this log holds one laser"
        )
    return open_log(p, READERS)
