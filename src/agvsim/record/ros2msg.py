"""ROS 2 message layouts without ROS: the ``ros2msg`` schema texts and fast CDR encoders.

An MCAP file with the ``ros2`` profile stores each message as CDR (little-endian XCDR1, a
4-byte encapsulation header ``00 01 00 00``, every primitive aligned to its size counted from the
end of that header) and each channel's schema as the ROS 2 ``.msg`` text of the type followed by
the texts of every type it uses (``====`` separator lines and ``MSG: pkg/Type``), as
``ros2 bag record`` writes them. Readers such as ``rosbags``, ``mcap-ros2-support`` and Foxglove
rebuild the types from that text, so no ROS installation is needed on either side.

The encoders take plain numbers and NumPy arrays and pack them with ``struct`` (a few
microseconds a message); ``tests/test_record_cdr.py`` checks their bytes against rosbags'
serializer for every type.
"""

from __future__ import annotations

import math
import re
import struct

import numpy as np

# ---------------------------------------------------------------------- schema texts
_DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    "geometry_msgs/PoseWithCovariance": "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    "geometry_msgs/TwistWithCovariance": "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/Transform": (
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
    ),
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
    ),
    "nav_msgs/MapMetaData": (
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
        "uint32 height\ngeometry_msgs/Pose origin\n"
    ),
    "nav_msgs/OccupancyGrid": "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n",
    "sensor_msgs/LaserScan": (
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n"
    ),
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data\n",
    "sensor_msgs/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\n"
        "float64[] d\nfloat64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\n"
        "uint32 binning_y\nsensor_msgs/RegionOfInterest roi\n"
    ),
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n"
    ),
    "std_msgs/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "visualization_msgs/UVCoordinate": "float32 u\nfloat32 v\n",
    "visualization_msgs/MeshFile": "string filename\nuint8[] data\n",
    # the layout of rosbags' ROS 2 Humble store (texture and mesh_file fields included)
    "visualization_msgs/Marker": (
        "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n"
        "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n"
        "builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n"
        "std_msgs/ColorRGBA[] colors\nstring texture_resource\n"
        "sensor_msgs/CompressedImage texture\n"
        "visualization_msgs/UVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\n"
        "visualization_msgs/MeshFile mesh_file\nbool mesh_use_embedded_materials\n"
    ),
    "visualization_msgs/MarkerArray": "visualization_msgs/Marker[] markers\n",
    "std_msgs/MultiArrayDimension": "string label\nuint32 size\nuint32 stride\n",
    "std_msgs/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
    "std_msgs/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data\n",
}

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"
LASER_SCAN = "sensor_msgs/msg/LaserScan"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
STRING = "std_msgs/msg/String"
JOINT_STATE = "sensor_msgs/msg/JointState"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
TYPES = (
    TF_MESSAGE, ODOMETRY, LASER_SCAN, OCCUPANCY_GRID, COMPRESSED_IMAGE, CAMERA_INFO, STRING,
    JOINT_STATE, MARKER_ARRAY, FLOAT64_MULTI_ARRAY,
)  # fmt: skip

_SEP = "=" * 80 + "\n"
_BAD = re.compile(r"[^A-Za-z0-9_]")


def topic_name(name: str) -> str:
    """A robot or sensor name as a ROS name part: characters outside ``[A-Za-z0-9_]`` become
    ``_``; a leading digit gets a ``_`` in front."""
    s = _BAD.sub("_", name) or "_"
    return "_" + s if s[0].isdigit() else s


def _short(type_name: str) -> str:
    """``pkg/msg/Type`` -> ``pkg/Type``."""
    pkg, _, name = type_name.partition("/msg/")
    return f"{pkg}/{name}" if name else type_name


def _uses(short: str) -> list[str]:
    out = []
    for line in _DEFS[short].splitlines():
        field_type = line.split()[0].split("[")[0]
        if "/" in field_type:
            out.append(field_type)
    return out


