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


def robotlaser_line(ranges: np.ndarray, start: float, res: float, pose: tuple, t: float) -> str:
    vals = " ".join(f"{r:.3f}" for r in ranges)
    x, y, th = pose
    return (
        f"ROBOTLASER1 0 {start} {res * (len(ranges) - 1)} {res} 30.0 0.01 0 {len(ranges)} "
        f"{vals} 0 {x + 0.2 * math.cos(th)} {y + 0.2 * math.sin(th)} {th} {x} {y} {th} "
        f"0.3 0.1 0.5 0.2 0.1 {t} host {t}\n"
    )


@pytest.mark.parametrize(("n", "res_deg"), [(361, 0.5), (721, 0.25), (361, 0.25)])
def test_robotlaser_geometry_and_a_log_with_only_odom_and_robotlaser(
    tmp_path: Path, n: int, res_deg: float
) -> None:
    """361 beams at 0.5 deg (180 deg), 721 at 0.25 deg, 361 at 0.25 deg (90 deg): each scan
    carries its own geometry; ODOM lines between them are not scans."""
    res = math.radians(res_deg)
    start = -0.5 * res * (n - 1)
    ranges = np.linspace(1.0, 5.0, n)
    ranges[7] = 30.0  # at max_range: no return
    text = "PARAM robot_front_laser_max 30.0 nohost 0\n"
    for k in range(3):
        text += f"ODOM {0.1 * k} 0 0 0.3 0 0 {10.0 + k} host 0\n"
        text += robotlaser_line(ranges, start, res, (0.1 * k, 0.0, 0.0), 10.5 + k)
    path = tmp_path / "rl.clf"
    path.write_text(text)
    log = CarmenLog(path)
    got = list(log)
    assert len(log) == 3 and len(got) == 3
    for k, s in enumerate(got):
        assert s.ranges.shape == (n,) and np.isinf(s.ranges[7])
        assert s.angles_rad[0] == pytest.approx(start)
        assert s.angles_rad[-1] == pytest.approx(-start)
        assert s.angle_increment_rad == pytest.approx(res)
        np.testing.assert_allclose(s.mount_pose, [0.2, 0.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(s.odom_pose, [0.1 * k, 0.0, 0.0])


def test_rawlaser_only_log_takes_odometry_from_odom_lines(tmp_path: Path) -> None:
    """No FLASER, no ROBOTLASER1: RAWLASER1 scans, their odometry interpolated between the
    ODOM lines around them (heading the short way round +-pi), the mount from PARAM."""
    raw = "RAWLASER1 0 -1.5708 3.1416 0.5 20.0 0.01 0 3 1.0 2.0 20.0 0 {t} host {t}\n"
    text = (
        "PARAM robot_frontlaser_offset 0.25 nohost 0\n"
        + raw.format(t=0.5)  # before the first ODOM: held at it
        + "ODOM 1.0 0.0 3.0 0 0 0 1.0 host 1.0\n"
        + raw.format(t=1.25)
        + "ODOM 2.0 4.0 -3.0 0 0 0 2.0 host 2.0\n"
        + raw.format(t=2.5)  # after the last ODOM: held at it
    )
    path = tmp_path / "raw.clf"
    path.write_text(text)
    log = CarmenLog(path)
    got = list(log)
    assert len(log) == 3 and [s.stamp_s for s in got] == [0.5, 1.25, 2.5]
    np.testing.assert_allclose(got[0].odom_pose, [1.0, 0.0, 3.0])
    # a quarter of the way from (1, 0, 3) to (2, 4, -3): the heading turns the short way,
    # by 2 pi - 6 (0.283 rad) through pi, not by -6 rad
    th = 3.0 + 0.25 * (2 * math.pi - 6.0)
    np.testing.assert_allclose(got[1].odom_pose, [1.25, 1.0, th], atol=1e-12)
    np.testing.assert_allclose(got[2].odom_pose, [2.0, 4.0, -3.0])
    np.testing.assert_allclose(got[1].mount_pose, [0.25, 0.0, 0.0])
    assert np.isinf(got[1].ranges[2]) and got[1].ranges[1] == 2.0
    assert got[1].angle_increment_rad == 0.5


def test_same_scan_logged_twice_is_read_once_and_param_geometry(tmp_path: Path) -> None:
    """FLASER next to ROBOTLASER1 with the same ipc_timestamp is one scan (the first kept);
    RAWLASER1 is not read when the log has FLASER lines; PARAM fov and resolution give a
    361-beam FLASER's geometry (90 deg at 0.25 deg, not the default 180 deg at 0.5)."""
    ranges = [1.0] * 361
    text = (
        "PARAM laser_front_laser_fov 90 nohost 0\n"
        "PARAM laser_front_laser_resolution 0.25 nohost 0\n"
        + flaser(ranges, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 5.0)
        + robotlaser_line(np.ones(361), -0.7854, math.radians(0.25), (0.0, 0.0, 0.0), 5.0)
        + "RAWLASER1 0 -1.5708 3.1416 0.5 20.0 0.01 0 3 1.0 2.0 20.0 0 5.5 host 5.5\n"
        + flaser(ranges, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 6.0)
    )
    path = tmp_path / "twice.clf"
    path.write_text(text)
    got = list(CarmenLog(path))
    assert [s.stamp_s for s in got] == [5.0, 6.0]
    assert got[0].angles_rad[0] == pytest.approx(-math.pi / 4)
    assert got[0].angle_increment_rad == pytest.approx(math.radians(0.25))
