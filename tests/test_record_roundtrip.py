"""Every topic of a recording survives a round trip through rosbags: the values read back are
the simulation's own arrays (poses, twists, odometry, scans, grid cells, states, images and
their camera info)."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import yaml

pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402

from agvsim.record.mcap_file import scan_records  # noqa: E402
from agvsim.record.mcap_reader import Recording  # noqa: E402
from agvsim.record.mcap_writer import Recorder, odom_twists, scenario_yaml  # noqa: E402
from agvsim.record.ros2msg import topic_name  # noqa: E402
from agvsim.runner import run_scenario  # noqa: E402
from agvsim.scenario import build, parse_scenario  # noqa: E402
from agvsim.sim.engine import ControllerError  # noqa: E402

ROOM = {
    "name": "recording room",
    "seed": 3,
    "duration_s": 2.0,
    "world": {
        "picture": "##########\n#........#\n#........#\n#...##...#\n#........#\n##########",
        "cell_size_m": 1.0,
        "boxes": [{"x_m": 2.5, "y_m": -1.5, "length_m": 0.6, "width_m": 0.4}],
    },
    "robots": [
        {
            "name": "a",
            "model": "differential",
            "pose": {"x_m": -3.0, "y_m": -1.5, "theta_deg": 0},
            "sensors": [
                {"type": "rangers", "range_max_m": 1.5},
                {
                    "type": "lidar",
                    "beams": 36,
                    "range_max_m": 6.0,
                    "rate_hz": 10,
                    "noise_std_m": 0.01,
                    "range_min_m": 0.1,
                },
            ],  # fmt: skip
            "odometry": {"wheel_noise_rel": 0.02},
            "controller": {"type": "script", "steps": [{"duration_s": 5, "twist": [0.5, 0.4]}]},
        },
        {
            "name": "b 2",
            "model": "mecanum",
            "mode": "inverse",
            "pose": {"x_m": 2.0, "y_m": 1.0, "theta_deg": 90},
            "sensors": [
                {"type": "rangers", "range_max_m": 1.0},
                {
                    "type": "lidar",
                    "name": "front",
                    "beams": 20,
                    "fov_deg": 180,
                    "mount_x_m": 0.2,
                    "mount_y_m": 0.05,
                    "mount_yaw_deg": 30,
                    "rate_hz": 25,
                },
            ],  # fmt: skip
            "controller": {"type": "avoid", "trigger_m": 0.8, "speed_m_s": 0.6},
        },
    ],
}


def _scenario(**changes):
    data = json.loads(json.dumps(ROOM))
    data.update(changes)
    return parse_scenario(data, "room")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """Step a simulation by hand, keep a copy of its arrays at every step, record it."""
    sc = _scenario()
    sim = build(sc)
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    rec = Recorder(path, sim, scenario_yaml(sc, sim.seed), flush_sim_s=0.5)
    st = sim.state
    snaps = []

    def snap():
        snaps.append(
            dict(
                t=st.t_s,
                poses=st.poses.copy(),
                twists=st.twists.copy(),
                odom=st.odom_poses.copy(),
                scans=st.scans.copy(),
                stamps=st.scan_stamp.copy(),
                states=sim.active_states(),
                wheel_angles=st.wheel_angles.copy(),
                wheel_speeds=st.wheel_speeds.copy(),
            )
        )

    snap()
    for _ in range(100):  # 2 s at 50 Hz
        sim.step()
        rec.record()
        snap()
    rec.write_occupancy(
        "/a/slam/map", 2.0, np.array([[0.0, 1.0, np.nan], [0.25, 0.5, 0.996]]), 0.05, (-1.0, 2.0)
    )
    rec.close()
    return sim, path, snaps


def _read(path):
    """topic -> [(log time ns, message)] through rosbags alone (types from the file)."""
    out: dict[str, list] = {}
    with AnyReader([path]) as r:
        for c, t, raw in r.messages():
            out.setdefault(c.topic, []).append((t, r.deserialize(raw, c.msgtype)))
    return out


def _stamp(m) -> float:
    return m.header.stamp.sec + m.header.stamp.nanosec * 1e-9


def _yaw(q) -> float:
    return 2.0 * np.arctan2(q.z, q.w)


def test_topics_and_types(recorded):
    _, path, _ = recorded
    with AnyReader([path]) as r:
        types = {c.topic: c.msgtype for c in r.connections}
    assert types == {
        "/agvsim/scenario": "std_msgs/msg/String",
        "/tf_static": "tf2_msgs/msg/TFMessage",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/map": "nav_msgs/msg/OccupancyGrid",
        "/a/ground_truth": "nav_msgs/msg/Odometry",
        "/a/odom": "nav_msgs/msg/Odometry",
        "/a/rangers": "sensor_msgs/msg/LaserScan",
        "/a/lidar": "sensor_msgs/msg/LaserScan",
        "/a/slam/map": "nav_msgs/msg/OccupancyGrid",
        "/b_2/ground_truth": "nav_msgs/msg/Odometry",
        "/b_2/odom": "nav_msgs/msg/Odometry",
        "/b_2/rangers": "sensor_msgs/msg/LaserScan",
        "/b_2/front": "sensor_msgs/msg/LaserScan",
        "/a/state": "std_msgs/msg/String",
        "/b_2/state": "std_msgs/msg/String",
        "/a/joint_states": "sensor_msgs/msg/JointState",
        "/b_2/joint_states": "sensor_msgs/msg/JointState",
        "/agvsim/footprints": "visualization_msgs/msg/MarkerArray",
    }


def test_joint_states_are_the_wheel_angles_and_speeds(recorded):
    _, path, snaps = recorded
    msgs = _read(path)
    for i, (name, wheels) in enumerate([("a", ["left", "right"]), ("b_2", None)]):
        joints = msgs[f"/{name}/joint_states"]
        assert len(joints) == 101
        for k in (0, 50, 100):
            m = joints[k][1]
            n = len(m.name)
            if wheels is not None:
                assert list(m.name) == [f"{name}/{w}_wheel" for w in wheels]
            assert n == len(m.position) == len(m.velocity) and len(m.effort) == 0
            assert m.header.frame_id == f"{name}/base_link"
            np.testing.assert_array_equal(m.position, snaps[k]["wheel_angles"][i, :n])
            np.testing.assert_array_equal(m.velocity, snaps[k]["wheel_speeds"][i, :n])
    # robot a turns both wheels forward on its constant twist: the angles grow
    last = msgs["/a/joint_states"][100][1]
    assert (np.asarray(last.position) > 0).all()


def test_footprints_are_the_body_outlines(recorded):
    sim, path, _ = recorded
    ((t_ns, m),) = _read(path)["/agvsim/footprints"]
    assert t_ns == 0 and len(m.markers) == 2
    for marker, rt, spec in zip(m.markers, ["a", "b_2"], sim.robots, strict=True):
        assert marker.header.frame_id == f"{rt}/base_link" and marker.type == 4
        pts = np.array([[p.x, p.y] for p in marker.points])
        assert len(pts) == 5 and (pts[0] == pts[-1]).all()  # closed
        hl, hw = spec.footprint_half_m
        np.testing.assert_allclose(pts[:4].max(axis=0), [spec.body_offset_x_m + hl, hw])
        np.testing.assert_allclose(pts[:4].min(axis=0), [spec.body_offset_x_m - hl, -hw])


def test_poses_twists_and_odometry_equal_the_simulation(recorded):
    _, path, snaps = recorded
    msgs = _read(path)
    for i, name in enumerate(["a", "b_2"]):
        gt, odo = msgs[f"/{name}/ground_truth"], msgs[f"/{name}/odom"]
        assert len(gt) == len(odo) == 101  # t = 0 .. 2 s, every 20 ms step
        for k, snap in enumerate(snaps):
            t_ns, m = gt[k]
            assert t_ns == round(snap["t"] * 1e9) and _stamp(m) == pytest.approx(snap["t"])
            assert (m.header.frame_id, m.child_frame_id) == ("map", f"{name}/base_link")
            p = m.pose.pose
            np.testing.assert_allclose(
                [p.position.x, p.position.y, _yaw(p.orientation)], snap["poses"][i], atol=1e-12
            )
            tw = m.twist.twist
            np.testing.assert_allclose(
                [tw.linear.x, tw.linear.y, tw.angular.z], snap["twists"][i], atol=1e-12
            )
            o = odo[k][1]
            assert (o.header.frame_id, o.child_frame_id) == (f"{name}/odom", f"{name}/base_link")
            op = o.pose.pose
            np.testing.assert_allclose(
                [op.position.x, op.position.y, _yaw(op.orientation)], snap["odom"][i], atol=1e-12
            )
    # robot a drives a constant twist (0.5, 0, 0.4): its noisy odometry twist stays near it
    o = msgs["/a/odom"][60][1].twist.twist
    assert o.linear.x == pytest.approx(0.5, rel=0.1) and o.angular.z == pytest.approx(0.4, rel=0.1)
    assert abs(o.linear.y) < 1e-9  # a differential drive never slides sideways


def test_tf_chain_map_odom_base_is_the_ground_truth(recorded):
    _, path, snaps = recorded
    tfs = _read(path)["/tf"]
    assert len(tfs) == 101
    for k in (0, 37, 100):
        tr = {t.child_frame_id: t for t in tfs[k][1].transforms}
        for i, name in enumerate(["a", "b_2"]):
            m_o = tr[f"{name}/odom"]
            o_b = tr[f"{name}/base_link"]
            assert m_o.header.frame_id == "map" and o_b.header.frame_id == f"{name}/odom"
            a, b = m_o.transform, o_b.transform
            th_a = _yaw(a.rotation)
            c, s = np.cos(th_a), np.sin(th_a)
            x = a.translation.x + c * b.translation.x - s * b.translation.y
            y = a.translation.y + s * b.translation.x + c * b.translation.y
            th = np.angle(np.exp(1j * (th_a + _yaw(b.rotation))))
            np.testing.assert_allclose([x, y], snaps[k]["poses"][i][:2], atol=1e-9)
            assert np.angle(np.exp(1j * (th - snaps[k]["poses"][i][2]))) == pytest.approx(
                0, abs=1e-9
            )
            np.testing.assert_allclose(
                [b.translation.x, b.translation.y], snaps[k]["odom"][i][:2], atol=1e-12
            )


def test_scans_equal_the_simulation_at_each_firing(recorded):
    sim, path, snaps = recorded
    msgs = _read(path)
    tab = sim.sensors
    counts = {}
    for s in range(tab.count):
        spec = tab.specs[s]
        topic = f"/{topic_name(sim.robots[int(tab.owner[s])].name)}/{spec.name}"
        got = msgs[topic]
        counts[topic] = len(got)
        fired = [
            snap
            for k, snap in enumerate(snaps)
            if k == 0 or snap["stamps"][s] > snaps[k - 1]["stamps"][s]
        ]
        assert len(got) == len(fired)
        for (t_ns, m), snap in zip(got, fired, strict=True):
            assert _stamp(m) == pytest.approx(snap["stamps"][s]) and t_ns == round(
                snap["stamps"][s] * 1e9
            )
            expect = snap["scans"][s, : spec.num_beams].astype(np.float32)
            np.testing.assert_array_equal(np.asarray(m.ranges), expect)  # inf, -inf kept
            assert m.header.frame_id == topic[1:]
            assert m.angle_min == pytest.approx(spec.angle_min_rad, abs=1e-6)
            assert m.angle_increment == pytest.approx(spec.angle_increment_rad, abs=1e-7)
            assert m.angle_max == pytest.approx(
                spec.angle_min_rad + spec.angle_increment_rad * (spec.num_beams - 1), abs=1e-5
            )
            assert (m.range_min, m.range_max) == pytest.approx((spec.range_min_m, spec.range_max_m))
            assert m.scan_time == pytest.approx(1.0 / spec.rate_hz)
    # rates over 2 s: rangers every step (50 Hz), a's lidar 10 Hz, b's front lidar 25 Hz
    assert counts == {"/a/rangers": 101, "/a/lidar": 21, "/b_2/rangers": 101, "/b_2/front": 51}
    # the noisy lidar really is noisy, and the recorded values are the noisy ones
    assert np.any(np.abs(np.diff(np.asarray(msgs["/a/lidar"][0][1].ranges))) > 0)


def test_static_transforms_are_the_sensor_mounts(recorded):
    _, path, _ = recorded
    (t_ns, m), = _read(path)["/tf_static"]  # fmt: skip
    tr = {t.child_frame_id: t for t in m.transforms}
    front = tr["b_2/front"]
    assert front.header.frame_id == "b_2/base_link"
    assert (front.transform.translation.x, front.transform.translation.y) == (0.2, 0.05)
    assert _yaw(front.transform.rotation) == pytest.approx(np.deg2rad(30))
    assert set(tr) == {"a/rangers", "a/lidar", "b_2/rangers", "b_2/front"}


def test_map_cells_and_the_occupancy_hook(recorded):
    sim, path, _ = recorded
    msgs = _read(path)
    (t_ns, m), = msgs["/map"]  # fmt: skip
    g = sim.world.grid
    assert (m.info.width, m.info.height) == (10, 6) and m.info.resolution == pytest.approx(1.0)
    assert (m.info.origin.position.x, m.info.origin.position.y) == g.origin_xy_m
    cells = np.asarray(m.data).reshape(6, 10)
    np.testing.assert_array_equal(cells, np.where(g.occupied[::-1], 100, 0))
    assert cells[0, 0] == 100 and cells[2, 4] == 100 and cells[2, 3] == 0  # row 0 is south
    (t_ns, s), = msgs["/a/slam/map"]  # fmt: skip
    assert t_ns == 2_000_000_000 and (s.info.width, s.info.height) == (3, 2)
    # probabilities -> 0..100, NaN -> -1, rows flipped to ROS order (south first)
    np.testing.assert_array_equal(np.asarray(s.data), [25, 50, 100, 0, 100, -1])
    assert s.info.origin.position.x == -1.0 and s.info.resolution == pytest.approx(0.05)


def test_states_and_scenario(recorded):
    sim, path, snaps = recorded
    msgs = _read(path)
    changes = [(round(t * 1e-9, 6), m.data) for t, m in msgs["/b_2/state"]]
    expect, last = [], None
    for snap in snaps:
        if snap["states"][1] != last:
            expect.append((round(snap["t"], 6), snap["states"][1]))
            last = snap["states"][1]
    assert changes == expect and changes[0][1] != ""
    # a script's state never changes: one message at the start
    assert [(t, m.data) for t, m in msgs["/a/state"]] == [(0, snaps[0]["states"][0])]
    (_, text), = msgs["/agvsim/scenario"]  # fmt: skip
    back = parse_scenario(yaml.safe_load(text.data), "stored")
    assert back.robots[1].name == "b 2" and back.seed == 3
    assert back.world.boxes[0].x_m == 2.5


def test_summary_and_chunks_of_the_closed_file(recorded):
    _, path, _ = recorded
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = list(reader.iter_metadata())
    n = sum(len(v) for v in _read(path).values())
    assert summary.statistics.message_count == n
    assert len(summary.chunk_indexes) >= 4  # flushed every 0.5 s of simulated time
    assert meta[0].name == "agvsim" and meta[0].metadata["seed"] == "3"
    assert "b 2" in meta[0].metadata["scenario_yaml"]
    _, _, complete = scan_records(path)
    assert complete


def test_fast_reader_equals_rosbags_decoding(recorded):
    _, path, _ = recorded
    rec = Recording(path)
    t, poses, tw = rec.odometry("/b_2/ground_truth")
    msgs = _read(path)["/b_2/ground_truth"]
    assert np.array_equal(t, [_stamp(m) for _, m in msgs])
    ref = [(m.pose.pose.position.x, m.pose.pose.position.y, _yaw(m.pose.pose.orientation))
           for _, m in msgs]  # fmt: skip
    np.testing.assert_array_equal(poses, ref)
    scans = rec.laser_scans("/a/lidar")
    ref_scans = [np.asarray(m.ranges, dtype=np.float64) for _, m in _read(path)["/a/lidar"]]
    np.testing.assert_array_equal(scans.ranges, ref_scans)
    assert rec.lidar_topics()[0] == ("a", "lidar", "/a/lidar")


@pytest.mark.parametrize("seed", [0, 1])
def test_odom_twist_inverts_exact_integration(seed):
    from agvsim.kinematics import integrate_se2

    rng = np.random.default_rng(seed)
    p0 = rng.uniform(-3, 3, (50, 3))
    tw = rng.uniform(-2, 2, (50, 3))
    tw[:5, 2] = 0.0  # straight lines: the small-angle branch
    tw[5:10, 2] = 1e-8
    p1 = integrate_se2(p0, tw, 0.3)
    np.testing.assert_allclose(odom_twists(p0, p1, 0.3), tw, atol=1e-9)


def test_images_round_trip_as_compressed_images(tmp_path):
    from PIL import Image

    sim = build(_scenario())
    rec = Recorder(tmp_path / "img.mcap", sim)
    rgb = (np.arange(24 * 32 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    rec.write_image("/a/cam/image/compressed", 0.5, "a/cam", rgb, "png")
    with pytest.raises(ValueError, match="'jpeg' or 'png'"):
        rec.write_image("/a/cam/image/compressed", 0.5, "a/cam", rgb, "bmp")
    rec.close()
    ((_, m),) = _read(tmp_path / "img.mcap")["/a/cam/image/compressed"]
    assert m.format == "png" and m.header.frame_id == "a/cam"
    back = np.asarray(Image.open(io.BytesIO(bytes(m.data))).convert("RGB"))
    np.testing.assert_array_equal(back, rgb)


def test_runner_writes_run_mcap_matching_trajectory_csv(tmp_path):
    import csv

    run_scenario(_scenario(duration_s=1.0), tmp_path, plot=False)
    rec = Recording(tmp_path / "run.mcap")
    t, poses, _ = rec.odometry("/a/ground_truth")
    with (tmp_path / "trajectory.csv").open() as f:
        rows = [r for r in csv.DictReader(f) if r["robot"] == "a"]
    assert len(rows) == len(t) == 51
    np.testing.assert_allclose(t, [float(r["t"]) for r in rows], atol=1e-9)
    np.testing.assert_allclose(poses[:, 0], [float(r["x"]) for r in rows], atol=1e-6)
    run_scenario(_scenario(duration_s=0.2), tmp_path / "none", plot=False, record_mcap=False)
    assert not (tmp_path / "none" / "run.mcap").exists()


def test_recording_is_closed_after_a_controller_error(tmp_path):
    (tmp_path / "ctrl.py").write_text(
        "def step(obs):\n    if obs.t_s >= 1.0:\n        raise RuntimeError('no')\n"
        "    return (0.2, 0.0, 0.0)\n"
    )
    data = json.loads(json.dumps(ROOM))
    data["robots"][0]["controller"] = {"type": "python", "file": "ctrl.py", "name": "step"}
    data["duration_s"] = 5.0
    sc = parse_scenario(data, "room")
    sc._base_dir = tmp_path
    with pytest.raises(ControllerError):
        run_scenario(sc, tmp_path / "out", plot=False)
    path = tmp_path / "out" / "run.mcap"
    assert scan_records(path)[2]  # closed with its footer
    t, poses, _ = Recording(path).odometry("/a/ground_truth")
    assert t[-1] == pytest.approx(1.0)
    assert poses[-1, 0] == pytest.approx(-3.0 + 0.2 * 1.0)


def test_camera_frames_are_recorded_as_jpeg(tmp_path):
    from PIL import Image

    data = json.loads(json.dumps(ROOM))
    data["robots"] = data["robots"][:1]
    data["robots"][0]["sensors"].append(
        {"type": "camera", "name": "cam", "width_px": 32, "height_px": 24, "rate_hz": 10}
    )
    sim = build(parse_scenario(data, "room"))
    rec = Recorder(tmp_path / "cam.mcap", sim)
    for _ in range(50):
        sim.step()
        rec.record()
    rec.close()
    msgs = _read(tmp_path / "cam.mcap")
    images = msgs["/a/cam/image/compressed"]
    assert len(images) == 11  # 10 Hz over 1 s, t = 0 included
    last = images[-1][1]
    assert last.format == "jpeg" and last.header.frame_id == "a/cam_optical"
    assert _stamp(last) == pytest.approx(sim.camera_frames()[0].stamp_s)
    back = np.asarray(Image.open(io.BytesIO(bytes(last.data))).convert("RGB"), dtype=int)
    assert back.shape == (24, 32, 3)
    assert np.abs(back - sim.camera_frames()[0].rgb.astype(int)).mean() < 12.0
    ((_, static),) = msgs["/tf_static"]
    assert {"a/cam", "a/cam_optical"} <= {t.child_frame_id for t in static.transforms}


def _matrix(q) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()


def _optical_in_base(static, cam: str) -> tuple[np.ndarray, np.ndarray]:
    """(t (3,), R (3, 3)) of ``<cam>_optical`` in ``<robot>/base_link``, composed from the
    ``/tf_static`` message: base_link -> ``<cam>`` -> ``<cam>_optical``."""
    tr = {t.child_frame_id: t.transform for t in static.transforms}
    cam_tf, opt_tf = tr[cam], tr[f"{cam}_optical"]
    r_cam = _matrix(cam_tf.rotation)
    t_cam = np.array([cam_tf.translation.x, cam_tf.translation.y, cam_tf.translation.z])
    t_opt = np.array([opt_tf.translation.x, opt_tf.translation.y, opt_tf.translation.z])
    return t_cam + r_cam @ t_opt, r_cam @ _matrix(opt_tf.rotation)


def _project(K, t_opt, r_opt, base_pose, pts_world) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (n, 2) and z-depths (n,) of world points (n, 3) through a planar base_link pose
    (x, y, theta), the optical frame's pose in base_link (``_optical_in_base``) and ``K``."""
    x0, y0, th = base_pose
    c, s = np.cos(th), np.sin(th)
    d = np.asarray(pts_world, dtype=np.float64) - (x0, y0, 0.0)
    pts_base = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    p_opt = (pts_base - t_opt) @ r_opt  # R^T (p - t), row by row
    return (p_opt @ np.asarray(K).T)[:, :2] / p_opt[:, 2:3], p_opt[:, 2]


