"""Read CARMEN laser logs (``.clf``, ``.clf.gz``), streaming one line at a time.

One message a line, fields separated by blanks; every message ends with
``ipc_timestamp ipc_hostname logger_timestamp`` (``ipc_timestamp`` is the scan time the
Kümmerle relations use). Understood messages:

* ``ODOM x y theta tv rv accel`` -- wheel odometry, robot base pose in the odometry frame.
* ``FLASER n r_1..r_n x y theta odom_x odom_y odom_theta`` -- front laser: the laser pose and the
  robot pose, both in the odometry frame. No angles in the message: CARMEN's convention is the
  first beam at -90 deg (counter-clockwise positive), 1 deg apart for 180/181 beams and 0.5 deg
  for 360/361 beams (``fov = pi`` otherwise spread evenly). A reading at or above the sensor's
  maximum is "no return"; the maximum is not in the message, so it is the largest reading of the
  log (a first pass over the file), unless given.
* ``ROBOTLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n
  n_rem rem_1..rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv ...`` -- carries
  its own geometry: beam ``k`` at ``start_angle + k * angular_res``.

``PARAM``, ``RAWLASER1..4``, ``#`` comments, blank lines and other messages are skipped. A scan
is an :class:`agvsim.scan.LaserScan` in the laser frame: its mount pose is
``T_robot_laser = T_odom_robot^-1 * T_odom_laser``, its ``odom_pose`` the robot's pose. A
malformed line raises :class:`CarmenFormatError` naming the file, line number, message and
problem.
"""

from __future__ import annotations

import gzip
import math
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import numpy as np
from numpy.typing import NDArray

from agvsim.angles import wrap_scalar
from agvsim.scan import LaserScan

__all__ = [
    "CarmenFormatError",
    "CarmenLog",
    "CarmenTruncated",
    "OdomRecord",
    "carmen_angles",
    "read_carmen",
]

_TRAILER = 3  # ipc_timestamp ipc_hostname logger_timestamp


class CarmenFormatError(ValueError):
    """A line of a CARMEN log that cannot be read: ``file:line: MESSAGE: problem``."""

    def __init__(self, path: str, line_no: int, message: str, problem: str) -> None:
        self.path, self.line_no, self.message, self.problem = path, line_no, message, problem
        super().__init__(f"{path}:{line_no}: {message}: {problem}")


@dataclass(frozen=True)
class OdomRecord:
    """An ``ODOM`` message: robot base pose in the odometry frame and its velocities."""

    stamp_s: float  # ipc_timestamp
    pose: NDArray[np.float64]  # (3,)
    tv_mps: float
    rv_radps: float


def _flaser_step(n_beams: int) -> float:
    if n_beams in (180, 181):
        return math.radians(1.0)
    if n_beams in (360, 361):
        return math.radians(0.5)
    return math.pi / max(n_beams - 1, 1)


def carmen_angles(n_beams: int) -> NDArray[np.float64]:
    """FLASER beam angles (rad): from -pi/2, 1 deg apart for 180/181 beams, 0.5 deg for 360/361,
    otherwise ``n`` beams spread evenly over pi."""
    return -0.5 * math.pi + _flaser_step(n_beams) * np.arange(n_beams, dtype=np.float64)


def _open(path: Path) -> IO[str]:
    if path.suffix == ".gz":
        return gzip.open(path, "rt", encoding="ascii", errors="replace")
    return open(path, encoding="ascii", errors="replace")


class CarmenTruncated(Exception):
    """The compressed log ends before its end-of-stream marker (a copy cut short, a recorder
    killed): the lines before the cut were read. Raised by :func:`_lines` only."""

    def __init__(self, path: str, line_no: int) -> None:
        self.path, self.line_no = path, line_no
        super().__init__(f"{path}: the log is cut off after line {line_no}")


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    """``(line number, line)`` of a log; a damaged gzip stream raises
    :class:`CarmenFormatError` naming the file and the line it broke in, a truncated one
    :class:`CarmenTruncated` after the last complete line."""
    line_no = 0
    try:
        with _open(path) as fh:
            for line in fh:  # a line cut by the end of the data is never returned
                line_no += 1
                yield line_no, line
    except EOFError:
        raise CarmenTruncated(str(path), line_no) from None
    except (gzip.BadGzipFile, zlib.error, OSError) as exc:
        where = "at the start" if line_no == 0 else f"after line {line_no}"
        raise CarmenFormatError(
            str(path), line_no + 1, "gzip", f"corrupt compressed data {where} ({exc})"
        ) from None


def _relative(robot: NDArray[np.float64], laser: NDArray[np.float64]) -> NDArray[np.float64]:
    """``robot^-1 * laser`` for single poses."""
    c, s = math.cos(robot[2]), math.sin(robot[2])
    dx, dy = laser[0] - robot[0], laser[1] - robot[1]
    dth = wrap_scalar(laser[2] - robot[2])
    return np.array([c * dx + s * dy, -s * dx + c * dy, dth])


