"""Read an agvsim recording (``run.mcap``) back into arrays, through ``rosbags``.

    rec = Recording("runs/x/run.mcap")
    t, poses, twists = rec.odometry("/differential/ground_truth")   # (T,), (T, 3), (T, 3)
    scans = rec.laser_scans("/differential/lidar")                  # ScanSeries (T scans)
    grids = rec.occupancy("/map")                                   # [GridMessage]

A file cut off in the middle of a write (the machine died) has no footer; it is repaired into
a temporary copy first (``mcap_file.repair``) and read from there. Nothing here imports the
simulator, so the offline SLAM can use it.
"""

from __future__ import annotations

import functools
import shutil
import tempfile
import warnings
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from agvsim.record.mcap_file import repair, scan_records
from agvsim.record.ros2msg import LASER_SCAN, OCCUPANCY_GRID, ODOMETRY, STRING, topic_name
from agvsim.scan import LaserScan

__all__ = ["GridMessage", "Recording", "RecordingError", "ScanSeries"]


class RecordingError(ValueError):
    """A recording that cannot be read, or a topic it does not hold."""


_F = TypeVar("_F", bound=Callable[..., Any])


def _reading(method: _F) -> _F:
    """Whatever a damaged file makes the decoder raise (struct, index, type, rosbags' own
    errors) becomes a RecordingError naming the file, the topic and the problem."""

    @functools.wraps(method)
    def wrapper(self: Recording, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except RecordingError:
            raise
        except Exception as err:  # noqa: BLE001 - any decoding failure of a damaged file
            topic = f" {args[0]}:" if args and isinstance(args[0], str) else ""
            raise RecordingError(
                f"{self.path}:{topic} the recording is damaged and cannot be decoded "
                f"({type(err).__name__}: {str(err)[:200]})"
            ) from None

    return wrapper  # type: ignore[return-value]


@dataclass(frozen=True)
class ScanSeries:
    """Every message of one ``sensor_msgs/LaserScan`` topic (one sensor): the batch form of
    :class:`agvsim.scan.LaserScan`, with its field names; ``scan(k)`` is the k-th scan."""

    frame_id: str
    stamp_s: np.ndarray  # (T,) header stamps
    ranges: np.ndarray  # (T, B) float64 (float32 values), inf / -inf kept
    angle_min_rad: float  # sensor frame
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    mount_pose: np.ndarray  # (3,) x, y, yaw of the sensor on the robot (/tf_static; 0 if absent)

    def __len__(self) -> int:
        return len(self.stamp_s)

    @property
    def angles_rad(self) -> np.ndarray:
        """(B,) beam directions in the sensor frame."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.ranges.shape[1])

    def scan(self, k: int) -> LaserScan:
        """The k-th scan (its ranges a copy)."""
        return LaserScan(
            float(self.stamp_s[k]),
            self.angle_min_rad,
            self.angle_increment_rad,
            self.range_min_m,
            self.range_max_m,
            self.ranges[k].copy(),
            self.mount_pose.copy(),
        )


@dataclass(frozen=True)
class GridMessage:
    """One ``nav_msgs/OccupancyGrid``: ``cells`` in ROS order (row 0 south), int8."""

    t_s: float
    frame_id: str
    cells: np.ndarray  # (height, width) int8: 0 free, 100 occupied, -1 unknown
    resolution_m: float
    origin_xy_m: tuple[float, float]

    @property
    def occupied(self) -> np.ndarray:
        """Our map layout: (rows, cols) bool, row 0 north, True where the cell is >= 50."""
        return np.ascontiguousarray(self.cells[::-1] >= 50)


def _yaw(q) -> float:
    """The heading of a rotation (its yaw in z-y-x Euler angles; a pure yaw for planar ones)."""
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


class Recording:
    """An MCAP file with ROS 2 messages (ours or anyone's), loaded once into memory as raw
    messages per topic; the accessors decode a topic on demand."""

    def __init__(self, path: str | Path):
        from rosbags.highlevel import AnyReader

        self.path = Path(path)
        if not self.path.is_file():
            raise RecordingError(f"{self.path}: no such recording")
        self.repaired = False
        readable, tmpdir = self._readable_copy()
        try:
            with AnyReader([readable]) as reader:
                self.types = {c.topic: c.msgtype for c in reader.connections}
                self._raw: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
                for conn, t_ns, raw in reader.messages():
                    self._raw[conn.topic].append((t_ns, bytes(raw)))
                self._store = reader.typestore
        except Exception as err:  # noqa: BLE001 - rosbags raises several kinds
            if isinstance(err, RecordingError):
                raise
            raise RecordingError(f"{self.path}: cannot read the recording: {err}") from None
        finally:
            if tmpdir is not None:
                shutil.rmtree(tmpdir, ignore_errors=True)

    def _readable_copy(self) -> tuple[Path, str | None]:
        try:
            _, _, complete = scan_records(self.path)
        except (ValueError, OSError) as err:
            raise RecordingError(f"{self.path}: {err}") from None
        if complete:
            return self.path, None
        tmpdir = tempfile.mkdtemp(prefix="agvsim-mcap-")
        fixed = Path(tmpdir) / "repaired.mcap"
        try:
            repair(self.path, fixed)
        except (ValueError, OSError) as err:
            shutil.rmtree(tmpdir, ignore_errors=True)
            raise RecordingError(f"{self.path}: cut off and cannot be repaired: {err}") from None
        self.repaired = True
        warnings.warn(
            f"{self.path} was cut off (no footer); reading the complete part",
            stacklevel=3,
        )
        return fixed, tmpdir

    # ------------------------------------------------------------------ generic
    @property
    def topics(self) -> list[str]:
        return sorted(self.types)

    def count(self, topic: str) -> int:
        return len(self._raw.get(topic, ()))

    @_reading
    def messages(self, topic: str, type_name: str | None = None) -> list[tuple[float, Any]]:
        """(log time s, decoded message) of every message on ``topic`` (rosbags' message
        classes, made from the recording's own definitions: typed ``Any`` here)."""
        if topic not in self.types:
            raise RecordingError(
                f"{self.path}: no topic {topic!r}; topics: {', '.join(self.topics)}"
            )
        typ = self.types[topic]
        if type_name is not None and typ != type_name:
            raise RecordingError(f"{self.path}: {topic} holds {typ}, not {type_name}")
        return [(t * 1e-9, self._decode(raw, typ)) for t, raw in self._raw[topic]]

    def _decode(self, raw: bytes, type_name: str) -> Any:
        """One CDR message as rosbags' class of ``type_name`` (a dataclass made at run time)."""
        return self._store.deserialize_cdr(raw, type_name)

    def topics_of_type(self, type_name: str) -> list[str]:
        return [t for t in self.topics if self.types[t] == type_name]

    # ------------------------------------------------------------------ typed accessors
    def _stacked(self, topic: str) -> np.ndarray | None:
        """The raw CDR messages of ``topic`` as one (T, L) byte array when they all have the
        same length (one frame id: the layout is then the same), else None."""
        raws = self._raw.get(topic, [])
        if not raws or len({len(r) for _, r in raws}) != 1:
            return None
        if raws[0][1][:4] != b"\x00\x01\x00\x00":  # not little-endian CDR
            return None
        return np.frombuffer(b"".join(r for _, r in raws), np.uint8).reshape(len(raws), -1)

    @staticmethod
    def _stamps(block: np.ndarray) -> np.ndarray:
        sec = np.ascontiguousarray(block[:, 4:8]).view("<i4")[:, 0].astype(np.float64)
        nsec = np.ascontiguousarray(block[:, 8:12]).view("<u4")[:, 0].astype(np.float64)
        return sec + nsec * 1e-9

    @_reading
    def odometry(self, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``nav_msgs/Odometry``: header stamps (T,), planar poses (T, 3) x, y, yaw and body
        twists (T, 3) vx, vy, omega."""
        if self.types.get(topic) == ODOMETRY and (block := self._stacked(topic)) is not None:
            # the message ends in 85 doubles: pose (7), covariance (36), twist (6), covariance
            tail = np.ascontiguousarray(block[:, -85 * 8 :]).view("<f8")
            q_z, q_w = tail[:, 5], tail[:, 6]
            poses = np.column_stack([tail[:, 0], tail[:, 1], 2.0 * np.arctan2(q_z, q_w)])
            tw = np.column_stack([tail[:, 43], tail[:, 44], tail[:, 48]])
            return self._stamps(block), poses, tw
        msgs = self.messages(topic, ODOMETRY)
        t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in msgs])
        poses = np.array(
            [
                (m.pose.pose.position.x, m.pose.pose.position.y, _yaw(m.pose.pose.orientation))
                for _, m in msgs
            ]
        ).reshape(-1, 3)
        tw = np.array(
            [
                (m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z)
                for _, m in msgs
            ]
        ).reshape(-1, 3)
        return t, poses, tw

    @_reading
    def laser_scans(self, topic: str) -> ScanSeries:
        """Every scan of a ``sensor_msgs/LaserScan`` topic (all with the same beam count)."""
        if self.count(topic) == 0:
            if topic in self.types:
                raise RecordingError(f"{self.path}: {topic} holds no scans")
            self.messages(topic)  # raises: no such topic
        first = self._decode(self._raw[topic][0][1], LASER_SCAN)
        if self.types[topic] != LASER_SCAN:
            raise RecordingError(f"{self.path}: {topic} holds {self.types[topic]}, not scans")
        n = len(first.ranges)
        block = self._stacked(topic) if len(first.intensities) == 0 else None
        if block is not None:
            # ... float32[] ranges (count, values), float32[] intensities (count 0): the end
            t = self._stamps(block)
            ranges = np.ascontiguousarray(block[:, block.shape[1] - 4 - 4 * n : -4])
            ranges = ranges.view("<f4").astype(np.float64)
        else:
            msgs = self.messages(topic, LASER_SCAN)
            bad = [k for k, (_, m) in enumerate(msgs) if len(m.ranges) != n]
            if bad:
                raise RecordingError(
                    f"{self.path}: {topic}: scan {bad[0]} has {len(msgs[bad[0]][1].ranges)} "
                    f"beams, the first has {n}"
                )
            t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in msgs])
            ranges = np.array([m.ranges for _, m in msgs], dtype=np.float64).reshape(-1, n)
        mount = self.static_transforms().get(first.header.frame_id)
        return ScanSeries(
            frame_id=first.header.frame_id,
            stamp_s=t,
            ranges=ranges,
            angle_min_rad=float(first.angle_min),
            angle_increment_rad=float(first.angle_increment),
            range_min_m=float(first.range_min),
            range_max_m=float(first.range_max),
            mount_pose=np.array(mount[1:] if mount is not None else (0.0, 0.0, 0.0)),
        )

    @_reading
    def occupancy(self, topic: str = "/map") -> list[GridMessage]:
        out = []
        for t, m in self.messages(topic, OCCUPANCY_GRID):
            info = m.info
            cells = np.asarray(m.data, dtype=np.int8).reshape(int(info.height), int(info.width))
            out.append(
                GridMessage(
                    t,
                    m.header.frame_id,
                    cells,
                    float(info.resolution),
                    (float(info.origin.position.x), float(info.origin.position.y)),
                )
            )
        return out

    @_reading
    def strings(self, topic: str) -> tuple[np.ndarray, list[str]]:
        msgs = self.messages(topic, STRING)
        return np.array([t for t, _ in msgs]), [m.data for _, m in msgs]

    @_reading
    def static_transforms(self) -> dict[str, tuple[str, float, float, float]]:
        """child frame -> (parent frame, x, y, yaw) from ``/tf_static`` (the planar part: a
        camera's height and pitch are left out)."""
        out: dict[str, tuple[str, float, float, float]] = {}
        if "/tf_static" not in self.types:
            return out
        for _, m in self.messages("/tf_static"):
            for tf in m.transforms:
                tr = tf.transform
                out[tf.child_frame_id] = (
                    tf.header.frame_id,
                    float(tr.translation.x),
                    float(tr.translation.y),
                    _yaw(tr.rotation),
                )
        return out

    # ------------------------------------------------------------------ agvsim layout
    @property
    @_reading
    def scenario_yaml(self) -> str | None:
        """The scenario stored by ``agvsim run`` (``/agvsim/scenario``), or None."""
        if "/agvsim/scenario" not in self.types:
            return None
        return self.strings("/agvsim/scenario")[1][0]

    @_reading
    def scenario_dict(self) -> dict | None:
        """The stored scenario as data (read within the scenario loader's YAML limits)."""
        from agvsim.safe_yaml import load_yaml

        text = self.scenario_yaml
        if text is None:
            return None
        data = load_yaml(text, f"{self.path} (/agvsim/scenario)")
        if not isinstance(data, dict) or not isinstance(data.get("robots", []), list):
            raise RecordingError(f"{self.path}: the stored scenario is not a scenario mapping")
        return data

    @_reading
    def robot_names(self) -> list[str]:
        """Robots in scenario order (from the stored scenario, else from the odometry
        topics)."""
        sc = self.scenario_dict()
        if sc is not None:
            return [r["name"] for r in sc.get("robots", [])]
        return [t.split("/")[1] for t in self.topics if t.endswith("/ground_truth")]

    @_reading
    def lidar_topics(self) -> list[tuple[str, str, str]]:
        """(robot name, sensor frame name, topic) of every scan topic, robots in scenario order;
        lidars (per the stored scenario, else scans of more than 8 beams) first."""
        scans = set(self.topics_of_type(LASER_SCAN))
        sc = self.scenario_dict() or {}
        kinds: dict[str, bool] = {}
        for r in sc.get("robots", []):
            rt = topic_name(r["name"])
            for k, s in enumerate(r.get("sensors", [])):
                typ = s.get("type", "")
                name = s.get("name") or (typ if typ else f"sensor{k}")
                kinds[f"/{rt}/{topic_name(name)}"] = typ == "lidar"
        out = []
        for name in self.robot_names():
            rt = topic_name(name)
            for topic in sorted(t for t in scans if t.startswith(f"/{rt}/")):
                lidar = kinds.get(topic)
                if lidar is None:
                    lidar = len(self._raw[topic]) > 0 and self._beams(topic) > 8
                out.append((name, topic.split("/", 2)[2], topic, lidar))
        out.sort(key=lambda x: not x[3])  # stable: lidars first, scenario order kept
        return [(a, b, c) for a, b, c, _ in out]

    @_reading
    def _beams(self, topic: str) -> int:
        t_ns, raw = self._raw[topic][0]
        return len(self._decode(raw, LASER_SCAN).ranges)
