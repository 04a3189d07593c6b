"""The offline SLAM reads our recordings: ``agvsim slam run.mcap`` (McapScanLog)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("rosbags")

from agvsim.record.mcap_reader import RecordingError  # noqa: E402
from agvsim.record.mcap_writer import Recorder, scenario_yaml  # noqa: E402
from agvsim.record.scan_log import McapScanLog, interpolate_poses, open_scan_log  # noqa: E402
from agvsim.scenario import build, parse_scenario  # noqa: E402
from agvsim.slam.offline import run_offline  # noqa: E402

pytestmark = pytest.mark.slow  # SLAM on recordings

SCENARIO = {
    "name": "slam room",
    "world": {"picture": "##########\n#........#\n#..##....#\n#........#\n##########"},
    "robots": [
        {
            "name": "scout",
            "model": "differential",
            "pose": {"x_m": -2.5, "y_m": -0.5},
            "sensors": [{"type": "rangers"}],
            "controller": {"type": "idle"},
        },
        {
            "name": "mapper",
            "model": "differential",
            "pose": {"x_m": -3.0, "y_m": 0.5},
            "odometry": {"wheel_noise_rel": 0.05},
            "sensors": [
                {"type": "rangers"},
                {
                    "type": "lidar",
                    "beams": 120,
                    "range_max_m": 8.0,
                    "mount_x_m": 0.15,
                    "mount_yaw_deg": 10,
                    "range_min_m": 0.2,
                },
            ],  # fmt: skip
            "controller": {"type": "script", "steps": [{"duration_s": 10, "twist": [0.6, 0.3]}]},
        },
    ],
}


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    sim = build(parse_scenario(SCENARIO, "slam room"))
    path = tmp_path_factory.mktemp("slam") / "run.mcap"
    rec = Recorder(path, sim, scenario_yaml(parse_scenario(SCENARIO, "s"), 0))
    odom = {0.0: sim.state.odom_poses[1].copy()}
    scans = {0.0: sim.state.scans[2, :120].copy()}
    for _ in range(150):  # 3 s
        sim.step()
        rec.record()
        odom[round(sim.state.t_s, 6)] = sim.state.odom_poses[1].copy()
        scans[round(float(sim.state.scan_stamp[2]), 6)] = sim.state.scans[2, :120].copy()
    rec.close()
    return path, odom, scans


def test_scan_log_yields_the_lidar_with_odometry_and_mount(recording):
    path, odom, scans = recording
    log = open_scan_log(path)  # ".mcap" is registered
    assert isinstance(log, McapScanLog)
    assert (log.robot, log.sensor) == ("mapper", "lidar")  # the first robot WITH a lidar
    records = list(log)
    assert len(log) == len(records) == 31  # 10 Hz over 3 s, t = 0 included
    for rec in records:
        t = round(rec.stamp_s, 6)
        np.testing.assert_allclose(rec.odom_pose, odom[t], atol=1e-12)
        expect = scans[t].astype(np.float32).astype(np.float64)
        expect[~(expect > 0)] = np.inf  # -inf (closer than range_min) carries no distance
        np.testing.assert_array_equal(rec.ranges, expect)
        assert rec.range_max_m == 8.0
    np.testing.assert_allclose(records[0].mount_pose, [0.15, 0.0, np.deg2rad(10)], atol=1e-12)
    np.testing.assert_allclose(
        records[0].angles_rad, -np.pi + np.arange(120) * (2 * np.pi / 120), atol=1e-6
    )


def test_scan_log_picks_robot_and_sensor(recording):
    path, _, _ = recording
    log = McapScanLog(path, robot="scout", sensor="rangers")
    assert log.topic == "/scout/rangers" and len(log) == 151
    with pytest.raises(RecordingError, match="no scans for robot 'ghost'.*mapper/lidar"):
        McapScanLog(path, robot="ghost")


def test_offline_slam_maps_a_recording(recording, tmp_path):
    path, _, _ = recording
    res = run_offline(open_scan_log(path), tmp_path / "slam")
    assert res.n_scans == 31
    traj = np.loadtxt(res.trajectory_path)
    assert traj.shape == (31, 4) and traj[-1, 0] == pytest.approx(3.0)
    assert res.map_png_path.stat().st_size > 0


def test_slam_command_picks_robot_and_sensor(recording, tmp_path):
    from typer.testing import CliRunner

    from agvsim.cli import app

    path, _, _ = recording
    args = ["slam", str(path), "--out", str(tmp_path / "m"), "--quiet"]
    ok = CliRunner().invoke(app, [*args, "--robot", "mapper", "--sensor", "lidar"])
    assert ok.exit_code == 0, ok.output
    assert np.loadtxt(tmp_path / "m" / "trajectory.txt").shape == (31, 4)
    bad = CliRunner().invoke(app, [*args, "--robot", "ghost"])
    assert bad.exit_code == 2 and "mapper/lidar" in bad.output
    carmen = tmp_path / "log.clf"
    carmen.write_text("# empty\n")
    refused = CliRunner().invoke(app, ["slam", str(carmen), "--robot", "mapper", "--quiet"])
    assert refused.exit_code == 2 and "agvsim recording (.mcap)" in refused.output


def test_interpolate_poses_wraps_the_heading():
    t = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, 3.0], [1.0, 2.0, -3.0]])
    got = interpolate_poses(np.array([0.5, -1.0, 2.0]), t, poses)
    # half-way from 3.0 rad to -3.0 rad the short way round is pi exactly
    np.testing.assert_allclose(got[0], [0.5, 1.0, np.pi], atol=1e-12)
    np.testing.assert_allclose(got[1:], poses, atol=1e-12)  # clamped at both ends


def test_slam_package_never_imports_the_simulator():
    code = (
        "import sys, agvsim.slam.offline, agvsim.record.scan_log\n"
        "print(sorted(m for m in sys.modules if m.startswith(('agvsim.sim', 'agvsim.scenario'))))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "[]"


def test_online_slam_map_is_recorded_at_the_end_of_a_run(tmp_path):
    from PIL import Image

    from agvsim.record.mcap_reader import Recording
    from agvsim.runner import run_scenario

    data = {**SCENARIO, "duration_s": 3.0}
    data["robots"] = [dict(r) for r in SCENARIO["robots"]]
    data["robots"][1]["slam"] = {"sensor": "lidar"}
    run_scenario(parse_scenario(data, "slam room"), tmp_path, plot=False)
    (grid,) = Recording(tmp_path / "run.mcap").occupancy("/mapper/slam/map")
    assert grid.t_s == pytest.approx(3.0) and grid.resolution_m == pytest.approx(0.05)
    # the same map as the run's map_server picture (row 0 north; occupied 0, free 254)
    pgm = np.asarray(Image.open(tmp_path / "slam_mapper" / "map.pgm"))
    cells = grid.cells[::-1]
    assert cells.shape == pgm.shape
    unsure = cells[pgm == 205]  # never seen (-1) or between the picture's thresholds
    assert np.all((unsure == -1) | ((unsure >= 19) & (unsure <= 65))) and np.any(unsure == -1)
    assert np.all(cells[pgm == 0] >= 65) and np.all(
        (cells[pgm == 254] >= 0) & (cells[pgm == 254] <= 20)
    )
    assert (pgm == 0).sum() > 50  # walls were seen


def test_slam_command_point_samples_maps_with_every_return_a_bump(recording, tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from agvsim.cli import app
    from agvsim.slam import offline

    seen = []
    real = offline.run_offline

    def spy(*args, **kwargs):
        seen.append(kwargs.get("config"))
        return real(*args, **kwargs)

    monkeypatch.setattr(offline, "run_offline", spy)
    path, _, _ = recording
    args = ["slam", str(path), "--robot", "mapper", "--quiet"]
    for k, flag in enumerate(([], ["--long-corridors"], ["--point-samples"])):
        out = tmp_path / f"m{k}"
        ok = CliRunner().invoke(app, [*args, "--out", str(out), *flag])
        assert ok.exit_code == 0, ok.output
        assert np.loadtxt(out / "trajectory.txt").shape == (31, 4)
    # the defaults spread edge-on samples; --long-corridors (the eleventh round's flag) is
    # the default's name, --point-samples the published figures' setting
    assert seen[0] is None and seen[1] is None
    assert offline.SlamConfig().tracking.edge_on_turn_rad == pytest.approx(np.radians(15.0))
    assert seen[2].tracking.edge_on_turn_rad is None
    assert seen[2].loop == offline.SlamConfig().loop  # nothing else changed
    assert dataclasses.replace(seen[2].tracking, edge_on_turn_rad=np.radians(15.0)) == (
        offline.SlamConfig().tracking
    )