class _Line:
    """The blank-separated fields of one message, read left to right with clear errors."""

    def __init__(self, parts: list[str], path: str, line_no: int) -> None:
        self.parts, self.pos, self.path, self.line_no = parts, 1, path, line_no

    def fail(self, problem: str) -> CarmenFormatError:
        return CarmenFormatError(self.path, self.line_no, self.parts[0], problem)

    def floats(self, count: int, what: str) -> NDArray[np.float64]:
        chunk = self.parts[self.pos : self.pos + count]
        if len(chunk) < count:
            raise self.fail(f"line ends early: expected {count} value(s) for {what}")
        try:
            values = np.array(chunk, dtype=np.float64)
        except ValueError:
            bad = next(v for v in chunk if not _is_float(v))
            raise self.fail(f"{what}: {bad!r} is not a number") from None
        if not np.all(np.isfinite(values)):
            raise self.fail(f"{what}: values must be finite")
        self.pos += count
        return values

    def count(self, what: str) -> int:
        value = self.floats(1, what)[0]
        if value != int(value) or value < 0:
            raise self.fail(f"{what}: {self.parts[self.pos - 1]!r} is not a count")
        return int(value)

    def timestamp(self) -> float:
        if len(self.parts) - self.pos < _TRAILER:
            raise self.fail("line ends early: expected ipc_timestamp ipc_hostname logger_timestamp")
        self.pos = len(self.parts) - _TRAILER
        return float(self.floats(1, "ipc_timestamp")[0])


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _survey(path: Path) -> tuple[int, float]:
    """Number of laser messages and the largest FLASER reading of the log (the sensor's
    no-return value); lines it cannot read are left for the main pass to report, and so is
    a truncated end."""
    count, best = 0, 0.0
    try:
        for line in _survey_lines(path):
            if line.startswith("FLASER"):
                count += 1
                parts = line.split()
                try:
                    n = int(parts[1])
                    best = max(best, max(map(float, parts[2 : 2 + n]), default=0.0))
                except (ValueError, IndexError):
                    continue
            elif line.startswith("ROBOTLASER1"):
                count += 1
    except CarmenTruncated:
        pass
    return count, best


def _survey_lines(path: Path) -> Iterable[str]:
    for _, line in _lines(path):
        yield line


def _no_return(ranges: NDArray[np.float64], max_range_m: float) -> NDArray[np.float64]:
    out = ranges.copy()
    out[(ranges >= max_range_m) | (ranges <= 0.0)] = np.inf
    return out


def _parse_odom(f: _Line) -> OdomRecord:
    x, y, th, tv, rv = f.floats(5, "x y theta tv rv")
    return OdomRecord(f.timestamp(), np.array([x, y, th]), float(tv), float(rv))


def _parse_flaser(f: _Line, max_range_m: float) -> LaserScan:
    n = f.count("num_readings")
    ranges = f.floats(n, f"{n} range readings")
    laser = f.floats(3, "laser pose x y theta")
    robot = f.floats(3, "odometry pose x y theta")
    stamp = f.timestamp()
    return LaserScan(
        stamp,
        -0.5 * math.pi,
        _flaser_step(n),
        0.0,
        max_range_m,
        _no_return(ranges, max_range_m),
        _relative(robot, laser),
        robot,
    )


def _parse_robotlaser(f: _Line) -> LaserScan:
    _, start, fov, res, max_range = f.floats(5, "laser_type start_angle fov angular_res max_range")
    f.floats(2, "accuracy remission_mode")
    if max_range <= 0 or res == 0:
        raise f.fail(f"max_range {max_range} and angular_res {res} must be positive")
    n = f.count("num_readings")
    ranges = f.floats(n, f"{n} range readings")
    f.floats(f.count("num_remissions"), "remissions")
    laser = f.floats(3, "laser pose x y theta")
    robot = f.floats(3, "robot pose x y theta")
    stamp = f.timestamp()
    return LaserScan(
        stamp,
        float(start),
        float(res),
        0.0,
        float(max_range),
        _no_return(ranges, max_range),
        _relative(robot, laser),
        robot,
    )


def read_carmen(
    path: str | Path, max_range_m: float | None = None, with_odom: bool = False
) -> Iterator[LaserScan | OdomRecord]:
    """Yield the scans (and, with ``with_odom``, the ``ODOM`` messages) of a CARMEN log in order.

    ``max_range_m`` is the FLASER no-return value; by default the largest FLASER reading in the
    log. Raises :class:`CarmenFormatError` on a malformed line or damaged compressed data,
    :class:`CarmenTruncated` after the last complete line of a cut-off ``.gz`` log, and
    :class:`FileNotFoundError` when the file is missing.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"CARMEN log not found: {p}")
    flaser_max = max_range_m
    for line_no, line in _lines(p):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        kind = parts[0]
        f = _Line(parts, str(p), line_no)
        if kind == "FLASER":
            if flaser_max is None:
                flaser_max = _survey(p)[1]
            yield _parse_flaser(f, flaser_max)
        elif kind == "ROBOTLASER1":
            yield _parse_robotlaser(f)
        elif kind == "ODOM":
            odom = _parse_odom(f)
            if with_odom:
                yield odom


class CarmenLog:
    """A CARMEN log as a sized iterable of :class:`~agvsim.scan.LaserScan` (one survey pass at
    open: the number of scans and the FLASER no-return value). A ``.gz`` log cut off before its
    end is read up to the cut; ``truncated_after_line`` then says where (None otherwise)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"CARMEN log not found: {self.path}")
        self._count, self.flaser_max_range_m = _survey(self.path)
        self.truncated_after_line: int | None = None

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[LaserScan]:
        try:
            for rec in read_carmen(self.path, self.flaser_max_range_m or None):
                if isinstance(rec, LaserScan):
                    yield rec
        except CarmenTruncated as cut:
            self.truncated_after_line = cut.line_no

    def warnings(self) -> list[str]:
        """What the user should know about the log once it was read."""
        if self.truncated_after_line is None:
            return []
        return [
            f"{self.path}: the log is cut off after line {self.truncated_after_line} "
            "(compressed data ends early); mapped the scans up to the cut"
        ]