def test_a_pitched_camera_mount_is_a_3d_transform_with_an_optical_child(tmp_path):
    from agvsim.sensors.camera import project_points

    data = json.loads(json.dumps(ROOM))
    data["robots"] = data["robots"][:1]
    data["robots"][0]["sensors"] = [
        {
            "type": "camera",
            "name": "cam",
            "width_px": 32,
            "height_px": 24,
            "mount_x_m": 0.3,
            "mount_y_m": -0.1,
            "mount_z_m": 0.45,
            "mount_yaw_deg": 90,
            "pitch_deg": 30,
        }
    ]
    sim = build(parse_scenario(data, "room"))
    Recorder(tmp_path / "cam.mcap", sim).close()
    ((_, static),) = _read(tmp_path / "cam.mcap")["/tf_static"]
    tr = {t.child_frame_id: t for t in static.transforms}
    assert set(tr) == {"a/cam", "a/cam_optical"}
    cam, opt = tr["a/cam"], tr["a/cam_optical"]
    assert cam.header.frame_id == "a/base_link" and opt.header.frame_id == "a/cam"
    t = cam.transform.translation
    assert (t.x, t.y, t.z) == pytest.approx((0.3, -0.1, 0.45), abs=1e-12)
    # q = q_z(90 deg) q_y(30 deg): (w, x, y, z) = (c45 c15, -s45 s15, c45 s15, s45 c15)
    #   = (0.683013, -0.183013, 0.183013, 0.683013)
    q = cam.transform.rotation
    want = (-0.183013, 0.183013, 0.683013, 0.683013)
    assert (q.x, q.y, q.z, q.w) == pytest.approx(want, abs=1e-6)
    t = opt.transform.translation
    assert (t.x, t.y, t.z) == (0.0, 0.0, 0.0)
    q = opt.transform.rotation
    assert (q.x, q.y, q.z, q.w) == (-0.5, 0.5, -0.5, 0.5)
    # the camera's axes in base_link: x forward = (cos 30 cos 90, cos 30 sin 90, -sin 30);
    # the optical frame: z along it, x right (yawed 90 deg: base +x), y down
    r_cam = _matrix(cam.transform.rotation)
    t_opt, r_opt = _optical_in_base(static, "a/cam")
    assert t_opt == pytest.approx((0.3, -0.1, 0.45), abs=1e-12)
    assert r_cam[:, 0] == pytest.approx((0.0, np.sqrt(3) / 2, -0.5), abs=1e-12)
    assert r_opt[:, 2] == pytest.approx((0.0, np.sqrt(3) / 2, -0.5), abs=1e-12)
    assert r_opt[:, 0] == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    assert r_opt[:, 1] == pytest.approx((0.0, -0.5, -np.sqrt(3) / 2), abs=1e-12)
    # base_link -> optical frame and the camera matrix K give the simulator's own pixels
    spec = sim.robots[0].cameras[0]
    x0, y0, th = sim.state.poses[0]
    rng = np.random.default_rng(0)
    pts_base = np.column_stack(
        [rng.uniform(-1, 1, 20) + 0.3, rng.uniform(1, 3, 20), rng.uniform(-0.5, 0.2, 20)]
    )
    c, s = np.cos(th), np.sin(th)
    pts_world = np.column_stack(
        [x0 + c * pts_base[:, 0] - s * pts_base[:, 1], y0 + s * pts_base[:, 0] + c * pts_base[:, 1],
         pts_base[:, 2]]
    )  # fmt: skip
    uv, z = _project(spec.K, t_opt, r_opt, (x0, y0, th), pts_world)
    want, depth = project_points(spec, sim.state.poses[0], pts_world)
    assert np.all(depth > 0)
    assert uv == pytest.approx(want, abs=1e-9)
    assert z == pytest.approx(depth, abs=1e-12)


