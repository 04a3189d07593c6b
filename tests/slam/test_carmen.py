"""CARMEN log reader: message layouts, beam geometry, no-return readings, clear line errors."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest

from agvsim.scan import LaserScan
from agvsim.slam.carmen import (
    CarmenFormatError,
    CarmenLog,
    OdomRecord,
    carmen_angles,
    read_carmen,
)
from agvsim.slam.datasets import datasets_dir


def flaser(ranges: list[float], laser: tuple, robot: tuple, stamp: float) -> str:
    vals = " ".join(f"{r:.3f}" for r in ranges)
    lx, ly, lth = laser
    rx, ry, rth = robot
    return f"FLASER {len(ranges)} {vals} {lx} {ly} {lth} {rx} {ry} {rth} {stamp} host 0.5\n"


def robotlaser(ranges: list[float], stamp: float) -> str:
    vals = " ".join(f"{r:.2f}" for r in ranges)
    # type start fov res max_range accuracy remission_mode n ranges n_rem rem.. laser robot tv rv
    return (
        f"ROBOTLASER1 0 -1.0 2.0 0.5 30.0 0.01 0 {len(ranges)} {vals} 2 7 8 "
        f"1.0 2.0 0.5 1.0 2.0 0.5 0.3 0.1 0.5 0.2 0.1 {stamp} host 0.7\n"
    )


LOG = (
    "# a comment\n"
    "PARAM robot_front_laser_max 81.9 nohost 0\n"
    "ODOM 1.0 2.0 0.1 0.3 0.05 0.0 100.0 host 0.1\n"
    + flaser([1.0] * 179 + [81.83], (1.1, 2.0, 0.1), (1.0, 2.0, 0.1), 100.5)
    + "RAWLASER1 0 0 0 0 0 0 0 0 0 101.0 host 0.2\n"
    + "\n"
    + robotlaser([4.0, 5.0, 30.0, 6.0, 7.0], 101.5)
)


def test_flaser_and_robotlaser_records(tmp_path: Path) -> None:
    path = tmp_path / "small.clf"
    path.write_text(LOG)
    recs = list(read_carmen(path, with_odom=True))
    assert [type(r) for r in recs] == [OdomRecord, LaserScan, LaserScan]
    odom, fl, rl = recs
    assert isinstance(odom, OdomRecord) and isinstance(fl, LaserScan)
    assert isinstance(rl, LaserScan)
    assert odom.stamp_s == 100.0 and np.allclose(odom.pose, [1.0, 2.0, 0.1])
    # FLASER: 180 beams from -90 deg, 1 deg apart; the largest reading of the log is no return
    assert fl.stamp_s == 100.5 and fl.range_max_m == pytest.approx(81.83)
    assert fl.angles_rad[0] == pytest.approx(-math.pi / 2)
    assert fl.angles_rad[-1] == pytest.approx(math.radians(89.0))
    assert np.isinf(fl.ranges[-1]) and np.all(fl.ranges[:-1] == 1.0)
    assert np.allclose(fl.odom_pose, [1.0, 2.0, 0.1])
    # laser 0.1 m ahead along the world x axis, robot heading 0.1 rad: T_robot_laser
    assert np.allclose(fl.mount_pose, [0.1 * math.cos(0.1), -0.1 * math.sin(0.1), 0.0])
    # ROBOTLASER1: own geometry, a reading at max_range is no return, remissions skipped
    assert np.allclose(rl.angles_rad, [-1.0, -0.5, 0.0, 0.5, 1.0])
    assert rl.range_max_m == 30.0 and np.isinf(rl.ranges[2])
    assert np.allclose(rl.odom_pose, [1.0, 2.0, 0.5]) and np.allclose(rl.mount_pose, 0.0)


def test_gzip_log_and_sized_iterable(tmp_path: Path) -> None:
    path = tmp_path / "small.clf.gz"
    with gzip.open(path, "wt") as f:
        f.write(LOG)
    log = CarmenLog(path)
    assert len(log) == 2 and log.flaser_max_range_m == pytest.approx(81.83)
    assert [r.stamp_s for r in log] == [100.5, 101.5]


def test_carmen_angle_convention() -> None:
    assert carmen_angles(181)[-1] == pytest.approx(math.pi / 2)
    assert np.diff(carmen_angles(361)) == pytest.approx(math.radians(0.5))
    assert carmen_angles(91)[-1] == pytest.approx(math.pi / 2)  # other counts spread over pi


@pytest.mark.parametrize(
    ("line", "problem"),
    [
        ("FLASER 3 1.0 abc 1.0 0 0 0 0 0 0 5.0 host 1\n", "'abc' is not a number"),
        ("FLASER 180 1.0 1.0 1.0\n", "line ends early"),
        ("ODOM 1.0 2.0\n", "line ends early"),
        ("FLASER 2.5 1.0 1.0 0 0 0 0 0 0 5.0 host 1\n", "not a count"),
        ("ROBOTLASER1 0 -1.0 2.0 0.5 30.0 0.01 0 2 1.0\n", "line ends early"),
    ],
)
def test_malformed_line_names_file_line_and_message(
    tmp_path: Path, line: str, problem: str
) -> None:
    path = tmp_path / "bad.clf"
    path.write_text("# header\nODOM 0 0 0 0 0 0 1.0 host 0\n" + line)
    with pytest.raises(CarmenFormatError) as info:
        list(read_carmen(path, max_range_m=80.0))
    err = info.value
    assert err.line_no == 3 and err.message == line.split()[0]
    assert str(err).startswith(f"{path}:3: {line.split()[0]}: ")
    assert problem in str(err)


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="CARMEN log not found"):
        CarmenLog(tmp_path / "nope.clf")


def test_intel_log_first_scans() -> None:
    root = datasets_dir()
    if root is None or not (root / "intel" / "intel.clf.gz").is_file():
        pytest.skip("datasets folder absent")
    log = CarmenLog(root / "intel" / "intel.clf.gz")
    assert len(log) == 13631 and log.flaser_max_range_m == pytest.approx(81.83)
    first = next(iter(log))
    assert first.ranges.shape == (180,) and first.stamp_s == pytest.approx(976052857.33753)
