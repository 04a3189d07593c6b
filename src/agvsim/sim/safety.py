"""The safety stage of a step: every robot with a safety scanner (``RobotSpec.safety``) gets
its command checked against its scanner's fields before actuation.

For the robots with a scanner, at once:

    active = field set for (signed forward speed, steering) of the last step   (select_sets)
    status = field_status(latest scan of the scanner's sensor, active set)     (numba)
    cmd    = brake(cmd, last twist, status, ...)                               (numba)

In forward mode (wheel speeds) the command's twist is worked out through the model's forward
kinematics, braked like a twist, and the driven wheel speeds are scaled by the same factor
(forward kinematics are linear in the wheel speeds at a fixed steering angle), the steering
angle kept. The engine owns the state this stage reads and writes (``SimState.safety_*``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba as nb
import numpy as np

from agvsim.sensors.safety_fields import (
    CLEAR,
    PROTECTIVE,
    WARNING,
    PackedFields,
    SafetyScannerSpec,
    brake,
    field_status,
)
from agvsim.sim.spec import RobotSpec
from agvsim.sim.state import SensorTable

#: how viewers colour a field set by its status: green clear, yellow warning, red protective
STATUS_RGB = ((0.17, 0.63, 0.17), (1.0, 0.8, 0.0), (0.84, 0.15, 0.16))

#: the commanded deceleration of robots with dynamics: zero wheel speed in one step
EMERGENCY_DECEL = 1e9
#: events counted per robot: column 0 warning, column 1 protective
EVENT_KINDS = (WARNING, PROTECTIVE)


@nb.njit(cache=True)
def select_sets(
    speed_m_s: np.ndarray,
    steering_rad: np.ndarray,
    first: np.ndarray,
    n_sets: np.ndarray,
    ranges: np.ndarray,
) -> np.ndarray:
    """The global index of each scanner's active field set (-1: none applies). ``ranges``
    (F, 4) holds each set's speed_min, speed_max (exclusive), steer_min, steer_max
    (exclusive); scanner s owns sets ``first[s] .. first[s] + n_sets[s] - 1``, first match
    wins (a scanner's sets do not overlap)."""
    out = np.full(speed_m_s.shape[0], -1, dtype=np.int64)
    for s in range(speed_m_s.shape[0]):
        v, d = speed_m_s[s], steering_rad[s]
        for f in range(first[s], first[s] + n_sets[s]):
            if ranges[f, 0] <= v < ranges[f, 1] and ranges[f, 2] <= d < ranges[f, 3]:
                out[s] = f
                break
    return out


@dataclass(frozen=True)
class SafetyTable:
    """The scanners of a simulation, as flat arrays over the K robots that have one."""

    robots: np.ndarray  # (K,) robot indices
    slots: np.ndarray  # (K,) sensor-table slot of each scanner's range sensor
    cos_sin: np.ndarray  # (K, B, 2) each beam's direction in the robot frame (NaN: padding)
    mount_xy: np.ndarray  # (K, 2) the sensors' positions in the robot frame
    specs: tuple[SafetyScannerSpec, ...]
    packed: PackedFields
    n_sets: np.ndarray  # (K,)
    ranges: np.ndarray  # (F, 4) speed_min, speed_max, steer_min, steer_max
    response_s: np.ndarray  # (K,)
    decel_m_s2: np.ndarray  # (K,)
    warn_speed_m_s: np.ndarray  # (K,)

    @classmethod
    def build(cls, robots: Sequence[RobotSpec], sensors: SensorTable) -> SafetyTable:
        """The scanners of ``robots`` on their sensors' slots of ``sensors``."""
        slot_of = [{sensors.specs[k].name: k for k in ks} for ks in sensors.slots_of]
        idx, slots, specs = [], [], []
        for i, r in enumerate(robots):
            if r.safety is None:
                continue
            if r.safety.sensor not in slot_of[i]:
                raise ValueError(
                    f"robot {r.name!r}: safety.sensor {r.safety.sensor!r} is not one of its "
                    f"range sensors {sorted(slot_of[i])}"
                )
            idx.append(i)
            slots.append(slot_of[i][r.safety.sensor])
            specs.append(r.safety)
        ranges = [
            (f.speed_min_m_s, f.speed_max_m_s, f.steer_min_rad, f.steer_max_rad)
            for s in specs
            for f in s.field_sets
        ]
        sl = np.asarray(slots, dtype=np.int64)
        # each beam's direction in the robot frame, worked out once: the stage then needs
        # no trigonometry (NaN-padded beams point nowhere and never count)
        angle = sensors.rel_angles[sl] + sensors.mount[sl, 2:3]
        return cls(
            robots=np.asarray(idx, dtype=np.int64),
            slots=sl,
            cos_sin=np.stack([np.cos(angle), np.sin(angle)], axis=-1),
            mount_xy=sensors.mount[sl, :2].copy(),
            specs=tuple(specs),
            packed=PackedFields.of(specs),
            n_sets=np.asarray([len(s.field_sets) for s in specs], dtype=np.int64),
            ranges=np.asarray(ranges, dtype=np.float64).reshape(-1, 4),
            response_s=np.asarray([s.response_time_s for s in specs], dtype=np.float64),
            # with dynamics the wheels are told to stand after the response time: the brake
            # gives what friction and motors allow (dynamics.braking's limit)
            decel_m_s2=np.asarray(
                [
                    EMERGENCY_DECEL if robots[i].dynamics is not None else s.decel_m_s2
                    for i, s in zip(idx, specs, strict=True)
                ],
                dtype=np.float64,
            ),
            warn_speed_m_s=np.asarray([s.warning_speed_m_s for s in specs], dtype=np.float64),
        )

    @property
    def count(self) -> int:
        return len(self.robots)

    def active_sets(self, speed_m_s: np.ndarray, steering_rad: np.ndarray) -> np.ndarray:
        """(K,) global field-set index for each scanner (-1: none applies)."""
        return select_sets(
            np.ascontiguousarray(speed_m_s, dtype=np.float64),
            np.ascontiguousarray(steering_rad, dtype=np.float64),
            self.packed.first,
            self.n_sets,
            self.ranges,
        )

    def status(self, scans: np.ndarray, active: np.ndarray) -> np.ndarray:
        """(K,) CLEAR / WARNING / PROTECTIVE from each scanner's latest ranges ``scans``
        (K, B) and active field sets ``active`` (K,)."""
        points, valid = robot_frame_points(
            np.ascontiguousarray(scans, dtype=np.float64), self.cos_sin, self.mount_xy
        )
        p = self.packed
        return field_status(points, valid, active, p.verts, p.start, p.count, p.prot, p.warn)

    def brake(
        self,
        cmd: np.ndarray,
        prev: np.ndarray,
        status: np.ndarray,
        since_s: np.ndarray,
        t_s: float,
        dt_s: float,
    ) -> np.ndarray:
        """The braked twists (K, 3); ``since_s`` (K,) is updated in place."""
        return brake(
            np.ascontiguousarray(cmd, dtype=np.float64),
            np.ascontiguousarray(prev, dtype=np.float64),
            status,
            since_s,
            t_s,
            dt_s,
            self.response_s,
            self.decel_m_s2,
            self.warn_speed_m_s,
        )

    def set_name(self, k: int, global_set: int) -> str:
        """The name of scanner k's field set ``global_set`` ("" for -1)."""
        if global_set < 0:
            return ""
        return self.specs[k].field_sets[int(global_set - self.packed.first[k])].name


def set_polygons(
    spec: SafetyScannerSpec, j: int
) -> list[tuple[str, tuple[tuple[float, float], ...]]]:
    """``[("protective", polygon), ("warning", polygon)]`` of field set ``j`` of a scanner
    (the warning one only when the set has it; none for ``j`` = -1), robot frame."""
    if j < 0:
        return []
    f = spec.field_sets[j]
    out = [("protective", f.protective)]
    if f.warning is not None:
        out.append(("warning", f.warning))
    return out


@nb.njit(cache=True)
def robot_frame_points(
    ranges: np.ndarray, cos_sin: np.ndarray, mount_xy: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Batched ``scan_points_robot_frame``: points (K, B, 2) in the robot frame from ranges
    (K, B), beam directions ``cos_sin`` (K, B, 2) and sensor positions ``mount_xy`` (K, 2),
    and which beams are returns (+inf: no return, NaN: a padded or dropped beam; -inf, closer
    than the sensor's minimum, is a return at the sensor)."""
    k_n, b_n = ranges.shape
    pts = np.zeros((k_n, b_n, 2))
    valid = np.zeros((k_n, b_n), dtype=np.bool_)
    for k in range(k_n):
        mx, my = mount_xy[k, 0], mount_xy[k, 1]
        for b in range(b_n):
            r, c = ranges[k, b], cos_sin[k, b, 0]
            if np.isnan(r) or np.isnan(c) or r == np.inf:
                pts[k, b, 0], pts[k, b, 1] = mx, my
                continue
            valid[k, b] = True
            r = max(r, 0.0)
            pts[k, b, 0] = mx + r * c
            pts[k, b, 1] = my + r * cos_sin[k, b, 1]
    return pts, valid


def count_events(
    prev: np.ndarray,
    new: np.ndarray,
    t_s: float,
    events: np.ndarray,
    first_s: np.ndarray,
    last_s: np.ndarray,
) -> None:
    """Update the per-robot event rows in place (rows of the scanner robots): a violation
    event is a step whose status is WARNING (PROTECTIVE) after one that was not; ``first_s``
    is when the first began, ``last_s`` the last step a field was violated."""
    for col, kind in enumerate(EVENT_KINDS):
        now = new == kind
        began = now & (prev != kind)
        events[began, col] += 1
        unset = began & np.isnan(first_s[:, col])
        first_s[unset, col] = t_s
        last_s[now, col] = t_s


__all__ = [
    "CLEAR",
    "EVENT_KINDS",
    "PROTECTIVE",
    "WARNING",
    "STATUS_RGB",
    "SafetyTable",
    "count_events",
    "robot_frame_points",
    "select_sets",
    "set_polygons",
]