def test_occupancy_hook_checks_its_input(tmp_path):
    sim = build(_scenario())
    rec = Recorder(tmp_path / "o.mcap", sim)
    with pytest.raises(ValueError, match="/x: occupancy must be a 2-D array"):
        rec.write_occupancy("/x", 0.0, np.zeros(4), 1.0, (0.0, 0.0))
    with pytest.raises(ValueError, match="/x: occupancy cell values must be -1.*got 255"):
        rec.write_occupancy("/x", 0.0, np.array([[0, 255]]), 1.0, (0.0, 0.0))
    rec.write_occupancy("/x", 0.5, np.array([[100, -1], [0, 0]]), 0.5, (1.0, 2.0))
    rec.close()
    ((_, m),) = _read(tmp_path / "o.mcap")["/x"]
    np.testing.assert_array_equal(np.asarray(m.data), [0, 0, 100, -1])  # south row first


def _pixel_points(K, t_opt, r_opt, base_pose, depth) -> np.ndarray:
    """World points (n, 3) of the pixel centres with a finite z-depth in ``depth`` (H, W): the
    inverse of ``_project``, pixel (u, v) at z-depth d is d K^-1 (u, v, 1) in the optical frame."""
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    d = depth.ravel().astype(np.float64)
    fin = np.isfinite(d)
    rays = np.linalg.solve(K, np.stack([u.ravel()[fin], v.ravel()[fin], np.ones(fin.sum())]))
    x0, y0, th = base_pose
    c, s = np.cos(th), np.sin(th)
    r_world_base = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    pts_base = (r_opt @ (rays * d[fin])).T + t_opt
    return pts_base @ r_world_base.T + (x0, y0, 0.0)


