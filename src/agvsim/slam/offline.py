"""Offline SLAM over a recorded log: :func:`run_offline`.

Reads a log through a :class:`ScanLog` (a sized iterable of :class:`~.carmen.ScanRecord`; the
:data:`READERS` registry maps file name endings to readers: CARMEN ``.clf``/``.clf.gz`` today,
our own recordings can be added next to it), runs :class:`~.graph_slam.GraphSlam` and writes

* ``trajectory.txt``: ``timestamp x y theta`` per scan, robot base pose (m, m, rad);
* ``map.pgm`` + ``map.yaml`` (ROS ``map_server``) and ``map.png``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from agvsim.slam.carmen import CarmenLog, ScanRecord
from agvsim.slam.graph_slam import GraphSlam, SlamConfig
from agvsim.slam.mapping import save_map_png, save_ros_map
from agvsim.slam.recording import McapScanLog

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

    def __len__(self) -> int: ...

    def __iter__(self) -> Iterator[ScanRecord]: ...


READERS: dict[str, Callable[[Path], ScanLog]] = {
    ".clf": CarmenLog,
    ".clf.gz": CarmenLog,
    ".mcap": McapScanLog,  # agvsim's own recordings (run.mcap), agvsim.slam.recording
}


def open_log(path: str | Path, robot: str | None = None, sensor: str | None = None) -> ScanLog:
    """The reader registered for the file's ending (:data:`READERS`). ``robot`` and ``sensor``
    pick the scans of a recording of several (agvsim's ``.mcap``); other logs hold one laser."""
    p = Path(path)
    name = p.name.lower()
    if name.endswith(".mcap"):
        return McapScanLog(p, robot, sensor)
    if robot is not None or sensor is not None:
        raise ValueError(
            f"{p}: --robot and --sensor pick the scans of an agvsim recording (.mcap); "
            "this log holds one laser"
        )
    for ending, reader in READERS.items():
        if name.endswith(ending):
            return reader(p)
    known = ", ".join(READERS)
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
    scans: Iterable[ScanRecord],
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
        if slam is None:
            slam = GraphSlam(rec.max_range_m, rec.laser_offset, config)
        slam.update(rec.timestamp_s, rec.ranges_m, rec.angles_rad, rec.odom_pose)
        n += 1
        if progress is not None and n % 100 == 0:
            progress(n)
    if slam is not None:
        slam.finish()
    return slam


def run_offline(
    log_path: str | Path,
    out_dir: str | Path,
    config: SlamConfig | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_scans: int | None = None,
    robot: str | None = None,
    sensor: str | None = None,
) -> OfflineResult:
    """Run SLAM over a log and write ``trajectory.txt``, ``map.pgm``, ``map.yaml``, ``map.png``
    into ``out_dir`` (created). ``progress(done, total)`` is called every 100 scans and at the
    end; ``max_scans`` stops early (a slice of the log); ``robot`` / ``sensor`` pick the lidar
    of an agvsim recording (default: the first robot with one)."""
    t0 = time.perf_counter()
    log = open_log(log_path, robot, sensor)
    total = len(log) if max_scans is None else min(len(log), max_scans)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    slam = map_scans(
        log, config, None if progress is None else lambda done: progress(done, total), total
    )
    if slam is None:
        raise ValueError(f"{log_path}: the log holds no laser scans")
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
