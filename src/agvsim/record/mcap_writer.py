"""Record a simulation to MCAP with ROS 2 message layouts (see docs/recording.md).

    rec = Recorder("run.mcap", sim, scenario_yaml=text)   # writes the static topics at t
    for _ in range(n):
        sim.step()
        rec.record()                                      # what changed this step
    rec.close()                                           # summary and index

Topics (``<robot>`` and ``<sensor>`` are the names from the scenario, characters outside
``[A-Za-z0-9_]`` replaced by ``_``):

==============================  ===========================  ==================================
topic                           type                         when
==============================  ===========================  ==================================
/agvsim/scenario                std_msgs/String              once, t = 0: the scenario YAML
/tf_static                      tf2_msgs/TFMessage           once: base_link -> each sensor
                                                             (cameras in 3D, + _optical)
/map                            nav_msgs/OccupancyGrid       t = 0 and whenever the walls change
/tf                             tf2_msgs/TFMessage           pose rate: map -> odom -> base_link
/<robot>/ground_truth           nav_msgs/Odometry            pose rate (map frame)
/<robot>/odom                   nav_msgs/Odometry            pose rate (<robot>/odom frame)
/<robot>/<sensor>               sensor_msgs/LaserScan        each time the sensor fires
/<robot>/state                  std_msgs/String              when the controller state changes
/<robot>/joint_states           sensor_msgs/JointState       pose rate: each wheel (accumulated
                                                             angle, speed, torque with dynamics)
                                                             and steered wheel (angle, rate)
/agvsim/footprints              visualization_msgs/          once: each robot's body outline in
                                MarkerArray                  its base_link frame
/<robot>/<camera>/image/...     sensor_msgs/CompressedImage  every camera frame (JPEG)
/<robot>/<camera>/camera_info   sensor_msgs/CameraInfo       with every frame (its intrinsics K)
/<robot>/slam/map               nav_msgs/OccupancyGrid       ``write_slam_map`` (online SLAM)
/<robot>/wheel_slip             std_msgs/Float64MultiArray   pose rate, robots with dynamics:
                                                             slip speed of each wheel (m/s)
/<robot>/safety_fields          visualization_msgs/          robots with a safety scanner, when
                                MarkerArray                  the active field set or its status
                                                             changes: its polygons (base_link),
                                                             green / yellow / red by status
/<robot>/safety_status          std_msgs/String              with it: clear, warning, protective
==============================  ===========================  ==================================

LaserScan carries ``intensities`` when the world has reflectors (empty otherwise); the
guidance topics (line sensors, floor-code fixes, pose estimates) are listed in
``agvsim.record.guidance_topics``.

Message times (log, publish and header stamps) are the simulated time, from 0. The file is
streamed: a chunk is written at least every ``flush_sim_s`` simulated seconds and every
``flush_wall_s`` wall seconds, and the file is valid after each (see ``mcap_file``).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from agvsim.record import ros2msg as msg
from agvsim.record.guidance_topics import GuidanceTopics
from agvsim.record.mcap_file import McapStreamWriter
from agvsim.record.ros2msg import topic_name

__all__ = ["Recorder", "odom_twists", "scenario_yaml", "topic_name"]


def odom_twists(p0: np.ndarray, p1: np.ndarray, dt_s: float) -> np.ndarray:
    """The constant body twists (N, 3) that carry poses ``p0`` to ``p1`` (N, 3) in ``dt_s``:
    the SE(2) logarithm of the relative motion over the time (exact for the simulator's
    constant-twist steps)."""
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    c, s = np.cos(p0[:, 2]), np.sin(p0[:, 2])
    d = p1 - p0
    rx, ry = c * d[:, 0] + s * d[:, 1], c * d[:, 1] - s * d[:, 0]  # in the frame of p0
    # the wrapped turn, in [-pi, pi): the one formula not agvsim.angles.wrap_angle, because the
    # recorded /odom twists were written with its rounding (the other differs in the last bit)
    a = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    # V(a)^-1 (rx, ry) with V = [[sin a / a, -(1 - cos a) / a], [(1 - cos a) / a, sin a / a]]:
    # (a / 2) [[cot(a / 2), 1], [-1, cot(a / 2)]] (rx, ry); a -> 0 gives (rx, ry)
    h = 0.5 * a
    small = np.abs(h) < 1e-6
    hc = np.where(small, 1.0 - h * h / 3.0, h / np.tan(np.where(small, 1.0, h)))  # h cot h
    out = np.empty_like(p0)
    out[:, 0] = hc * rx + h * ry
    out[:, 1] = hc * ry - h * rx
    out[:, 2] = a
    return out / dt_s


def _ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


def _grid_cells_ros(occupied: np.ndarray) -> np.ndarray:
    """Our ``occupied[row, col]`` (row 0 north) -> ROS cells (row 0 south), 0 / 100."""
    return np.ascontiguousarray(occupied[::-1]).astype(np.int8) * np.int8(100)


class Recorder:
    """Records a ``Simulation`` into ``path`` (an ``.mcap`` file, ROS 2 layouts).

    ``pose_rate_hz`` caps how often /tf and the odometry topics are written (every step when
    the step is longer); scans follow each sensor's rate. The constructor writes the static
    topics and the state at the current time."""

    def __init__(
        self,
        path: str | Path,
        sim,
        scenario_yaml: str | None = None,
        *,
        pose_rate_hz: float = 50.0,
        flush_sim_s: float = 1.0,
        flush_wall_s: float = 1.0,
        compression: str = "lz4",
        metadata: dict[str, str] | None = None,
    ):
        if not pose_rate_hz > 0:
            raise ValueError(f"pose_rate_hz must be > 0, got {pose_rate_hz}")
        self.sim = sim
        self.path = Path(path)
        self.pose_period_s = 1.0 / pose_rate_hz
        self.flush_sim_s, self.flush_wall_s = float(flush_sim_s), float(flush_wall_s)
        self.writer = McapStreamWriter(self.path, compression=compression)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.robot_topics = [topic_name(r.name) for r in sim.robots]
        tab = sim.sensors
        self._scan_topics = [
            f"/{self.robot_topics[int(tab.owner[s])]}/{topic_name(tab.specs[s].name)}"
            for s in range(tab.count)
        ]
        self._scan_frames = [t[1:] for t in self._scan_topics]
        self._scan_channels = [
            (
                self._channel(self._scan_topics[s], msg.LASER_SCAN),
                msg.LaserScanEncoder(
                    self._scan_frames[s],
                    sp.angle_min_rad,
                    sp.angle_increment_rad,
                    sp.range_min_m,
                    sp.range_max_m,
                    1.0 / sp.rate_hz,
                    sp.num_beams,
                ),
            )
            for s, sp in enumerate(tab.specs)
        ]
        self._pose_channels = [
            (
                self._channel(f"/{rt}/ground_truth", msg.ODOMETRY),
                self._channel(f"/{rt}/odom", msg.ODOMETRY),
                msg.OdometryEncoder("map", f"{rt}/base_link"),
                msg.OdometryEncoder(f"{rt}/odom", f"{rt}/base_link"),
            )
            for rt in self.robot_topics
        ]
        pairs = []
        for rt in self.robot_topics:
            pairs += [("map", f"{rt}/odom"), (f"{rt}/odom", f"{rt}/base_link")]
        dyn = sim.dynamics
        self._wheel_rows = [] if dyn is None else [int(i) for i in dyn.idx]
        self._tf = msg.TfEncoder(pairs)
        self._joint_channels = [self._channel(f"/{rt}/joint_states", msg.JOINT_STATE)
                                for rt in self.robot_topics]  # fmt: skip
        self._joint_names = [
            [f"{rt}/{w}_wheel" for w in r.model.wheel_names]
            + [f"{rt}/{r.model.wheel_names[k]}_steer" for k in r.model.steered_wheels]
            for rt, r in zip(self.robot_topics, sim.robots, strict=True)
        ]
        self._prev_steer: tuple[float, np.ndarray] | None = None
        self._tf_channel = self._channel("/tf", msg.TF_MESSAGE)
        frames = sim_frames(sim)
        self._camera_seq = {f.slot: 0 for f in frames}
        self._camera_names = {
            f.slot: f"{topic_name(f.robot_name)}/{topic_name(f.camera)}" for f in frames
        }
        self._camera_info: dict[int, msg.CameraInfoEncoder] = {}
        for f in frames:  # intrinsics K as the renderer uses them (CameraSpec.K)
            spec = self._camera_spec(f)
            optical = f"{self._camera_names[f.slot]}_optical"
            self._camera_info[f.slot] = msg.CameraInfoEncoder(
                optical, spec.width_px, spec.height_px, spec.K
            )
        self._last_scan = np.full(tab.count, -np.inf)
        self._last_states: list[str | None] = [None] * sim.n
        self._last_safety: dict[int, tuple[int, int]] = {}  # robot -> (set, status) written
        self._grid = None
        self._next_pose_s = -np.inf
        self._recorded_s = -np.inf
        self._prev_odom: tuple[float, np.ndarray] | None = None
        self._last_flush_s = sim.state.t_s
        self._last_flush_wall = time.perf_counter()
        # guidance sensors and pose estimates (docs/guidance.md): only where a run has them
        self._guidance = GuidanceTopics(self, sim) if GuidanceTopics.needed(sim) else None
        meta = {"format": "agvsim recording 1", "dt_s": repr(sim.dt_s), "seed": str(sim.seed)}
        meta["robots"] = ",".join(r.name for r in sim.robots)
        if scenario_yaml is not None:
            meta["scenario_yaml"] = scenario_yaml
        meta.update(metadata or {})
        self.writer.add_metadata("agvsim", meta)
        t_ns = _ns(sim.state.t_s)
        if scenario_yaml is not None:
            self._write("/agvsim/scenario", msg.STRING, t_ns, msg.encode_string(scenario_yaml))
        self._write_tf_static(t_ns)
        self._write_footprints(t_ns)
        self.record()
        self.writer.flush()

    # ------------------------------------------------------------------ channels
    def _channel(self, topic: str, type_name: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(type_name)
            if sid is None:
                text = msg.schema_text(type_name).encode()
                sid = self.writer.add_schema(type_name, "ros2msg", text)
                self._schemas[type_name] = sid
            cid = self.writer.add_channel(topic, sid, "cdr")
            self._channels[topic] = cid
        return cid

    def _write(self, topic: str, type_name: str, t_ns: int, data: bytes) -> None:
        self.writer.add_message(self._channel(topic, type_name), t_ns, data)

    # ------------------------------------------------------------------ static topics
    def _write_tf_static(self, t_ns: int) -> None:
        """``<robot>/base_link`` -> each range sensor (planar: x, y, yaw) and each camera (x,
        y, z, yaw then pitch, REP-103 body axes), and camera -> ``<camera>_optical`` (z
        forward, x right, y down: the frame of its images)."""
        tab = self.sim.sensors
        tfs: list[msg.Transform3D] = []
        for s in range(tab.count):
            base = f"{self.robot_topics[int(tab.owner[s])]}/base_link"
            mx, my, myaw = (float(v) for v in tab.mount[s])
            tfs.append((base, self._scan_frames[s], (mx, my, 0.0), msg.yaw_quaternion(myaw)))
        for f in sim_frames(self.sim):
            spec = self._camera_spec(f)
            base = f"{self.robot_topics[f.robot]}/base_link"
            cam = self._camera_names[f.slot]
            x, y = (float(v) for v in spec.mount_xy_m)
            q = msg.yaw_pitch_quaternion(spec.mount_yaw_rad, spec.pitch_rad)
            tfs.append((base, cam, (x, y, float(spec.mount_z_m)), q))
            tfs.append((cam, f"{cam}_optical", (0.0, 0.0, 0.0), msg.OPTICAL_QUATERNION))
        if tfs:
            self._write("/tf_static", msg.TF_MESSAGE, t_ns, msg.encode_tf_3d(t_ns, tfs))

    def _write_footprints(self, t_ns: int) -> None:
        """Each robot's rectangular body outline in its ``base_link`` frame (reference point
        P at the origin, the body centre ``body_offset_x_m`` ahead), in the robot's colour."""
        from matplotlib.colors import to_rgb  # colours are checked when the scenario loads

        markers = []
        for rt, r in zip(self.robot_topics, self.sim.robots, strict=True):
            hl, hw = r.footprint_half_m
            x0 = r.body_offset_x_m
            corners = [(x0 + hl, hw), (x0 - hl, hw), (x0 - hl, -hw), (x0 + hl, -hw)]
            markers.append((f"{rt}/base_link", rt, corners, to_rgb(r.color)))
        if markers:
            self._write("/agvsim/footprints", msg.MARKER_ARRAY, t_ns,
                        msg.encode_footprints(t_ns, markers))  # fmt: skip

    def _write_joints(self, t_s: float, t_ns: int) -> None:
        st = self.sim.state
        steer = st.steer_angles
        if self._prev_steer is None or t_s <= self._prev_steer[0]:
            steer_rate = np.zeros_like(steer)
        else:
            steer_rate = (steer - self._prev_steer[1]) / (t_s - self._prev_steer[0])
        self._prev_steer = (t_s, steer.copy())
        torque = st.wheel_torque_nm
        for i, r in enumerate(self.sim.robots):
            w, k = len(r.model.wheel_names), len(r.model.steered_wheels)
            effort: list[float] = []  # unknown without dynamics: empty, as ROS allows
            if r.dynamics is not None and torque.shape[0] == self.sim.n:
                effort = torque[i, :w].tolist() + [0.0] * k
            data = msg.encode_joint_state(
                t_ns,
                f"{self.robot_topics[i]}/base_link",
                self._joint_names[i],
                st.wheel_angles[i, :w].tolist() + steer[i, :k].tolist(),
                st.wheel_speeds[i, :w].tolist() + steer_rate[i, :k].tolist(),
                effort,
            )
            self.writer.add_message(self._joint_channels[i], t_ns, data)

    # ------------------------------------------------------------------ every step
    def record(self) -> None:
        """Write what is due at the simulation's current time."""
        sim = self.sim
        st = sim.state
        t_s = st.t_s
        t_ns = _ns(t_s)
        self._recorded_s = t_s
        if sim.world.grid is not self._grid:
            self._grid = g = sim.world.grid
            self.write_occupancy("/map", t_s, _grid_cells_ros(g.occupied), g.resolution_m,
                                 g.origin_xy_m, trinary=True)  # fmt: skip
        if t_s >= self._next_pose_s - 1e-9:
            self._write_poses(t_s, t_ns)
            self._write_joints(t_s, t_ns)
            self._write_slip(t_ns)
            if self._guidance is not None:
                self._guidance.write(t_ns)
            self._next_pose_s = t_s + self.pose_period_s
        self._write_scans(t_ns)
        if self._camera_seq:
            self._write_cameras()
        self._write_states(t_ns)
        if sim.safety is not None:
            self._write_safety(t_ns)
        wall = time.perf_counter()
        if (
            t_s - self._last_flush_s >= self.flush_sim_s - 1e-9
            or wall - self._last_flush_wall >= self.flush_wall_s
            or self.writer.chunk_bytes > (8 << 20)
        ):
            self.flush()

    def flush(self) -> None:
        """Write the collected messages now; the file on disk is complete afterwards."""
        self.writer.flush()
        self._last_flush_s = self.sim.state.t_s
        self._last_flush_wall = time.perf_counter()

    def _write_poses(self, t_s: float, t_ns: int) -> None:
        st = self.sim.state
        gt, odo, tw = st.poses, st.odom_poses, st.twists
        if self._prev_odom is None or t_s <= self._prev_odom[0]:
            otw = np.zeros_like(odo)
        else:
            otw = odom_twists(self._prev_odom[1], odo, t_s - self._prev_odom[0])
        self._prev_odom = (t_s, odo.copy())
        # map -> odom = T_map_base(ground truth) * inverse(T_odom_base(odometry))
        dth = gt[:, 2] - odo[:, 2]
        c, s = np.cos(dth), np.sin(dth)
        tf = np.empty((2 * len(gt), 3))
        tf[0::2, 0] = gt[:, 0] - (c * odo[:, 0] - s * odo[:, 1])
        tf[0::2, 1] = gt[:, 1] - (s * odo[:, 0] + c * odo[:, 1])
        tf[0::2, 2] = dth
        tf[1::2] = odo
        write = self.writer.add_message
        gt_l, odo_l, tw_l, otw_l = gt.tolist(), odo.tolist(), tw.tolist(), otw.tolist()
        for i, (c_gt, c_odo, e_gt, e_odo) in enumerate(self._pose_channels):
            write(c_gt, t_ns, e_gt.encode(t_ns, gt_l[i], tw_l[i]))
            write(c_odo, t_ns, e_odo.encode(t_ns, odo_l[i], otw_l[i]))
        write(self._tf_channel, t_ns, self._tf.encode(t_ns, tf))

    def _write_slip(self, t_ns: int) -> None:
        """The slip speed of each wheel (m/s) of the robots with dynamics."""
        st = self.sim.state
        for i in self._wheel_rows:
            rt, n = self.robot_topics[i], len(self.sim.robots[i].model.wheel_names)
            slip = msg.encode_float64_multi_array("wheel", st.wheel_slip_m_s[i, :n].tolist())
            self._write(f"/{rt}/wheel_slip", msg.FLOAT64_MULTI_ARRAY, t_ns, slip)

    def _write_scans(self, t_ns: int) -> None:
        st, tab = self.sim.state, self.sim.sensors
        if tab.count == 0:
            return
        fresh = np.flatnonzero(st.scan_stamp > self._last_scan)
        inten = st.intensities if st.intensities.size else None  # a world with reflectors
        for s in fresh.tolist():
            cid, enc = self._scan_channels[s]
            stamp = _ns(float(st.scan_stamp[s]))
            b = enc.num_beams
            data = enc.encode(stamp, st.scans[s, :b], None if inten is None else inten[s, :b])
            self.writer.add_message(cid, stamp, data)
        self._last_scan[fresh] = st.scan_stamp[fresh]

    def _camera_spec(self, frame):
        cameras = self.sim.robots[frame.robot].cameras
        return cameras[[c.name for c in cameras].index(frame.camera)]

    def _write_cameras(self) -> None:
        """Each new frame as a JPEG ``CompressedImage`` and its ``CameraInfo`` (same stamp and
        frame, one per image as ROS drivers publish them)."""
        for f in sim_frames(self.sim):
            if f.seq > self._camera_seq[f.slot]:
                self._camera_seq[f.slot] = f.seq
                name = self._camera_names[f.slot]
                topic, frame = f"/{name}/image/compressed", f"{name}_optical"
                self.write_image(topic, f.stamp_s, frame, f.rgb, "jpeg")
                t_ns = _ns(f.stamp_s)
                info = self._camera_info[f.slot].encode(t_ns)
                self._write(f"/{name}/camera_info", msg.CAMERA_INFO, t_ns, info)

    def _write_states(self, t_ns: int) -> None:
        states = self.sim.active_states()
        for i, name in enumerate(states):
            if name != self._last_states[i]:
                if name or self._last_states[i] is not None:
                    topic = f"/{self.robot_topics[i]}/state"
                    self._write(topic, msg.STRING, t_ns, msg.encode_string(name))
                self._last_states[i] = name

    def _write_safety(self, t_ns: int) -> None:
        """Each scanner's active field set, coloured by its status, when either changes."""
        from agvsim.sensors.safety_fields import STATUS_NAMES
        from agvsim.sim.safety import STATUS_RGB, set_polygons

        st = self.sim.state
        for i in self.sim.safety.robots.tolist():
            now = (int(st.safety_set[i]), int(st.safety_status[i]))
            if self._last_safety.get(i) == now:
                continue
            self._last_safety[i] = now
            rt, spec = self.robot_topics[i], self.sim.robots[i].safety
            rgb = STATUS_RGB[now[1]]
            markers = [
                (f"{rt}/base_link", f"{rt}/{kind}", list(poly), rgb)
                for kind, poly in set_polygons(spec, now[0])
            ]
            self._write(f"/{rt}/safety_fields", msg.MARKER_ARRAY, t_ns,
                        msg.encode_footprints(t_ns, markers))  # fmt: skip
            status = msg.encode_string(STATUS_NAMES[now[1]])
            self._write(f"/{rt}/safety_status", msg.STRING, t_ns, status)

    # ------------------------------------------------------------------ public extras
    def write_occupancy(
        self,
        topic: str,
        t_s: float,
        occupancy: np.ndarray,
        resolution_m: float,
        origin_xy: tuple[float, float],
        *,
        frame_id: str = "map",
        trinary: bool = False,
    ) -> None:
        """Write a ``nav_msgs/OccupancyGrid`` on ``topic`` (e.g. ``/<robot>/slam/map``).

        ``occupancy`` is (rows, cols) with **row 0 north** (our map layout): floats are
        occupancy probabilities in [0, 1] (NaN = unknown), written as 0..100 (-1); integers are
        ROS cell values already (0 free, 100 occupied, -1 unknown). ``trinary=True`` takes ROS
        cell values in ROS row order (row 0 south), as ``/map`` is built. ``origin_xy`` is the
        map's lower-left corner (m)."""
        occ = np.asarray(occupancy)
        if occ.ndim != 2:
            raise ValueError(f"{topic}: occupancy must be a 2-D array, got shape {occ.shape}")
        if trinary or np.issubdtype(occ.dtype, np.integer):
            bad = (occ < -1) | (occ > 100)
            if bad.any():
                raise ValueError(
                    f"{topic}: occupancy cell values must be -1 (unknown) or 0..100, got "
                    f"{occ[bad].ravel()[0]}"
                )
            cells = occ.astype(np.int8)
            if not trinary:
                cells = np.ascontiguousarray(cells[::-1])
        else:
            p = occ.astype(np.float64)[::-1]
            cells = np.where(np.isfinite(p), np.rint(np.clip(p, 0.0, 1.0) * 100), -1)
            cells = cells.astype(np.int8)
        t_ns = _ns(t_s)
        data = msg.encode_occupancy_grid(t_ns, frame_id, cells, resolution_m, origin_xy)
        self._write(topic, msg.OCCUPANCY_GRID, t_ns, data)

    def write_slam_map(self, robot: str, t_s: float, occupancy_map) -> None:
        """A SLAM map (``agvsim.slam.mapping.OccupancyMap``: log-odds ``[iy, ix]``, row 0
        south) on ``/<robot>/slam/map``, frame ``map``."""
        prob = occupancy_map.probability[::-1]  # to row 0 north
        known = occupancy_map.logodds[::-1] != 0
        self.write_occupancy(
            f"/{topic_name(robot)}/slam/map",
            t_s,
            np.where(known, prob, np.nan),
            occupancy_map.resolution_m,
            occupancy_map.origin_xy_m,
        )

    def write_image(
        self, topic: str, t_s: float, frame_id: str, image: np.ndarray | bytes, fmt: str = "jpeg"
    ) -> None:
        """Write a ``sensor_msgs/CompressedImage``: ``image`` is (H, W, 3) uint8 RGB (encoded
        here as ``fmt``, ``"jpeg"`` or ``"png"``) or already encoded bytes. The camera hook:
        topic ``/<robot>/<camera>/image/compressed``, frame ``<robot>/<camera>_optical``."""
        if fmt not in ("jpeg", "png"):
            raise ValueError(f"{topic}: image format must be 'jpeg' or 'png', got {fmt!r}")
        if isinstance(image, bytes | bytearray):
            data = bytes(image)
        else:
            data = encode_image(np.asarray(image), fmt)
        t_ns = _ns(t_s)
        self._write(topic, msg.COMPRESSED_IMAGE, t_ns,
                    msg.encode_compressed_image(t_ns, frame_id, fmt, data))  # fmt: skip

    def close(self) -> None:
        """Write the last messages, the summary and the footer (idempotent). A step that ran
        but was not recorded (Ctrl-C between the two) is recorded first."""
        if not self.writer.closed and self.sim.state.t_s > self._recorded_s:
            self.record()
        self.writer.close()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SlamMaps:
    """Writes each online SLAM's final map on ``/<robot>/slam/map`` when the run ends (put it
    before the recorder in the runner's observers, so it closes first)."""

    def __init__(self, recorder: Recorder, slams: list):
        self.recorder, self.slams = recorder, slams

    def record(self) -> None:
        pass

    def close(self) -> None:
        for s in self.slams:
            if s.slam.keyframes:  # final_map() finishes the SLAM; its summary reuses the map
                self.recorder.write_slam_map(s.name, self.recorder.sim.state.t_s, s.final_map())


def scenario_yaml(sc, seed: int | None = None) -> str:
    """The scenario as YAML (the keys the user set), with the run's ``seed``."""
    import yaml

    data = sc.model_dump(mode="json", exclude_unset=True)
    if seed is not None:
        data["seed"] = int(seed)
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, width=100)


def sim_frames(sim) -> list:
    """The simulation's latest camera frames (none for a simulation without cameras)."""
    return sim.camera_frames() if hasattr(sim, "camera_frames") else []


def encode_image(rgb: np.ndarray, fmt: str = "jpeg", quality: int = 85) -> bytes:
    """(H, W, 3) uint8 -> JPEG or PNG bytes (Pillow)."""
    import io

    from PIL import Image

    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"an image must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    buf = io.BytesIO()
    if fmt == "jpeg":
        Image.fromarray(rgb).save(buf, format="JPEG", quality=quality)
    else:
        Image.fromarray(rgb).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()
