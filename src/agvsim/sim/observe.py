"""Observations: what controllers see of the simulation (scans, odometry, bumps, poses).

Functions of a ``Simulation``; its ``scan``, ``observation``, ``batch_observation`` and
``active_states`` methods call these.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from agvsim.control.api import BatchObservation, ControlMode, Observation
from agvsim.scan import LaserScan
from agvsim.sensors.floor_codes import FloorFixReading
from agvsim.sensors.line_sensor import LineReading
from agvsim.sim.state import SensorTable

if TYPE_CHECKING:
    from agvsim.sim.engine import Simulation


def scan(sim: Simulation, slot: int) -> LaserScan:
    tab, st = sim.sensors, sim.state
    spec = tab.specs[slot]
    return LaserScan(
        float(st.scan_stamp[slot]),
        spec.angle_min_rad,
        spec.angle_increment_rad,
        spec.range_min_m,
        spec.range_max_m,
        st.scans[slot, : spec.num_beams].copy(),
        np.array((*spec.mount_xy_m, spec.mount_yaw_rad), dtype=np.float64),
        intensities=st.intensities[slot, : spec.num_beams].copy() if st.intensities.size else None,
    )


@dataclass(frozen=True)
class CameraObservation(Observation):
    """An ``Observation`` with the robot's camera frames, by camera name (empty without
    cameras): ``images[name]`` ``(H, W, 3)`` uint8 RGB, ``depth[name]`` ``(H, W)`` float32
    z-depth in m (inf: nothing within range), ``image_stamps[name]`` the frame's time, s. The
    arrays are read-only and stay as they are: a new frame is a new array."""

    images: dict[str, np.ndarray] = field(default_factory=dict)
    depth: dict[str, np.ndarray] = field(default_factory=dict)
    image_stamps: dict[str, float] = field(default_factory=dict)


def observation(sim: Simulation, i: int) -> Observation:
    st = sim.state
    robot = sim.robots[i]
    scans = {sim.sensors.specs[s].name: scan(sim, s) for s in sim.sensors.slots_of[i]}
    w = len(robot.model.wheel_names)
    images: dict[str, np.ndarray] = {}
    depth: dict[str, np.ndarray] = {}
    stamps: dict[str, float] = {}
    cams = sim.cameras
    if cams is not None:
        for c in cams.slots_of[i]:
            name = cams.specs[c].name
            images[name], depth[name] = st.images[c], st.depths[c]
            stamps[name] = float(st.image_stamp[c])
    lines: dict[str, LineReading] = {}
    fixes: dict[str, FloorFixReading] = {}
    g = sim.guidance
    if g is not None:
        for k in g.line_slots_of[i]:
            offs = st.line_offsets[k]
            lines[g.line_specs[k].name] = LineReading(
                float(st.line_stamp[k]),
                st.line_active[k, : g.line_specs[k].elements].copy(),
                tuple(float(v) for v in offs[np.isfinite(offs)]),
                int(st.line_spot[k]),
            )
        for c in g.cam_slots_of[i]:
            fixes[g.cam_specs[c].name] = FloorFixReading(
                float(st.fix_stamp[c]),
                int(st.fix_seq[c]),
                int(st.fix_code[c]),
                st.fix_pose[c].copy(),
            )
    return CameraObservation(
        t_s=st.t_s,
        name=robot.name,
        scans=scans,
        odom_pose=st.odom_poses[i].copy(),
        wheel_speeds=st.wheel_speeds[i, :w].copy(),
        bump=bool(st.bump[i]),
        true_pose=st.poses[i].copy(),
        others={sim.robots[j].name: st.poses[j].copy() for j in sim.knows[i]},
        model=robot.model,
        mode=ControlMode(robot.mode),
        dt_s=sim.dt_s,
        images=images,
        depth=depth,
        image_stamps=stamps,
        lines=lines,
        floor_fixes=fixes,
    )


def batch_observation(sim: Simulation, idx: np.ndarray) -> BatchObservation:
    st = sim.state
    ranges = _LazyRanges(st.scans, sim.batch_slots(idx))
    return BatchObservation(
        t_s=st.t_s,
        robots=idx,
        ranges=ranges,
        odom_pose=st.odom_poses[idx],
        bump=st.bump[idx],
        true_pose=st.poses[idx],
        extra=_guidance_extra(sim, idx),
    )


def _guidance_extra(sim: Simulation, idx: np.ndarray) -> dict:
    """Batch form of the guidance readings (empty without them): ``line_offsets`` /
    ``line_spot`` of each robot's first line sensor ``(k, R)`` / ``(k,)`` (NaN / -1 for a robot
    without one), ``intensities`` of the range sensors by name ``(k, B)``."""
    g = sim.guidance
    if g is None:
        return {}
    st = sim.state
    out: dict = {}
    if g.line_count:
        first = np.array(
            [g.line_slots_of[int(i)][0] if g.line_slots_of[int(i)] else -1 for i in idx]
        )
        has = first >= 0
        offs = np.full((len(idx), st.line_offsets.shape[1]), np.nan)
        offs[has] = st.line_offsets[first[has]]
        spot = np.full(len(idx), -1, dtype=np.int64)
        spot[has] = st.line_spot[first[has]]
        out["line_offsets"], out["line_spot"] = offs, spot
    if st.intensities.size:
        out["intensities"] = {
            name: st.intensities[rows, :width]
            for name, (rows, width) in sim.batch_slots(idx).items()
        }
    return out


def batch_slots(tab: SensorTable, idx: np.ndarray) -> dict[str, tuple[slice | np.ndarray, int]]:
    """Sensor name -> (its rows of the sensor table, beams) for the robots ``idx``: the
    sensors every one of them has with the same beam count."""
    return {
        name: (
            _rows(slots := np.array([tab.slot(int(i), name) for i in idx])),
            tab.specs[int(slots[0])].num_beams,
        )
        for name in tab.common_names(idx)
    }


def active_states(sim: Simulation) -> list[str]:
    """Each robot's active controller state ("" when its controller has none): read from
    ``state_name`` (one robot) or ``state_names()`` (a batch controller)."""
    out = [""] * sim.n
    for b, idx in zip(sim.bindings, sim.binding_robots, strict=True):
        ctrl = b.controller
        if b.batch and hasattr(ctrl, "state_names"):
            for i, name in zip(idx, ctrl.state_names(), strict=False):
                out[int(i)] = name
        elif not b.batch:
            name = getattr(ctrl, "state_name", "")
            for i in idx:
                out[int(i)] = name if isinstance(name, str) else ""
    for i in np.flatnonzero(sim.state.stopped):
        out[int(i)] = "stopped"
    return out


def _rows(slots: np.ndarray) -> slice | np.ndarray:
    """Consecutive slots as a slice (their rows are then a view, not a copy)."""
    if np.all(np.diff(slots) == 1):
        return slice(int(slots[0]), int(slots[-1]) + 1)
    return slots


class _LazyRanges(Mapping):
    """sensor name -> (k, B) readings, gathered only when a controller asks for them."""

    def __init__(self, scans: np.ndarray, slots: dict[str, tuple[slice | np.ndarray, int]]):
        self._scans, self._slots = scans, slots

    def __getitem__(self, name: str) -> np.ndarray:
        rows, width = self._slots[name]
        return self._scans[rows, :width]

    def __contains__(self, name: object) -> bool:
        return name in self._slots

    def __iter__(self):
        return iter(self._slots)

    def __len__(self) -> int:
        return len(self._slots)
