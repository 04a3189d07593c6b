"""ROS 2 layouts: our CDR bytes equal rosbags' serializer's, our schema texts parse as the
standard types, and the MCAP stream writer's files read in rosbags and mcap, closed or not."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from agvsim.record import ros2msg as R  # noqa: E402
from agvsim.record.mcap_file import McapStreamWriter, repair, scan_records  # noqa: E402

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types


def _hdr(t_ns: int, frame: str):
    sec, nsec = divmod(t_ns, 1_000_000_000)
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id=frame
    )


def _pose(x, y, th):
    return T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=np.sin(th / 2), w=np.cos(th / 2)
        ),
    )


def test_odometry_bytes_equal_rosbags():
    t = 3_250_000_000
    ours = R.encode_odometry(t, "a/odom", "a/base_link", (1.5, -2.0, 0.7), (0.3, 0.1, -0.2))
    v3 = T["geometry_msgs/msg/Vector3"]
    ref = T["nav_msgs/msg/Odometry"](
        header=_hdr(t, "a/odom"),
        child_frame_id="a/base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=_pose(1.5, -2.0, 0.7), covariance=np.zeros(36)
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=v3(x=0.3, y=0.1, z=0.0), angular=v3(x=0.0, y=0.0, z=-0.2)
            ),
            covariance=np.zeros(36),
        ),
    )
    assert ours == bytes(TS.serialize_cdr(ref, R.ODOMETRY))


@pytest.mark.parametrize("frame", ["", "r", "robot_1/base", "abcdefg"])
def test_tf_bytes_equal_rosbags_for_every_string_padding(frame):
    t = 20_000_000
    ours = R.encode_tf(t, [("map", frame, 1.0, 2.0, 0.5), (frame, "x/base_link", -1.0, 0.0, 3.0)])
    ts_ = T["geometry_msgs/msg/TransformStamped"]
    tr = T["geometry_msgs/msg/Transform"]
    v3, q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]

    def one(parent, child, x, y, th):
        return ts_(
            header=_hdr(t, parent),
            child_frame_id=child,
            transform=tr(
                translation=v3(x=x, y=y, z=0.0),
                rotation=q(x=0.0, y=0.0, z=np.sin(th / 2), w=np.cos(th / 2)),
            ),
        )

    ref = T["tf2_msgs/msg/TFMessage"](
        transforms=[one("map", frame, 1.0, 2.0, 0.5), one(frame, "x/base_link", -1.0, 0.0, 3.0)]
    )
    assert ours == bytes(TS.serialize_cdr(ref, R.TF_MESSAGE))


def test_3d_tf_bytes_equal_rosbags_and_yaw_pitch_quaternions_compose():
    from scipy.spatial.transform import Rotation

    t = 1_500_000_000
    q = R.yaw_pitch_quaternion(0.7, -0.3)
    want = Rotation.from_euler("ZY", [0.7, -0.3]).as_quat()  # intrinsic: yaw, then pitch
    assert q == pytest.approx(tuple(want), abs=1e-12)
    tfs = [("a/base_link", "a/cam", (0.3, -0.1, 0.45), q), ("a/cam", "a/cam_optical", (0.0,) * 3,
           R.OPTICAL_QUATERNION)]  # fmt: skip
    ours = R.encode_tf_3d(t, tfs)
    ts_ = T["geometry_msgs/msg/TransformStamped"]
    tr = T["geometry_msgs/msg/Transform"]
    v3, qt = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    ref = T["tf2_msgs/msg/TFMessage"](
        transforms=[
            ts_(
                header=_hdr(t, parent),
                child_frame_id=child,
                transform=tr(
                    translation=v3(x=p[0], y=p[1], z=p[2]),
                    rotation=qt(x=r[0], y=r[1], z=r[2], w=r[3]),
                ),
            )
            for parent, child, p, r in tfs
        ]
    )
    assert ours == bytes(TS.serialize_cdr(ref, R.TF_MESSAGE))
    # the optical frame: z along the camera's x (forward), x along -y (right), y along -z
    m = Rotation.from_quat(R.OPTICAL_QUATERNION).as_matrix()
    assert m == pytest.approx(np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]]), abs=1e-12)


@pytest.mark.parametrize("n", [0, 1, 4, 240])
def test_laser_scan_bytes_equal_rosbags(n):
    ranges = np.linspace(0.2, 9.0, n).astype(np.float32)
    if n >= 4:
        ranges[1], ranges[2] = np.inf, -np.inf
    ours = R.encode_laser_scan(5, "r/lidar", -3.0, 0.025, 0.1, 10.0, 0.1, ranges)
    ref = T["sensor_msgs/msg/LaserScan"](
        header=_hdr(5, "r/lidar"),
        angle_min=-3.0,
        angle_max=-3.0 + 0.025 * max(n - 1, 0),
        angle_increment=0.025,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=10.0,
        ranges=ranges,
        intensities=np.zeros(0, np.float32),
    )
    assert ours == bytes(TS.serialize_cdr(ref, R.LASER_SCAN))


def test_occupancy_grid_image_and_string_bytes_equal_rosbags():
    cells = np.array([[0, 100, -1], [100, 0, 0]], np.int8)
    ours = R.encode_occupancy_grid(7, "map", cells, 0.05, (-1.0, -2.0))
    info = T["nav_msgs/msg/MapMetaData"](
        map_load_time=T["builtin_interfaces/msg/Time"](sec=0, nanosec=7),
        resolution=0.05,
        width=3,
        height=2,
        origin=_pose(-1.0, -2.0, 0.0),
    )
    ref = T["nav_msgs/msg/OccupancyGrid"](header=_hdr(7, "map"), info=info, data=cells.ravel())
    assert ours == bytes(TS.serialize_cdr(ref, R.OCCUPANCY_GRID))
    img = R.encode_compressed_image(9, "r/cam", "png", b"\x89PNG12345")
    ref_img = T["sensor_msgs/msg/CompressedImage"](
        header=_hdr(9, "r/cam"), format="png", data=np.frombuffer(b"\x89PNG12345", np.uint8)
    )
    assert img == bytes(TS.serialize_cdr(ref_img, R.COMPRESSED_IMAGE))
    assert R.encode_string("héllo") == bytes(
        TS.serialize_cdr(T["std_msgs/msg/String"](data="héllo"), R.STRING)
    )


def _camera_info_ref(t_ns: int, frame: str, w: int, h: int, k: np.ndarray):
    roi = T["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return T["sensor_msgs/msg/CameraInfo"](
        header=_hdr(t_ns, frame),
        height=h,
        width=w,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=k.ravel(),
        r=np.eye(3).ravel(),
        p=np.column_stack([k, np.zeros(3)]).ravel(),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


@pytest.mark.parametrize("frame", ["", "r", "a/cam_optical", "robot_1/front_optical"])
def test_camera_info_bytes_equal_rosbags_for_every_string_padding(frame):
    from agvsim.sensors.camera import CameraSpec

    spec = CameraSpec(width_px=64, height_px=48, hfov_rad=np.deg2rad(75.0))
    t = 2_100_000_000
    ours = R.encode_camera_info(t, frame, 64, 48, spec.K)
    assert ours == bytes(
        TS.serialize_cdr(_camera_info_ref(t, frame, 64, 48, spec.K), R.CAMERA_INFO)
    )
    enc = R.CameraInfoEncoder(frame, 64, 48, spec.K)  # the template: only the stamp changes
    for t_ns in (0, t, 59_980_000_000):
        assert enc.encode(t_ns) == R.encode_camera_info(t_ns, frame, 64, 48, spec.K)
    with pytest.raises(ValueError, match=r"K must be a \(3, 3\) camera matrix"):
        R.encode_camera_info(t, frame, 64, 48, np.eye(4))


@pytest.mark.parametrize("type_name", R.TYPES)
def test_schema_texts_define_the_standard_fields(type_name):
    parsed = get_types_from_msg(R.schema_text(type_name), type_name)
    for name, fields in parsed.items():
        assert name in TS.fielddefs, name
        ours = [f[0] for f in fields[1]]
        ref = [f[0] for f in TS.fielddefs[name][1]]
        assert ours == ref, name


def _write(path, close: bool, n: int = 100, flush_every: int = 50):
    w = McapStreamWriter(path)
    sid = w.add_schema(R.ODOMETRY, "ros2msg", R.schema_text(R.ODOMETRY).encode())
    cid = w.add_channel("/r/odom", sid)
    for k in range(n):
        t = k * 20_000_000
        data = R.encode_odometry(t, "r/odom", "r/base_link", (k * 0.1, 2.0, 0.3), (1, 0, 0))
        w.add_message(cid, t, data)
        if k % flush_every == flush_every - 1:
            w.flush()
    if close:
        w.close()
    return w


def _read_x(path):
    with AnyReader([path]) as r:
        return [r.deserialize(raw, c.msgtype).pose.pose.position.x for c, _, raw in r.messages()]


def test_stream_writer_files_read_back_closed_and_unclosed(tmp_path):
    closed = tmp_path / "a.mcap"
    _write(closed, close=True)
    np.testing.assert_allclose(_read_x(closed), np.arange(100) * 0.1)
    # not closed: the 2 flushed chunks (100 messages) are on disk, the file ends in a footer
    open_ = tmp_path / "b.mcap"
    w = _write(open_, close=False, n=120)  # 20 messages still in memory
    snap = tmp_path / "snap.mcap"
    shutil.copy(open_, snap)
    np.testing.assert_allclose(_read_x(snap), np.arange(100) * 0.1)
    w.close()
    assert len(_read_x(open_)) == 120
    from mcap.reader import make_reader

    with open(closed, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == 100
    assert summary.statistics.channel_message_counts == {0: 100}
    assert len(summary.chunk_indexes) == 2


def test_repair_drops_a_half_written_chunk(tmp_path):
    p = tmp_path / "c.mcap"
    _write(p, close=False, n=100)  # two chunks and a provisional end on disk
    data = p.read_bytes()
    recs, _, complete = scan_records(p)
    assert complete
    chunk2 = [off for op, off, _ in recs if op == 6][1]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunk2 + 100])  # the second chunk cut in the middle
    with pytest.raises(Exception):  # noqa: B017 - rosbags refuses a file without footer
        _read_x(cut)
    repair(cut)
    np.testing.assert_allclose(_read_x(cut), np.arange(50) * 0.1)


def test_template_encoders_equal_the_plain_ones():
    enc = R.OdometryEncoder("rob/odom", "rob/base_link")
    for t, pose, tw in [(0, (0, 0, 0), (0, 0, 0)), (1_020_000_000, (1.5, -2, 3.0), (0.2, 0, 1))]:
        assert enc.encode(t, pose, tw) == R.encode_odometry(
            t, "rob/odom", "rob/base_link", pose, tw
        )
    ranges = np.array([0.5, np.inf, -np.inf, 0.0, 7.25])
    scan = R.LaserScanEncoder("rob/front", -0.5, 0.25, 0.1, 8.0, 0.05, 5)
    assert scan.encode(123, ranges) == R.encode_laser_scan(
        123, "rob/front", -0.5, 0.25, 0.1, 8.0, 0.05, ranges
    )
    with pytest.raises(ValueError, match="expected 5 ranges"):
        scan.encode(0, ranges[:3])
    pairs = [("map", "a/odom"), ("a/odom", "a/base_link"), ("map", "bb/odom")]
    vals = np.array([[1.0, 2.0, 0.1], [-1.0, 0.5, -2.0], [0.0, 0.0, np.pi]])
    tf = R.TfEncoder(pairs)
    assert tf.encode(99, vals) == R.encode_tf(
        99, [(p, c, *v) for (p, c), v in zip(pairs, vals.tolist(), strict=True)]
    )


def test_every_type_decodes_with_mcap_ros2_as_foxglove_would(tmp_path):
    """mcap-ros2-support parses our ros2msg schema texts on its own (like Foxglove)."""
    mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")
    from mcap.reader import make_reader

    K = np.array([[32.0, 0.0, 31.5], [0.0, 32.0, 23.5], [0.0, 0.0, 1.0]])
    samples = {
        R.ODOMETRY: R.encode_odometry(1, "o", "b", (1.5, 2.0, 0.5), (0.1, 0.2, 0.3)),
        R.TF_MESSAGE: R.encode_tf(1, [("map", "o", 1.0, 2.0, 0.5)]),
        R.LASER_SCAN: R.encode_laser_scan(1, "l", -1.0, 0.5, 0.0, 5.0, 0.1, np.array([1.0, 2])),
        R.OCCUPANCY_GRID: R.encode_occupancy_grid(1, "map", np.array([[0, 100]]), 0.5, (1, 2)),
        R.COMPRESSED_IMAGE: R.encode_compressed_image(1, "c", "jpeg", b"xyz"),
        R.CAMERA_INFO: R.encode_camera_info(1, "c_optical", 64, 48, K),
        R.STRING: R.encode_string("drive"),
    }
    p = tmp_path / "all.mcap"
    w = McapStreamWriter(p)
    for k, (typ, data) in enumerate(samples.items()):
        cid = w.add_channel(f"/t{k}", w.add_schema(typ, "ros2msg", R.schema_text(typ).encode()))
        w.add_message(cid, 1, data)
    w.close()
    with open(p, "rb") as f:
        reader = make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        got = {s.name: m for s, _, _, m in reader.iter_decoded_messages()}
    assert got[R.ODOMETRY].pose.pose.position.x == 1.5
    assert got[R.ODOMETRY].twist.twist.angular.z == 0.3
    assert got[R.TF_MESSAGE].transforms[0].child_frame_id == "o"
    assert list(got[R.LASER_SCAN].ranges) == [1.0, 2.0]
    assert list(got[R.OCCUPANCY_GRID].data) == [0, 100]
    assert got[R.OCCUPANCY_GRID].info.origin.position.y == 2.0
    assert bytes(got[R.COMPRESSED_IMAGE].data) == b"xyz"
    info = got[R.CAMERA_INFO]
    assert (info.width, info.height, info.distortion_model) == (64, 48, "plumb_bob")
    assert list(info.k) == K.ravel().tolist() and list(info.d) == [0.0] * 5
    assert list(info.p) == [32.0, 0.0, 31.5, 0.0, 0.0, 32.0, 23.5, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert info.roi.do_rectify is False and info.header.frame_id == "c_optical"
    assert got[R.STRING].data == "drive"


def test_recording_reads_a_cut_file_through_a_repaired_copy(tmp_path):
    from agvsim.record.mcap_reader import Recording, RecordingError

    p = tmp_path / "c.mcap"
    _write(p, close=False, n=100)
    data = p.read_bytes()
    chunk2 = [off for op, off, _ in scan_records(p)[0] if op == 6][1]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunk2 + 100])
    with pytest.warns(UserWarning, match="cut off"):
        rec = Recording(cut)
    assert rec.repaired and cut.read_bytes() == data[: chunk2 + 100]  # the original untouched
    t, poses, _ = rec.odometry("/r/odom")
    np.testing.assert_allclose(poses[:, 0], np.arange(50) * 0.1)
    with pytest.raises(RecordingError, match="no topic '/nope'; topics: /r/odom"):
        rec.odometry("/nope")
    (tmp_path / "junk.mcap").write_bytes(b"hello")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        Recording(tmp_path / "junk.mcap")


def test_joint_state_bytes_equal_rosbags():
    t = 1_500_000_000
    names, pos, vel, eff = ["a/left_wheel", "a/right_wheel"], [0.1, 0.2], [1.0, -2.0], [0.5, 0.3]
    for effort in (eff, []):
        ours = R.encode_joint_state(t, "a/base_link", names, pos, vel, effort)
        ref = T["sensor_msgs/msg/JointState"](
            header=_hdr(t, "a/base_link"),
            name=names,
            position=np.array(pos),
            velocity=np.array(vel),
            effort=np.array(effort if effort else [], dtype=np.float64),
        )
        assert ours == bytes(TS.serialize_cdr(ref, R.JOINT_STATE))


@pytest.mark.parametrize("frame", ["a/base_link", "robot_12/base_link"])
def test_footprint_marker_array_bytes_equal_rosbags(frame):
    t = 2_000_000_000
    P, C = T["geometry_msgs/msg/Point"], T["std_msgs/msg/ColorRGBA"]
    outlines = [
        (frame, "a", [(0.3, 0.2), (-0.3, 0.2), (-0.3, -0.2), (0.3, -0.2)], (1.0, 0.5, 0.25)),
        ("bb/base_link", "bb", [(0.5, 0.1), (-0.1, 0.1), (-0.1, -0.1)], (0.0, 0.0, 1.0)),
    ]
    empty = np.array([], dtype=np.uint8)

    def marker(i, frame_id, ns, corners, rgb):
        return T["visualization_msgs/msg/Marker"](
            header=_hdr(t, frame_id), ns=ns, id=i, type=4, action=0, pose=_pose(0.0, 0.0, 0.0),
            scale=T["geometry_msgs/msg/Vector3"](x=0.02, y=0.0, z=0.0),
            color=C(r=rgb[0], g=rgb[1], b=rgb[2], a=1.0),
            lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=True,
            points=[P(x=x, y=y, z=0.0) for x, y in [*corners, corners[0]]], colors=[],
            texture_resource="",
            texture=T["sensor_msgs/msg/CompressedImage"](header=_hdr(0, ""), format="", data=empty),
            uv_coordinates=[], text="", mesh_resource="",
            mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=empty),
            mesh_use_embedded_materials=False,
        )  # fmt: skip

    ref = T["visualization_msgs/msg/MarkerArray"](
        markers=[marker(i, *o) for i, o in enumerate(outlines)]
    )
    assert R.encode_footprints(t, outlines) == bytes(TS.serialize_cdr(ref, R.MARKER_ARRAY))
