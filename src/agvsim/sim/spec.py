"""The static description of a simulation: world and robot specs (built once, never stepped)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agvsim.control.api import ControlMode
from agvsim.dynamics.spec import DynamicsSpec, FloorFriction
from agvsim.kinematics.base import KinematicModel
from agvsim.sensors.camera import CameraSpec
from agvsim.sensors.floor_codes import FloorCameraSpec, FloorCodeGrid
from agvsim.sensors.line_sensor import LineSensorSpec
from agvsim.sensors.range_sensor import RangeSensorSpec
from agvsim.sensors.reflectors import ReflectorMap
from agvsim.sensors.safety_fields import SafetyScannerSpec
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Appearance
from agvsim.world.tape import Tape

# Heights of the 3D world (m), shared by the onboard camera and the browser app: walls are the
# occupancy grid extruded to WALL_HEIGHT_M, static boxes stand BOX_HEIGHT_M tall, and a robot's
# body is BODY_HEIGHT_M tall on top of its wheels (see RobotSpec.height_m).
WALL_HEIGHT_M = 1.0
BOX_HEIGHT_M = 1.0
BODY_HEIGHT_M = 0.25


@dataclass(frozen=True)
class OdometrySpec:
    """Wheel encoders: measured wheel speed = true * (1 + N(0, rel_std)) + N(0, abs_std);
    measured steering = true + N(0, steer_std). Dead reckoning integrates the measurements."""

    wheel_noise_rel: float = 0.01
    wheel_noise_abs_rad_s: float = 0.0
    steering_noise_rad: float = 0.0


@dataclass(frozen=True)
class RobotSpec:
    name: str
    model: KinematicModel
    mode: ControlMode = ControlMode.INVERSE
    body_length_m: float = 0.6
    body_width_m: float = 0.45
    body_offset_x_m: float = 0.0  # footprint centre ahead of the reference point P
    initial_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x m, y m, theta rad (world)
    sensors: tuple[RangeSensorSpec, ...] = ()
    cameras: tuple[CameraSpec, ...] = ()
    odometry: OdometrySpec = field(default_factory=OdometrySpec)
    color: str = "#d62728"
    dynamics: DynamicsSpec | None = None  # None: kinematic (commanded speeds reached at once)
    # guidance sensors (docs/guidance.md): line sensor bars and downward floor-code cameras
    line_sensors: tuple[LineSensorSpec, ...] = ()
    floor_cameras: tuple[FloorCameraSpec, ...] = ()
    safety: SafetyScannerSpec | None = None  # a safety scanner's field sets (sim/safety.py)

    @property
    def footprint_half_m(self) -> tuple[float, float]:
        return (self.body_length_m / 2.0, self.body_width_m / 2.0)

    @property
    def bounding_radius_m(self) -> float:
        hl, hw = self.footprint_half_m
        return float(np.hypot(abs(self.body_offset_x_m) + hl, hw))

    @property
    def height_m(self) -> float:
        """Top of the body above the floor: it sits on the axles (wheel radius) and is
        BODY_HEIGHT_M tall."""
        r = float(np.asarray(getattr(self.model, "wheel_radius_m", 0.1)).reshape(-1)[0])
        return r + BODY_HEIGHT_M


@dataclass(frozen=True)
class World:
    grid: OccupancyGrid
    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))  # (K, 5) static boxes
    appearance: Appearance = field(default_factory=Appearance)  # colours, markers (camera)
    floor: FloorFriction = field(default_factory=FloorFriction)  # read by robots with dynamics
    # guidance infrastructure (docs/guidance.md); None: not laid
    tape: Tape | None = None
    floor_codes: FloorCodeGrid | None = None
    reflectors: ReflectorMap | None = None

    def __post_init__(self) -> None:
        b = np.asarray(self.boxes, dtype=np.float64).reshape(-1, 5)
        object.__setattr__(self, "boxes", b)
