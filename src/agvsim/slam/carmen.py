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

* ``RAWLASER1 type start_angle fov angular_res max_range accuracy remission_mode n r_1..r_n
  n_rem rem_1..rem_m`` -- a laser with its geometry but no pose: read only when the log has
  neither FLASER nor ROBOTLASER1 lines (otherwise it repeats their scans), its odometry pose
  interpolated between the ``ODOM`` messages around it (held at the first or last one outside
  them) and its mount pose from the ``robot_frontlaser_offset``, ``..._side_offset`` and
  ``..._angular_offset`` parameters (0 when absent).
* ``PARAM name value`` -- parameters; ``laser_front_laser_fov`` and
  ``laser_front_laser_resolution`` (deg) give FLASER's geometry when they agree with its number
  of beams (the first beam at ``-fov / 2``).

A laser message with the same ``ipc_timestamp`` as the scan before it is the same scan logged
twice (FLASER next to ROBOTLASER1) and is skipped. ``RAWLASER2..4``, ``#`` comments, blank
lines and other messages are skipped. A scan
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


@dataclass
class _Survey:
    """What one pass over the log found: laser messages by kind, the largest FLASER reading
    (the sensor's no-return value) and the ``PARAM`` values that are numbers."""

    counts: dict[str, int]
    flaser_max_m: float
    params: dict[str, float]

    @property
    def raw_only(self) -> bool:
        """The log's scans are RAWLASER1 messages (no FLASER, no ROBOTLASER1)."""
        return not self.counts.get("FLASER") and not self.counts.get("ROBOTLASER1")

    @property
    def count(self) -> int:
        if self.raw_only:
            return self.counts.get("RAWLASER1", 0)
        return self.counts.get("FLASER", 0) + self.counts.get("ROBOTLASER1", 0)

    def flaser_geometry(self, n_beams: int) -> tuple[float, float]:
        """(first beam angle, step) in radians of an ``n_beams`` FLASER scan."""
        fov = self.params.get("laser_front_laser_fov")
        res = self.params.get("laser_front_laser_resolution")
        if fov and res and fov > 0 and res > 0:
            k = fov / res
            if abs(k - n_beams) < 1e-6 or abs(k + 1 - n_beams) < 1e-6:
                return -0.5 * math.radians(fov), math.radians(res)
        return -0.5 * math.pi, _flaser_step(n_beams)

    def raw_mount(self) -> NDArray[np.float64]:
        p = self.params
        return np.array(
            [
                p.get("robot_frontlaser_offset", 0.0),
                p.get("robot_frontlaser_side_offset", 0.0),
                p.get("robot_frontlaser_angular_offset", 0.0),
            ]
        )


_LASERS = ("FLASER", "ROBOTLASER1", "RAWLASER1")


def _survey(path: Path) -> _Survey:
    """One pass over the log (:class:`_Survey`); lines it cannot read are left for the main
    pass to report, and so is a truncated end."""
    out = _Survey({}, 0.0, {})
    try:
        for line in _survey_lines(path):
            kind = line.split(None, 1)[0] if line.strip() else ""
            if kind in _LASERS:
                out.counts[kind] = out.counts.get(kind, 0) + 1
            if kind == "FLASER":
                parts = line.split()
                try:
                    n = int(parts[1])
                    best = max(map(float, parts[2 : 2 + n]), default=0.0)
                    out.flaser_max_m = max(out.flaser_max_m, best)
                except (ValueError, IndexError):
                    continue
            elif kind == "PARAM":
                parts = line.split()
                if len(parts) >= 3 and _is_float(parts[2]) and math.isfinite(float(parts[2])):
                    out.params[parts[1]] = float(parts[2])
    except CarmenTruncated:
        pass
    return out


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


def _parse_flaser(f: _Line, max_range_m: float, survey: _Survey | None = None) -> LaserScan:
    n = f.count("num_readings")
    ranges = f.floats(n, f"{n} range readings")
    laser = f.floats(3, "laser pose x y theta")
    robot = f.floats(3, "odometry pose x y theta")
    stamp = f.timestamp()
    start, step = (
        survey.flaser_geometry(n) if survey is not None else (-0.5 * math.pi, _flaser_step(n))
    )
    return LaserScan(
        stamp,
        start,
        step,
        0.0,
        max_range_m,
        _no_return(ranges, max_range_m),
        _relative(robot, laser),
        robot,
    )