def schema_text(type_name: str) -> str:
    """The ``ros2msg`` schema of ``type_name`` (``pkg/msg/Type``): its own text, then each type
    it depends on (depth first, once each) after a separator line and ``MSG: pkg/Type``."""
    top = _short(type_name)
    if top not in _DEFS:
        raise KeyError(f"no ROS 2 definition for {type_name!r}; known: {sorted(_DEFS)}")
    seen: list[str] = []

    def visit(t: str) -> None:
        for dep in _uses(t):
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(top)
    parts = [_DEFS[top]] + [f"{_SEP}MSG: {d}\n{_DEFS[d]}" for d in seen]
    return "".join(parts)


# ---------------------------------------------------------------------- CDR encoding
_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR little endian
_ZERO36 = struct.pack("<36d", *([0.0] * 36))


class Cdr:
    """A growing CDR buffer; offsets for alignment count from after the 4-byte header."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(_ENCAPSULATION)

    def align(self, n: int) -> None:
        pad = (-(len(self.buf) - 4)) % n
        if pad:
            self.buf += b"\x00" * pad

    def u32(self, v: int) -> None:
        self.align(4)
        self.buf += struct.pack("<I", v)

    def string(self, s: str) -> None:
        b = s.encode()
        self.align(4)
        self.buf += struct.pack("<I", len(b) + 1)
        self.buf += b
        self.buf += b"\x00"

    def stamp(self, t_ns: int) -> None:
        self.align(4)
        sec, nsec = divmod(int(t_ns), 1_000_000_000)
        self.buf += struct.pack("<iI", sec, nsec)

    def header(self, t_ns: int, frame_id: str) -> None:
        self.stamp(t_ns)
        self.string(frame_id)

    def f64(self, *values: float) -> None:
        self.align(8)
        self.buf += struct.pack(f"<{len(values)}d", *values)

    def f32(self, *values: float) -> None:
        self.align(4)
        self.buf += struct.pack(f"<{len(values)}f", *values)

    def seq(self, data: bytes, count: int, elem_size: int) -> None:
        """A sequence: its element count, then the packed elements (already little endian)."""
        self.u32(count)
        if count:
            self.align(elem_size)
            self.buf += data

    def bytes(self) -> bytes:
        return bytes(self.buf)


def yaw_quaternion(theta: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``theta`` about z."""
    return (0.0, 0.0, math.sin(theta / 2.0), math.cos(theta / 2.0))


def encode_string(text: str) -> bytes:
    c = Cdr()
    c.string(text)
    return c.bytes()


