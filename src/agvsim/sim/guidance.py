"""The guidance sensors of all robots as flat tables: line sensor bars, downward floor-code
cameras, and the lidar intensity channel over reflectors (docs/guidance.md).

Built by the engine only when a robot has a line sensor or a floor camera, or the world has
reflectors: other runs pay nothing and draw nothing from the generator. The rig reads and
returns; the engine stores the readings in the state (only ``sim/`` writes it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agvsim.sensors.floor_codes import FloorCameraSpec, read_fix, render
from agvsim.sensors.line_sensor import LineSensorSpec, line_offsets, read_elements, spots_under
from agvsim.sensors.reflectors import intensities
from agvsim.sim.spec import RobotSpec, World

MAX_RUNS = 4  # runs of lit elements kept per line reading (a crossing gives two or three)


@dataclass(frozen=True)
class LineRead:
    active: np.ndarray  # (L, E_max) bool
    offsets_m: np.ndarray  # (L, MAX_RUNS) runs right to left, NaN padded, noise included
    spot_code: np.ndarray  # (L,) int64, -1: no spot under the reader


class GuidanceRig:
    """Line sensors (L slots) and floor cameras (F slots) of every robot, and the world's
    tape, floor codes and reflectors."""

    def __init__(self, robots: Sequence[RobotSpec], world: World):
        self.world = world
        self.line_specs: list[LineSensorSpec] = []
        self.cam_specs: list[FloorCameraSpec] = []
        line_owner: list[int] = []
        cam_owner: list[int] = []
        self.line_slots_of: list[list[int]] = []
        self.cam_slots_of: list[list[int]] = []
        for i, r in enumerate(robots):
            self.line_slots_of.append(
                list(range(len(self.line_specs), len(self.line_specs) + len(r.line_sensors)))
            )
            self.cam_slots_of.append(
                list(range(len(self.cam_specs), len(self.cam_specs) + len(r.floor_cameras)))
            )
            self.line_specs.extend(r.line_sensors)
            self.cam_specs.extend(r.floor_cameras)
            line_owner += [i] * len(r.line_sensors)
            cam_owner += [i] * len(r.floor_cameras)
        self.line_owner = np.array(line_owner, dtype=np.int64)
        self.cam_owner = np.array(cam_owner, dtype=np.int64)
        e_max = max((s.elements for s in self.line_specs), default=1)
        self.line_pos = np.full((len(self.line_specs), e_max), np.nan)
        for k, s in enumerate(self.line_specs):
            self.line_pos[k, : s.elements] = s.positions_m
        self.line_mount_x = np.array([s.mount_x_m for s in self.line_specs], dtype=np.float64)
        self.line_noise = np.array([s.noise_std_m for s in self.line_specs], dtype=np.float64)
        self.line_spot_r = np.array([s.spot_radius_m for s in self.line_specs], dtype=np.float64)
        self.cam_period_s = np.array([1.0 / s.rate_hz for s in self.cam_specs], dtype=np.float64)
        tape = world.tape
        self._segments = np.zeros((0, 4)) if tape is None else tape.segments
        self._half_width = 0.0 if tape is None else tape.width_m / 2.0
        self._spot_xy = np.zeros((0, 2)) if tape is None else tape.spot_xy
        self._spot_code = np.zeros(0, dtype=np.int64) if tape is None else tape.spot_code

    line_offsets_width = MAX_RUNS

    @property
    def line_count(self) -> int:
        return len(self.line_specs)

    @property
    def cam_count(self) -> int:
        return len(self.cam_specs)

    def read_lines(self, poses: np.ndarray, rng: np.random.Generator) -> LineRead:
        """Every line sensor at the robots' ``poses`` (N, 3); noise from ``rng`` only for the
        sensors that have some."""
        n = self.line_count
        pose = np.ascontiguousarray(poses[self.line_owner])
        active = read_elements(
            pose, self.line_mount_x, self.line_pos, self._segments, self._half_width
        )
        offsets = np.full((n, MAX_RUNS), np.nan)
        for k, runs in enumerate(line_offsets(active, self.line_pos)):
            m = min(len(runs), MAX_RUNS)
            offsets[k, :m] = runs[:m]
        noisy = self.line_noise > 0
        if noisy.any():
            draw = rng.standard_normal((int(noisy.sum()), MAX_RUNS))
            offsets[noisy] += self.line_noise[noisy, None] * draw
        spot = spots_under(pose, self.line_mount_x, self._spot_xy, self.line_spot_r)
        code = (
            np.where(spot >= 0, self._spot_code[np.maximum(spot, 0)], -1)
            if len(self._spot_code)
            else np.full(len(spot), -1, dtype=np.int64)  # a world without spots (or tape)
        )
        if len(self._spot_code) == 0:
            code = np.full(n, -1, dtype=np.int64)
        return LineRead(active, offsets, code.astype(np.int64))

    def read_codes(
        self, poses: np.ndarray, due: np.ndarray
    ) -> list[tuple[int, int, np.ndarray | None]]:
        """(slot, code id, robot pose) for each floor camera ``due`` that read a code (code
        id -1 and None when it read none); nothing without floor codes."""
        grid = self.world.floor_codes
        out: list[tuple[int, int, np.ndarray | None]] = []
        for c in np.flatnonzero(due):
            spec = self.cam_specs[int(c)]
            fix = None
            if grid is not None:
                fix = read_fix(spec, grid, render(spec, grid, poses[self.cam_owner[c]]))
            out.append((int(c), -1, None) if fix is None else (int(c), fix.code_id, fix.pose))
        return out

    def scan_intensities(
        self,
        poses: np.ndarray,
        owner: np.ndarray,
        mount: np.ndarray,
        rel_angles: np.ndarray,
        num_beams: np.ndarray,
        ranges: np.ndarray,
    ) -> np.ndarray:
        """(S', B) intensities of the scans ``ranges`` (S', B) just cast (sensor rows with
        their owners, mounts, beam angles and beam counts); zeros without reflectors."""
        out = np.zeros(ranges.shape)
        refl = self.world.reflectors
        if refl is None:
            return out
        for k in range(len(ranges)):
            b = int(num_beams[k])
            out[k, :b] = intensities(
                poses[owner[k]],
                ranges[k, :b],
                rel_angles[k, :b],
                (float(mount[k, 0]), float(mount[k, 1])),
                float(mount[k, 2]),
                refl,
            )
        return out
