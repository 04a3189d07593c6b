"""Offline SLAM over a recorded log: :func:`run_offline`.

Reads a log through a :class:`ScanLog` (a sized iterable of :class:`~agvsim.scan.LaserScan`
with their ``odom_pose``; the
:data:`READERS` registry maps file name endings to readers: CARMEN ``.clf``/``.clf.gz``; agvsim's
own recordings are read by :mod:`agvsim.record.scan_log`, in the layer above, whose
``open_scan_log`` also opens these), runs :class:`~.graph_slam.GraphSlam` and writes

* ``trajectory.txt``: ``timestamp x y theta`` per scan, robot base pose (m, m, rad);
* ``map.pgm`` + ``map.yaml`` (ROS ``map_server``) and ``map.png``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from agvsim.scan import LaserScan
from agvsim.slam.carmen import CarmenFormatError, CarmenLog
from agvsim.slam.graph_slam import GraphSlam, SlamConfig
from agvsim.slam.mapping import save_map_png, save_ros_map

__all__ = [
    "READERS",
    "OfflineResult",
    "ScanLog",
    "map_scans",
    "open_log",
    "run_offline",
    "write_trajectory",
]


class ScanLog(Protocol):
    """What :func:`run_offline` reads: the number of scans and the scans in time order."""

    path: Path  # the file, for messages

    def __len__(self) -> int: ...

    def __iter__(self) -> Iterator[LaserScan]: ...


READERS: dict[str, Callable[[Path], ScanLog]] = {
    ".clf": CarmenLog,
    ".clf.gz": CarmenLog,
}


def open_log(
    path: str | Path, readers: Mapping[str, Callable[[Path], ScanLog]] = READERS
) -> ScanLog:
    """The reader ``readers`` (default :data:`READERS`) registers for the file's ending."""
    p = Path(path)
    name = p.name.lower()
    for ending, reader in readers.items():
        if name.endswith(ending):
            return reader(p)
    known = ", ".join(readers)
    raise ValueError(f"{p}: unknown log format; expected a file ending in one of {known}")


@dataclass(frozen=True)
class OfflineResult:
    """What a run produced and how long it took."""

    trajectory_path: Path
    map_yaml_path: Path
    map_png_path: Path
    n_scans: int
    n_keyframes: int
    n_submaps: int
    n_loop_closures: int
    log_duration_s: float  # last minus first scan time stamp
    processing_s: float  # SLAM and map writing, log reading included
    warnings: tuple[str, ...] = ()  # e.g. a log cut off early (mapped up to the cut)

    @property
    def realtime_factor(self) -> float:
        """Log duration over processing time."""
        return self.log_duration_s / max(self.processing_s, 1e-9)


def write_trajectory(path: Path, timestamps: np.ndarray, poses: np.ndarray) -> Path:
    """``timestamp x y theta`` a line (TUM-like 2-D)."""
    data = np.column_stack([timestamps, poses])
    np.savetxt(path, data, fmt=["%.6f", "%.6f", "%.6f", "%.6f"], delimiter=" ")
    return path


def map_scans(
    scans: Iterable[LaserScan],
    config: SlamConfig | None = None,
    progress: Callable[[int], None] | None = None,
    max_scans: int | None = None,
) -> GraphSlam | None:
    """Run :class:`GraphSlam` over scans in time order (finished: the last optimisation done);
    None when there are none. ``progress(done)`` is called every 100 scans."""
    slam: GraphSlam | None = None
    n = 0
    for rec in scans:
        if max_scans is not None and n >= max_scans:
            break
        if rec.odom_pose is None:
            raise ValueError(f"the scan at {rec.stamp_s} s has no odometry pose (odom_pose)")
        if slam is None:
            mount = np.asarray(rec.mount_pose, np.float64)
            reach = (config or SlamConfig()).usable_range_m
            if not np.all(np.isfinite(mount)) or math.hypot(mount[0], mount[1]) > reach:
                raise ValueError(
                    f"the scanner's mount pose {mount.tolist()} is not on the robot: its "
                    f"position must be finite and within {reach} m of the robot's"
                )
            slam = GraphSlam(rec.range_max_m, rec.mount_pose, config)
        slam.update(rec.stamp_s, rec.ranges, rec.angles_rad, rec.odom_pose)
        n += 1
        if progress is not None and n % 100 == 0:
            progress(n)
    if slam is not None:
        slam.finish()
    return slam


def run_offline(
    log_path: str | Path | ScanLog,
    out_dir: str | Path,
    config: SlamConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_scans: int | None = None,
) -> OfflineResult:
    """Run SLAM over a log and write ``trajectory.txt``, ``map.pgm``, ``map.yaml``, ``map.png``
    into ``out_dir`` (created). ``log_path`` is a file :func:`open_log` reads, or a log already
    open (e.g. ``agvsim.record.scan_log.open_scan_log(path, robot, sensor)`` for a recording).
    ``progress(done, total)`` is called every 100 scans and at the end; ``max_scans`` stops
    early (a slice of the log)."""
    t0 = time.perf_counter()
    log = open_log(log_path) if isinstance(log_path, str | Path) else log_path
    source = log_path if isinstance(log_path, str | Path) else log.path
    total = len(log) if max_scans is None else min(len(log), max_scans)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    try:
        slam = map_scans(
            log, config, None if progress is None else lambda done: progress(done, total), total
        )
    except CarmenFormatError:
        raise  # names the file and the line
    except ValueError as exc:
        if str(source) in str(exc):
            raise
        raise ValueError(f"{source}: {exc}") from exc
    if slam is None:
        raise ValueError(f"{source}: the log holds no laser scans")
    n = len(slam.scan_times)
    stamps, poses = slam.trajectory()
    traj = write_trajectory(out / "trajectory.txt", stamps, poses)
    grid = slam.occupancy_map()
    yaml_path = save_ros_map(grid, out / "map.yaml")
    png = save_map_png(grid, out / "map.png")
    if progress is not None:
        progress(n, total)
    return OfflineResult(
        traj,
        yaml_path,
        png,
        n,
        len(slam.keyframes),
        len(slam.submaps),
        len(slam.loop_edges),
        float(stamps[-1] - stamps[0]) if n else 0.0,
        time.perf_counter() - t0,
        tuple(log.warnings()) if isinstance(log, CarmenLog) else (),
    )