def yaw_pitch_quaternion(yaw: float, pitch: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw`` about z, then by ``pitch`` about the turned y
    (REP-103 body axes x forward, y left, z up: a positive pitch tips x down), i.e.
    ``q_z(yaw) * q_y(pitch)``."""
    cy, sy = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    return (-sy * sp, cy * sp, sy * cp, cy * cp)


#: (x, y, z, w) from a camera's body frame (x forward, y left, z up) to its optical frame
#: (z forward, x right, y down), the fixed rotation of ROS's ``*_optical`` frames (REP-103)
OPTICAL_QUATERNION = (-0.5, 0.5, -0.5, 0.5)

Transform3D = tuple[str, str, tuple[float, float, float], tuple[float, float, float, float]]


def encode_tf(t_ns: int, transforms: list[tuple[str, str, float, float, float]]) -> bytes:
    """``tf2_msgs/TFMessage``: (parent, child, x, y, theta) planar transforms, z = 0."""
    return encode_tf_3d(
        t_ns, [(p, ch, (x, y, 0.0), yaw_quaternion(th)) for p, ch, x, y, th in transforms]
    )


def encode_tf_3d(t_ns: int, transforms: list[Transform3D]) -> bytes:
    """``tf2_msgs/TFMessage``: (parent, child, (x, y, z), (qx, qy, qz, qw)) transforms."""
    c = Cdr()
    c.u32(len(transforms))
    for parent, child, xyz, q in transforms:
        c.header(t_ns, parent)
        c.string(child)
        c.f64(*xyz, *q)
    return c.bytes()


def encode_joint_state(
    t_ns: int,
    frame_id: str,
    names: list[str],
    position: list[float],
    velocity: list[float],
    effort: list[float],
) -> bytes:
    """``sensor_msgs/JointState``: one entry per joint (rad, rad/s, N m)."""
    c = Cdr()
    c.header(t_ns, frame_id)
    c.u32(len(names))
    for n in names:
        c.string(n)
    for values in (position, velocity, effort):
        c.u32(len(values))
        if values:
            c.f64(*values)
    return c.bytes()


def encode_float64_multi_array(label: str, values: list[float]) -> bytes:
    """``std_msgs/Float64MultiArray`` with one dimension named ``label``."""
    c = Cdr()
    c.u32(1)
    c.string(label)
    c.u32(len(values))
    c.u32(1)
    c.u32(0)  # data_offset
    c.u32(len(values))
    if values:
        c.f64(*values)
    return c.bytes()


def encode_odometry(
    t_ns: int,
    frame_id: str,
    child_frame_id: str,
    pose: tuple[float, float, float],
    twist: tuple[float, float, float],
) -> bytes:
    """``nav_msgs/Odometry``: planar ``pose`` (x, y, theta) in ``frame_id`` and body ``twist``
    (vx, vy, omega) in ``child_frame_id``; covariances zero (not estimated)."""
    c = Cdr()
    c.header(t_ns, frame_id)
    c.string(child_frame_id)
    x, y, th = pose
    c.f64(x, y, 0.0, *yaw_quaternion(th))
    c.buf += _ZERO36
    vx, vy, om = twist
    c.f64(vx, vy, 0.0, 0.0, 0.0, om)
    c.buf += _ZERO36
    return c.bytes()


def encode_laser_scan(
    t_ns: int,
    frame_id: str,
    angle_min: float,
    angle_increment: float,
    range_min: float,
    range_max: float,
    scan_time: float,
    ranges: np.ndarray,
) -> bytes:
    """``sensor_msgs/LaserScan`` with float32 ranges (inf / -inf kept, REP-117), no
    intensities."""
    r = np.ascontiguousarray(ranges, dtype="<f4")
    n = int(r.size)
    c = Cdr()
    c.header(t_ns, frame_id)
    angle_max = angle_min + angle_increment * max(n - 1, 0)
    c.f32(angle_min, angle_max, angle_increment, 0.0, scan_time, range_min, range_max)
    c.seq(r.tobytes(), n, 4)
    c.u32(0)
    return c.bytes()


def encode_occupancy_grid(
    t_ns: int,
    frame_id: str,
    cells_ros: np.ndarray,
    resolution_m: float,
    origin_xy_m: tuple[float, float],
    load_time_ns: int | None = None,
) -> bytes:
    """``nav_msgs/OccupancyGrid``. ``cells_ros`` is (height, width) int8 in ROS order: row 0 at
    the map's origin (south), values 0 free, 100 occupied, -1 unknown."""
    cells = np.ascontiguousarray(cells_ros, dtype=np.int8)
    h, w = cells.shape
    c = Cdr()
    c.header(t_ns, frame_id)
    c.stamp(t_ns if load_time_ns is None else load_time_ns)
    c.f32(resolution_m)
    c.u32(w)
    c.u32(h)
    c.f64(float(origin_xy_m[0]), float(origin_xy_m[1]), 0.0, 0.0, 0.0, 0.0, 1.0)
    c.seq(cells.tobytes(), int(cells.size), 1)
    return c.bytes()


def encode_compressed_image(t_ns: int, frame_id: str, fmt: str, data: bytes) -> bytes:
    """``sensor_msgs/CompressedImage``: ``fmt`` is ``"jpeg"`` or ``"png"``."""
    c = Cdr()
    c.header(t_ns, frame_id)
    c.string(fmt)
    c.seq(bytes(data), len(data), 1)
    return c.bytes()


def encode_camera_info(
    t_ns: int, frame_id: str, width_px: int, height_px: int, K: np.ndarray
) -> bytes:
    """``sensor_msgs/CameraInfo`` of an ideal pinhole camera with the (3, 3) camera matrix
    ``K`` (OpenCV pixel convention, as ROS's): model ``plumb_bob`` with five zero distortion
    coefficients, ``r`` the identity, ``p = [K | 0]``, no binning, an empty (full) ROI."""
    k = np.asarray(K, dtype=np.float64)
    if k.shape != (3, 3):
        raise ValueError(f"K must be a (3, 3) camera matrix, got shape {k.shape}")
    c = Cdr()
    c.header(t_ns, frame_id)
    c.u32(height_px)
    c.u32(width_px)
    c.string("plumb_bob")
    c.seq(struct.pack("<5d", *([0.0] * 5)), 5, 8)  # d
    c.f64(*k.ravel().tolist())  # k
    c.f64(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)  # r
    c.f64(*np.column_stack([k, np.zeros(3)]).ravel().tolist())  # p
    for v in (0, 0, 0, 0, 0, 0):  # binning_x, binning_y, roi x_offset, y_offset, height, width
        c.u32(v)
    c.buf += b"\x00"  # roi.do_rectify = false
    return c.bytes()


LINE_STRIP = 4  # visualization_msgs/Marker.type


def encode_footprints(
    t_ns: int,
    markers: list[tuple[str, str, list[tuple[float, float]], tuple[float, float, float]]],
    line_width_m: float = 0.02,
) -> bytes:
    """``visualization_msgs/MarkerArray`` of closed ``LINE_STRIP`` outlines, one per
    ``(frame_id, ns, corners_xy_m, rgb)``: the corners in that frame (z = 0), the strip closed
    back to its first corner, opaque, frame-locked and without a lifetime (shown until
    replaced)."""
    c = Cdr()
    c.u32(len(markers))
    for marker_id, (frame_id, ns, corners, rgb) in enumerate(markers):
        c.header(t_ns, frame_id)
        c.string(ns)
        c.u32(marker_id)  # int32 id (non-negative here)
        c.u32(LINE_STRIP)
        c.u32(0)  # action ADD
        c.f64(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)  # pose: identity
        c.f64(line_width_m, 0.0, 0.0)  # scale.x: the line width
        c.f32(*rgb, 1.0)
        c.stamp(0)  # lifetime 0: forever
        c.buf += b"\x01"  # frame_locked
        closed = [*corners, corners[0]] if corners else []
        c.u32(len(closed))
        if closed:
            c.align(8)
            for x, y in closed:
                c.buf += struct.pack("<3d", x, y, 0.0)
        c.u32(0)  # colors
        c.string("")  # texture_resource
        c.header(0, "")  # texture: CompressedImage with an empty header, format and data
        c.string("")
        c.u32(0)
        c.u32(0)  # uv_coordinates
        c.string("")  # text
        c.string("")  # mesh_resource
        c.string("")  # mesh_file.filename
        c.u32(0)  # mesh_file.data
        c.buf += b"\x00"  # mesh_use_embedded_materials
    return c.bytes()


# ---------------------------------------------------------------------- template encoders
# A recorder writes the same frames again and again: only the stamp and the numbers change.
# These encoders build the message once and then patch the stamp and numbers in place.
_STAMP = struct.Struct("<iI")
_POSE7 = struct.Struct("<7d")
_TWIST6 = struct.Struct("<6d")


def _sec_nsec(t_ns: int) -> tuple[int, int]:
    return divmod(int(t_ns), 1_000_000_000)


class OdometryEncoder:
    """``nav_msgs/Odometry`` for fixed frames: ``encode(t_ns, pose, twist)``."""

    def __init__(self, frame_id: str, child_frame_id: str):
        self.template = encode_odometry(0, frame_id, child_frame_id, (0, 0, 0), (0, 0, 0))
        self._pose_off = len(self.template) - (7 + 36 + 6 + 36) * 8
        self._twist_off = self._pose_off + (7 + 36) * 8

    def encode(self, t_ns: int, pose, twist) -> bytes:
        buf = bytearray(self.template)
        _STAMP.pack_into(buf, 4, *_sec_nsec(t_ns))
        x, y, th = pose
        _POSE7.pack_into(buf, self._pose_off, x, y, 0.0, *yaw_quaternion(th))
        vx, vy, om = twist
        _TWIST6.pack_into(buf, self._twist_off, vx, vy, 0.0, 0.0, 0.0, om)
        return bytes(buf)


class LaserScanEncoder:
    """``sensor_msgs/LaserScan`` of one sensor (fixed frame, angles, limits, beam count):
    ``encode(t_ns, ranges)``."""

    def __init__(
        self,
        frame_id: str,
        angle_min: float,
        angle_increment: float,
        range_min: float,
        range_max: float,
        scan_time: float,
        num_beams: int,
    ):
        full = encode_laser_scan(
            0, frame_id, angle_min, angle_increment, range_min, range_max, scan_time,
            np.zeros(num_beams, np.float32),
        )  # fmt: skip
        self.num_beams = int(num_beams)
        self._head = full[4 + 8 : len(full) - 4 - 4 * self.num_beams]
        self._tail = b"\x00\x00\x00\x00"  # no intensities

    def encode(self, t_ns: int, ranges: np.ndarray, intensities: np.ndarray | None = None) -> bytes:
        """The scan; ``intensities`` (B,) go into the message's intensities (None: empty)."""
        r = np.asarray(ranges, dtype="<f4")
        if r.shape != (self.num_beams,):
            raise ValueError(f"expected {self.num_beams} ranges, got shape {r.shape}")
        tail = self._tail
        if intensities is not None:
            i = np.asarray(intensities, dtype="<f4")
            if i.shape != r.shape:
                raise ValueError(f"expected {self.num_beams} intensities, got shape {i.shape}")
            tail = struct.pack("<I", len(i)) + i.tobytes()
        return b"".join(
            (_ENCAPSULATION, _STAMP.pack(*_sec_nsec(t_ns)), self._head, r.tobytes(), tail)
        )


class CameraInfoEncoder:
    """``sensor_msgs/CameraInfo`` of one camera (fixed frame and intrinsics):
    ``encode(t_ns)``, the stamp being the only thing that changes."""

    def __init__(self, frame_id: str, width_px: int, height_px: int, K: np.ndarray):
        self.template = encode_camera_info(0, frame_id, width_px, height_px, K)

    def encode(self, t_ns: int) -> bytes:
        buf = bytearray(self.template)
        _STAMP.pack_into(buf, 4, *_sec_nsec(t_ns))
        return bytes(buf)


class TfEncoder:
    """``tf2_msgs/TFMessage`` of fixed (parent, child) frame pairs:
    ``encode(t_ns, values)`` with ``values`` (K, 3) x, y, theta per pair."""

    def __init__(self, pairs: list[tuple[str, str]]):
        c = Cdr()
        c.u32(len(pairs))
        self._stamps: list[int] = []
        self._poses: list[int] = []
        for parent, child in pairs:
            c.align(4)
            self._stamps.append(len(c.buf))
            c.header(0, parent)
            c.string(child)
            c.align(8)
            self._poses.append(len(c.buf))
            c.f64(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        self.template = c.bytes()

    def encode(self, t_ns: int, values: np.ndarray) -> bytes:
        buf = bytearray(self.template)
        sn = _sec_nsec(t_ns)
        v = np.asarray(values, dtype=np.float64)
        half = 0.5 * v[:, 2]
        qz, qw = np.sin(half), np.cos(half)
        for k, (so, po) in enumerate(zip(self._stamps, self._poses, strict=True)):
            _STAMP.pack_into(buf, so, *sn)
            _POSE7.pack_into(buf, po, v[k, 0], v[k, 1], 0.0, 0.0, 0.0, qz[k], qw[k])
        return bytes(buf)