def _parse_laser_geometry(f: _Line) -> tuple[float, float, float, NDArray[np.float64]]:
    """start angle, step, max range and the ranges of a ROBOTLASER1 / RAWLASER1 message."""
    _, start, fov, res, max_range = f.floats(5, "laser_type start_angle fov angular_res max_range")
    f.floats(2, "accuracy remission_mode")
    if max_range <= 0 or res == 0:
        raise f.fail(f"max_range {max_range} and angular_res {res} must be positive")
    n = f.count("num_readings")
    ranges = f.floats(n, f"{n} range readings")
    f.floats(f.count("num_remissions"), "remissions")
    return float(start), float(res), float(max_range), ranges


def _parse_rawlaser(f: _Line, odom: NDArray[np.float64], mount: NDArray[np.float64]) -> LaserScan:
    start, res, max_range, ranges = _parse_laser_geometry(f)
    stamp = f.timestamp()
    return LaserScan(
        stamp, start, res, 0.0, max_range, _no_return(ranges, max_range), mount.copy(), odom
    )


def _interpolate(a: OdomRecord, b: OdomRecord, t: float) -> NDArray[np.float64]:
    """The odometry pose at ``t`` between ``a`` and ``b`` (linear, heading the short way);
    held at the nearer one outside them."""
    span = b.stamp_s - a.stamp_s
    w = 0.0 if span <= 0 else min(max((t - a.stamp_s) / span, 0.0), 1.0)
    out = a.pose + w * (b.pose - a.pose)
    out[2] = wrap_scalar(a.pose[2] + w * wrap_scalar(b.pose[2] - a.pose[2]))
    return out


def _parse_robotlaser(f: _Line) -> LaserScan:
    start, res, max_range, ranges = _parse_laser_geometry(f)
    laser = f.floats(3, "laser pose x y theta")
    robot = f.floats(3, "robot pose x y theta")
    stamp = f.timestamp()
    return LaserScan(
        stamp,
        start,
        res,
        0.0,
        max_range,
        _no_return(ranges, max_range),
        _relative(robot, laser),
        robot,
    )


def read_carmen(
    path: str | Path,
    max_range_m: float | None = None,
    with_odom: bool = False,
    survey: _Survey | None = None,
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
    info = survey if survey is not None else _survey(p)
    flaser_max = max_range_m if max_range_m is not None else info.flaser_max_m
    mount = info.raw_mount()
    last_stamp = math.nan
    odoms: list[OdomRecord] = []  # the last ODOM (and the one before) for RAWLASER1
    waiting: list[_Line] = []  # RAWLASER1 lines after the last ODOM
    for line_no, line in _lines(p):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        kind = parts[0]
        f = _Line(parts, str(p), line_no)
        scan: LaserScan | None = None
        if kind == "FLASER" and not info.raw_only:
            scan = _parse_flaser(f, flaser_max, info)
        elif kind == "ROBOTLASER1":
            scan = _parse_robotlaser(f)
        elif kind == "RAWLASER1" and info.raw_only:
            waiting.append(f)  # parsed when the ODOM after it comes (errors name its line)
            continue
        elif kind == "ODOM":
            odom = _parse_odom(f)
            odoms = [*odoms[-1:], odom]
            for g in waiting:  # the raw scans before this ODOM, interpolated
                t = g.timestamp()
                g.pos = 1
                raw = _parse_rawlaser(g, _interpolate(odoms[0], odom, t), mount)
                if raw.stamp_s != last_stamp:
                    last_stamp = raw.stamp_s
                    yield raw
            waiting = []
            if with_odom:
                yield odom
        if scan is not None and scan.stamp_s != last_stamp:
            last_stamp = scan.stamp_s
            yield scan
    for g in waiting:  # after the last ODOM: held at it
        pose = odoms[-1].pose.copy() if odoms else np.zeros(3)
        raw = _parse_rawlaser(g, pose, mount)
        if raw.stamp_s != last_stamp:
            last_stamp = raw.stamp_s
            yield raw


class CarmenLog:
    """A CARMEN log as a sized iterable of :class:`~agvsim.scan.LaserScan` (one survey pass at
    open: the number of scans and the FLASER no-return value). A ``.gz`` log cut off before its
    end is read up to the cut; ``truncated_after_line`` then says where (None otherwise)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"CARMEN log not found: {self.path}")
        self._survey = _survey(self.path)
        self._count, self.flaser_max_range_m = self._survey.count, self._survey.flaser_max_m
        self.truncated_after_line: int | None = None

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[LaserScan]:
        try:
            for rec in read_carmen(self.path, self.flaser_max_range_m or None, survey=self._survey):
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
