"""The changing state of a simulation (a handful of arrays) and the flat sensor table.

Only the engine (:mod:`agvsim.sim.engine`) writes a ``SimState``; everyone else reads it, and
changes it through the engine's methods (``place``, ``reset``, ``restore``, ...).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sim.spec import RobotSpec


@dataclass
class SensorTable:
    """Every sensor of every robot as one flat table of S slots (structure of arrays)."""

    specs: list[RangeSensorSpec]
    owner: np.ndarray  # (S,) robot index
    mount: np.ndarray  # (S, 3) x, y, yaw in the robot frame
    rel_angles: np.ndarray  # (S, B_max) beam angles in the sensor frame, NaN padded
    num_beams: np.ndarray  # (S,) beams of each sensor
    range_min: np.ndarray  # (S,)
    range_max: np.ndarray  # (S,)
    noise: np.ndarray  # (S,)
    dropout: np.ndarray  # (S,)
    period_s: np.ndarray  # (S,)
    post: np.ndarray  # (S,) bool: readings need noise, dropout or the range_min rule
    slots_of: list[list[int]]  # robot index -> its slots

    @property
    def count(self) -> int:
        return len(self.specs)

    @property
    def max_beams(self) -> int:
        return int(self.rel_angles.shape[1])

    @classmethod
    def build(cls, robots: Sequence[RobotSpec]) -> SensorTable:
        specs: list[RangeSensorSpec] = []
        owner: list[int] = []
        slots_of: list[list[int]] = []
        for i, r in enumerate(robots):
            names = [s.name for s in r.sensors]
            if len(set(names)) != len(names):
                raise ValueError(f"robot {r.name!r}: sensor names must be unique, got {names}")
            slots_of.append(list(range(len(specs), len(specs) + len(r.sensors))))
            specs.extend(r.sensors)
            owner.extend([i] * len(r.sensors))
        b_max = max((s.num_beams for s in specs), default=1)
        rel = np.full((len(specs), b_max), np.nan)
        for k, s in enumerate(specs):
            rel[k, : s.num_beams] = s.beam_angles_rad

        def col(attr: str) -> np.ndarray:
            return np.array([getattr(s, attr) for s in specs], dtype=np.float64)

        return cls(
            specs=specs,
            owner=np.array(owner, dtype=np.int64),
            mount=np.array(
                [(*s.mount_xy_m, s.mount_yaw_rad) for s in specs], dtype=np.float64
            ).reshape(-1, 3),
            rel_angles=rel,
            num_beams=np.array([sp.num_beams for sp in specs], dtype=np.int64),
            range_min=col("range_min_m"),
            range_max=col("range_max_m"),
            noise=col("noise_std_m"),
            dropout=col("dropout_prob"),
            period_s=1.0 / col("rate_hz") if specs else np.zeros(0),
            post=(col("noise_std_m") > 0) | (col("dropout_prob") > 0) | (col("range_min_m") > 0),
            slots_of=slots_of,
        )

    def slot(self, robot: int, name: str) -> int:
        for s in self.slots_of[robot]:
            if self.specs[s].name == name:
                return s
        raise KeyError(name)

    def common_names(self, robots: np.ndarray) -> list[str]:
        """Sensor names every robot of ``robots`` has, with the same beam count."""
        first = [self.specs[s] for s in self.slots_of[int(robots[0])]]
        out = []
        for spec in first:
            ok = True
            for i in robots[1:]:
                try:
                    other = self.specs[self.slot(int(i), spec.name)]
                except KeyError:
                    ok = False
                    break
                ok = other.num_beams == spec.num_beams
                if not ok:
                    break
            if ok:
                out.append(spec.name)
        return out


#: the per-robot rows of the physical state, carried over when a simulation is rebuilt with
#: the same robot (``Simulation.carry_over``): pose, motion, wheels, odometry and counters
ROBOT_ROWS = (
    "poses",
    "twists",
    "wheel_speeds",
    "wheel_angles",
    "steering",
    "steer_angles",
    "odom_poses",
    "bump",
    "bump_wall",
    "bump_robot",
    "collisions",
    "wall_collisions",
    "robot_collisions",
    "distance_m",
    "safety_status",
    "safety_since_s",
    "safety_set",
    "safety_events",
    "safety_first_s",
    "safety_last_s",
)


@dataclass
class SimState:
    """Everything that changes from one step to the next: the robots, the commands waiting
    to be actuated, the sensors' latest readings and timers, the cameras' frames, the random
    generator and the controller errors so far. Copy it with :meth:`copy`."""

    t_s: float
    step: int
    poses: np.ndarray  # (N, 3) x, y, theta: ground truth, world frame
    twists: np.ndarray  # (N, 3) vx, vy, omega executed in the last step, robot frame
    wheel_speeds: np.ndarray  # (N, W_max) rad/s, model wheel order, zero padded
    wheel_angles: np.ndarray  # (N, W_max) rad, accumulated rotation of each wheel
    steering: np.ndarray  # (N,) rad, bicycle steering angle (car-like models)
    steer_angles: np.ndarray  # (N, S_max) rad, each steered wheel
    odom_poses: np.ndarray  # (N, 3) dead-reckoned from wheel encoders
    bump: np.ndarray  # (N,) bool: collided in the last step
    bump_wall: np.ndarray  # (N,) bool: the bump was against a wall, the map edge or a box
    bump_robot: np.ndarray  # (N,) bool: the bump was against another robot
    collisions: np.ndarray  # (N,) int: collision events (a bump after a free step)
    wall_collisions: np.ndarray  # (N,) int: events against walls, the map edge or boxes
    robot_collisions: np.ndarray  # (N,) int: events against other robots
    distance_m: np.ndarray  # (N,) travelled
    stopped: np.ndarray  # (N,) bool: taken out of the run (e.g. its controller failed)
    scans: np.ndarray  # (S, B_max) latest readings per sensor slot
    scan_stamp: np.ndarray  # (S,) time of the latest reading
    next_scan_s: np.ndarray  # (S,) when each sensor fires next
    # commands of the last control stage, read by the actuation stage
    cmd_twist: np.ndarray  # (N, 3) vx, vy, omega (inverse mode)
    cmd_wheels: np.ndarray  # (N, W_max + 1) driven wheel speeds, then steering (forward mode)
    cmd_is_twist: np.ndarray  # (N,) bool: which of the two holds the robot's command
    rng: np.random.Generator  # sensor and encoder noise, controllers' randomness
    errors: list[Any] = field(default_factory=list)  # ControllerErrors so far, in order
    # cameras (C slots, agvsim.sensors.camera_rig; empty without cameras): latest frames
    images: list[np.ndarray] = field(default_factory=list)  # (H, W, 3) uint8 each, read-only
    depths: list[np.ndarray] = field(default_factory=list)  # (H, W) float32 z-depth m each
    image_stamp: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (C,) frame time
    image_seq: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (C,) frames
    image_pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (C, 3) at frame
    next_image_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (C,) next frame
    # planar dynamics (agvsim.dynamics; (0, W) without any robot that has it): per wheel, in
    # the model's wheel order, zero for kinematic robots
    wheel_torque_nm: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (N, W)
    wheel_slip_m_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (N, W)
    wheel_power_w: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (N, W)
    # guidance sensors (agvsim.sim.guidance; empty without them): L line sensor slots,
    # F floor-camera slots, and the range sensors' intensities when the world has reflectors
    line_active: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), bool))  # (L, E)
    line_offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (L, R) m
    line_spot: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (L,) code
    line_stamp: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (L,) s
    fix_pose: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (F, 3) last fix
    fix_code: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (F,) its code
    fix_stamp: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F,) its time
    fix_seq: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (F,) fixes
    next_fix_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (F,) next frame
    intensities: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (S, B_max)
    # safety scanners (agvsim.sim.safety; -1 / NaN / 0 for robots without one): status of the
    # last safety stage (0 clear, 1 warning, 2 protective), when the protective violation
    # began (NaN: none now), the active field set's index in the robot's own list, and per
    # robot [warning, protective] violation counts, first start and last time violated
    safety_status: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))  # (N,)
    safety_since_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (N,)
    safety_set: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (N,)
    safety_events: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    safety_first_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (N, 2)
    safety_last_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (N, 2)

    @classmethod
    def zeros(
        cls,
        n: int,
        sensors: SensorTable,
        w_max: int,
        s_max: int,
        poses: np.ndarray,
        rng: np.random.Generator,
        cmd_is_twist: np.ndarray,
    ) -> SimState:
        s, b = sensors.count, sensors.max_beams
        return cls(
            t_s=0.0,
            step=0,
            poses=poses.copy(),
            twists=np.zeros((n, 3)),
            wheel_speeds=np.zeros((n, w_max)),
            wheel_angles=np.zeros((n, w_max)),
            steering=np.zeros(n),
            steer_angles=np.zeros((n, s_max)),
            odom_poses=poses.copy(),
            bump=np.zeros(n, dtype=bool),
            bump_wall=np.zeros(n, dtype=bool),
            bump_robot=np.zeros(n, dtype=bool),
            collisions=np.zeros(n, dtype=np.int64),
            wall_collisions=np.zeros(n, dtype=np.int64),
            robot_collisions=np.zeros(n, dtype=np.int64),
            distance_m=np.zeros(n),
            stopped=np.zeros(n, dtype=bool),
            scans=np.full((s, b), np.inf),
            scan_stamp=np.zeros(s),
            next_scan_s=np.zeros(s),
            cmd_twist=np.zeros((n, 3)),
            cmd_wheels=np.zeros((n, w_max + 1)),
            cmd_is_twist=cmd_is_twist.copy(),
            rng=rng,
            safety_status=np.zeros(n, dtype=np.int8),
            safety_since_s=np.full(n, np.nan),
            safety_set=np.full(n, -1, dtype=np.int64),
            safety_events=np.zeros((n, 2), dtype=np.int64),
            safety_first_s=np.full((n, 2), np.nan),
            safety_last_s=np.full((n, 2), np.nan),
        )

    def copy(self) -> SimState:
        """An independent copy: arrays copied, the generator at the same point of its stream.
        Camera frames are shared (they are read-only and replaced, never written in place)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                out[f.name] = v.copy()
            elif isinstance(v, np.random.Generator):
                out[f.name] = copy.deepcopy(v)
            elif isinstance(v, list):
                out[f.name] = list(v)
            else:
                out[f.name] = v
        return SimState(**out)