def test_camera_info_with_every_image_projects_onto_the_rendered_pixels(tmp_path):
    """One CameraInfo per image (same stamp and frame), K and P as worked out by hand, and
    /tf + /tf_static + K put world points on the pixels where the renderer draws them."""
    from agvsim.sensors.camera import project_points
    from agvsim.sim.spec import WALL_HEIGHT_M

    data = json.loads(json.dumps(ROOM))
    data["world"]["boxes"] = []  # every surface in view is the floor or a wall face on a grid line
    data["robots"] = data["robots"][:1]
    data["robots"][0]["sensors"] = [
        {"type": "camera", "name": "cam", "width_px": 64, "height_px": 48, "hfov_deg": 90,
         "rate_hz": 10, "mount_x_m": 0.2, "mount_z_m": 0.3, "mount_yaw_deg": -10,
         "pitch_deg": 20},
        {"type": "camera", "name": "level", "width_px": 40, "height_px": 30, "hfov_deg": 60,
         "rate_hz": 10, "mount_x_m": 0.1, "mount_y_m": 0.05, "mount_z_m": 0.25,
         "mount_yaw_deg": 25},
    ]  # fmt: skip
    sim = build(parse_scenario(data, "room"))
    rec = Recorder(tmp_path / "cam.mcap", sim)
    for _ in range(50):  # 1 s
        sim.step()
        rec.record()
    rec.close()
    msgs = _read(tmp_path / "cam.mcap")
    for cam in ("cam", "level"):
        images, infos = msgs[f"/a/{cam}/image/compressed"], msgs[f"/a/{cam}/camera_info"]
        assert len(images) == len(infos) == 11  # 10 Hz over 1 s, t = 0 included
        for (t_img, img), (t_info, info) in zip(images, infos, strict=True):
            assert t_info == t_img and info.header.stamp == img.header.stamp
            assert info.header.frame_id == img.header.frame_id == f"a/{cam}_optical"
    # pixel centres at integer coordinates: principal point ((W - 1) / 2, (H - 1) / 2), and
    # f = (W / 2) / tan(hfov / 2): 64 x 48 px, 90 deg: f = 32 / tan 45 deg = 32;
    # 40 x 30 px, 60 deg: f = 20 / tan 30 deg = 20 sqrt(3) = 34.641016
    hand = {
        "cam": np.array([[32.0, 0.0, 31.5], [0.0, 32.0, 23.5], [0.0, 0.0, 1.0]]),
        "level": np.array([[34.641016, 0.0, 19.5], [0.0, 34.641016, 14.5], [0.0, 0.0, 1.0]]),
    }
    K = {}
    for cam, (w, h) in [("cam", (64, 48)), ("level", (40, 30))]:
        m = msgs[f"/a/{cam}/camera_info"][-1][1]
        assert (m.width, m.height, m.distortion_model) == (w, h, "plumb_bob")
        assert np.asarray(m.d).tolist() == [0.0] * 5
        K[cam] = np.asarray(m.k).reshape(3, 3)
        assert K[cam] == pytest.approx(hand[cam], rel=1e-7)
        assert np.asarray(m.r).reshape(3, 3).tolist() == np.eye(3).tolist()
        assert (
            np.asarray(m.p).reshape(3, 4).tolist()
            == np.column_stack([K[cam], np.zeros(3)]).tolist()
        )
        roi = m.roi
        assert (m.binning_x, m.binning_y, roi.x_offset, roi.y_offset, roi.height,
                roi.width, roi.do_rectify) == (0, 0, 0, 0, 0, 0, False)  # fmt: skip
    # the last frames, from the recording alone: base_link at their stamp from /tf (map ->
    # odom -> base_link), the optical frames from /tf_static, K from camera_info
    frames = {f.camera: f for f in sim.camera_frames()}
    t_ns = msgs["/a/cam/camera_info"][-1][0]
    assert t_ns == round(frames["cam"].stamp_s * 1e9) == round(frames["level"].stamp_s * 1e9)
    ((_, tf),) = [(t, m) for t, m in msgs["/tf"] if t == t_ns]
    tr = {t.child_frame_id: t.transform for t in tf.transforms}
    a, b = tr["a/odom"], tr["a/base_link"]
    th_a = _yaw(a.rotation)
    c, s = np.cos(th_a), np.sin(th_a)
    pose = (a.translation.x + c * b.translation.x - s * b.translation.y,
            a.translation.y + s * b.translation.x + c * b.translation.y,
            th_a + _yaw(b.rotation))  # fmt: skip
    assert pose == pytest.approx(tuple(sim.state.image_pose[0]), abs=1e-9)
    ((_, static),) = msgs["/tf_static"]
    # known world points (ahead of the robot) land where the renderer's projection puts them
    rng = np.random.default_rng(1)
    ahead = np.column_stack([rng.uniform(1, 3, 30), rng.uniform(-1, 1, 30), rng.uniform(0, 1, 30)])
    ct, st = np.cos(pose[2]), np.sin(pose[2])
    pts = np.column_stack([pose[0] + ct * ahead[:, 0] - st * ahead[:, 1],
                           pose[1] + st * ahead[:, 0] + ct * ahead[:, 1], ahead[:, 2]])  # fmt: skip
    for i, cam in enumerate(("cam", "level")):
        t_opt, r_opt = _optical_in_base(static, f"a/{cam}")
        uv, z = _project(K[cam], t_opt, r_opt, pose, pts)
        want, depth = project_points(sim.robots[0].cameras[i], sim.state.image_pose[0], pts)
        assert np.all(depth > 0) and uv == pytest.approx(want, abs=1e-9)
        assert z == pytest.approx(depth, abs=1e-12)
    # ... and on the rendered images: each pixel centre at the z-depth the renderer drew there
    # is a point on a surface of the world. The pitched camera's pixels use the nearest of 2 W
    # azimuths, exact only on the floor: its points lie on the floor or above it (a wall in
    # front). The level camera's image is exact: every point is on the floor or a wall face.
    # Half a pixel off in cy (or 1 % in f) takes them ~0.45 m off; 0.1 px in cx, 9 mm.
    t_opt, r_opt = _optical_in_base(static, "a/cam")
    p = _pixel_points(K["cam"], t_opt, r_opt, pose, frames["cam"].depth)
    on_floor = np.abs(p[:, 2]) < 1e-5
    assert np.all(on_floor | (p[:, 2] > 0)) and on_floor.mean() > 0.5, on_floor.mean()
    t_opt, r_opt = _optical_in_base(static, "a/level")
    p = _pixel_points(K["level"], t_opt, r_opt, pose, frames["level"].depth)
    ox, oy = sim.world.grid.origin_xy_m  # 1 m cells
    off_x, off_y = (np.abs((p[:, k] - o + 0.5) % 1.0 - 0.5) for k, o in ((0, ox), (1, oy)))
    on_floor = np.abs(p[:, 2]) < 1e-5
    on_wall = (np.minimum(off_x, off_y) < 1e-5) & (p[:, 2] > 0) & (p[:, 2] < WALL_HEIGHT_M)
    assert np.all(on_floor | on_wall)
    assert on_floor.sum() > 200 and on_wall.sum() > 200, (on_floor.sum(), on_wall.sum())


def test_foxglove_layout_names_topics_of_the_main_demo(tmp_path):
    """Every topic the shipped Foxglove layout shows is one that a run of the main demo
    records."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    layout = json.loads((root / "docs/foxglove/agvsim_layout.json").read_text())
    panels = layout["configById"]
    wanted = set(panels["3D!agvsim"]["topics"])
    wanted |= {p["value"].split(".")[0] for p in panels["Plot!wheels"]["paths"]}
    wanted |= {c["topicPath"].split(".")[0] for k, c in panels.items() if "RawMessages" in k}
    run_scenario(root / "scenarios/thesis_maze_avoid.yaml", tmp_path, duration_s=0.2, plot=False)
    with AnyReader([tmp_path / "run.mcap"]) as r:
        topics = {c.topic for c in r.connections}
    assert wanted <= topics, wanted - topics
