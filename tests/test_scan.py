"""One scan type (agvsim.scan.LaserScan): a controller's scan, a recording's scan and a SLAM
log's scan are the same thing, in the sensor frame with the sensor's mount pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.scan import LaserScan
from agvsim.slam.carmen import carmen_angles, read_carmen

ROOM = {
    "name": "scan room",
    "world": {"picture": "########\n#......#\n#......#\n#......#\n########"},
    "robots": [
        {
            "name": "r",
            "model": "differential",
            "pose": {"x_m": -1.0, "y_m": 0.0, "theta_deg": 30},
            "sensors": [
                {"type": "rangers"},
                {
                    "type": "lidar",
                    "beams": 36,
                    "range_max_m": 6.0,
                    "range_min_m": 0.1,
                    "mount_x_m": 0.2,
                    "mount_y_m": -0.05,
                    "mount_yaw_deg": 90,
                },
            ],  # fmt: skip
            "controller": {"type": "script", "steps": [{"duration_s": 5, "twist": [0.3, 0.2]}]},
        }
    ],
}


def test_hand_worked_scan() -> None:
    s = LaserScan(1.5, -0.5, 0.25, 0.1, 4.0, np.array([1.0, np.inf, -np.inf, 2.0, 0.5]))
    np.testing.assert_allclose(s.angles_rad, [-0.5, -0.25, 0.0, 0.25, 0.5], atol=0)
    assert s.robot_angle_min_rad == -0.5  # no mount: robot frame = sensor frame
    assert s.hits.tolist() == [True, False, True, True, True]
    assert s.odom_pose is None and s.mount_pose.tolist() == [0.0, 0.0, 0.0]
    turned = LaserScan(0.0, -0.5, 0.25, 0.1, 4.0, s.ranges, np.array([0.2, 0.0, math.pi / 2]))
    assert turned.robot_angle_min_rad == -0.5 + math.pi / 2


def test_observed_scan_is_in_the_sensor_frame_with_its_mount():
    from agvsim.scenario import build, parse_scenario

    sim = build(parse_scenario(ROOM, "scan room"))
    sim.step()
    lidar = sim.observation(0).scans["lidar"]
    assert lidar.angle_min_rad == pytest.approx(-math.pi)  # a full circle, from behind the sensor
    assert lidar.angle_increment_rad == pytest.approx(2 * math.pi / 36)
    np.testing.assert_allclose(lidar.mount_pose, [0.2, -0.05, math.pi / 2], atol=1e-15)
    assert lidar.robot_angle_min_rad == lidar.angle_min_rad + lidar.mount_pose[2]
    rangers = sim.observation(0).scans["rangers"]
    assert rangers.angle_min_rad == 0.0 and rangers.mount_pose.tolist() == [0.0, 0.0, 0.0]


def test_recorded_scan_reads_back_as_the_observed_one(tmp_path):
    pytest.importorskip("rosbags")
    from agvsim.record.mcap_reader import Recording
    from agvsim.record.mcap_writer import Recorder
    from agvsim.scenario import build, parse_scenario

    sim = build(parse_scenario(ROOM, "scan room"))
    rec = Recorder(tmp_path / "run.mcap", sim)
    seen: dict[float, LaserScan] = {}
    for _ in range(30):
        sim.step()
        rec.record()
        scan = sim.observation(0).scans["lidar"]
        seen[scan.stamp_s] = scan
    rec.close()
    series = Recording(tmp_path / "run.mcap").laser_scans("/r/lidar")
    assert len(series) == len(seen) > 2
    for k in range(len(series)):
        back = series.scan(k)
        mem = seen[min(seen, key=lambda t: abs(t - back.stamp_s))]
        assert back.stamp_s == pytest.approx(mem.stamp_s, abs=1e-9)
        assert back.angle_min_rad == pytest.approx(mem.angle_min_rad, abs=1e-6)  # float32
        assert back.angle_increment_rad == pytest.approx(mem.angle_increment_rad, abs=1e-6)
        assert (back.range_min_m, back.range_max_m) == pytest.approx((0.1, 6.0), abs=1e-6)
        np.testing.assert_allclose(back.mount_pose, mem.mount_pose, atol=1e-12)
        np.testing.assert_array_equal(back.ranges, mem.ranges.astype(np.float32))


@pytest.mark.parametrize("n", [91, 180, 181, 360, 361])
def test_carmen_scan_angles_are_the_flaser_convention_bit_for_bit(tmp_path, n):
    line = "FLASER {} {} 0.0 0.0 0.0 0.0 0.0 0.0 5.0 host 5.0\n".format(n, " ".join(["1.0"] * n))
    path = tmp_path / "one.clf"
    path.write_text(line)
    (scan,) = list(read_carmen(path, max_range_m=80.0))
    assert isinstance(scan, LaserScan)
    assert np.array_equal(scan.angles_rad.view(np.int64), carmen_angles(n).view(np.int64))
    assert scan.odom_pose is not None and scan.odom_pose.tolist() == [0.0, 0.0, 0.0]
