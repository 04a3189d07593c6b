"""Scenario blocks of the industrial guidance and safety sensors (docs/guidance.md):

* world ``tape:`` (magnetic tape or a painted line, and spots), ``floor_codes:`` (a grid of
  2-D codes) and ``reflectors:`` (laser-navigation reflectors);
* robot ``safety:`` (a safety laser scanner's field sets) and the sensors ``line`` (a line
  sensor bar) and ``floor_camera`` (a downward code reader).

Each block is validated here and turned into its core object (agvsim.world.tape,
agvsim.sensors.safety_fields, line_sensor, floor_codes, reflectors).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from typing import Annotated, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from agvsim.config_base import StrictConfig, construct
from agvsim.control.api import ControllerContext
from agvsim.control.line_follow import LineFollower
from agvsim.control.route_follow import RouteFollower
from agvsim.kinematics.base import KinematicModel
from agvsim.scenario_controllers import ControllerConfigBase
from agvsim.sensors.floor_codes import FloorCameraSpec, FloorCodeGrid
from agvsim.sensors.line_sensor import LineSensorSpec
from agvsim.sensors.reflectors import ReflectorMap
from agvsim.sensors.safety_fields import FieldSet, SafetyScannerSpec, check_fields
from agvsim.world.tape import Arc, Spot, Tape

Point = tuple[float, float]
Polygon = Annotated[list[Point], Field(min_length=3, max_length=256)]
Name = Annotated[str, Field(min_length=1, max_length=64)]
JunctionChoice = Literal["left", "right", "straight"]


# ---------------------------------------------------------------------------------- world
class ArcConfig(StrictConfig):
    center: Point
    radius_m: float = Field(gt=0, le=10_000)
    start_deg: float = Field(ge=-3600, le=3600)
    sweep_deg: float = Field(ge=-3600, le=3600)


class TapeLineConfig(StrictConfig):
    """One piece of tape: a polyline ``points`` or an ``arc``."""

    points: Annotated[list[Point], Field(min_length=2, max_length=100_000)] | None = None
    arc: ArcConfig | None = None

    @model_validator(mode="after")
    def _one_shape(self) -> TapeLineConfig:
        if (self.points is None) == (self.arc is None):
            raise ValueError("give either points (a polyline) or arc, not both or neither")
        return self


class SpotConfig(StrictConfig):
    x_m: float
    y_m: float
    code: int = Field(ge=0, le=2**31 - 1)


class TapeConfig(StrictConfig):
    """Guidance tape on the floor (agvsim.world.tape)."""

    width_m: float = Field(0.05, gt=0, le=1)
    lines: Annotated[list[TapeLineConfig], Field(max_length=10_000)] = []
    spots: Annotated[list[SpotConfig], Field(max_length=100_000)] = []


class FloorCodesConfig(StrictConfig):
    """A grid of 2-D codes on the floor (agvsim.sensors.floor_codes)."""

    cols: int = Field(ge=1, le=1000)
    rows: int = Field(ge=1, le=1000)
    spacing_m: float = Field(1.0, gt=0, le=100)
    size_m: float = Field(0.05, gt=0, le=10)
    origin_xy_m: Point = (0.0, 0.0)
    kind: Literal["aruco", "apriltag", "qr"] = "aruco"  # qr: the text is the id
    dictionary: str = Field("4x4_1000", max_length=32)


class ReflectorsConfig(StrictConfig):
    """Retro-reflectors for laser navigation (agvsim.sensors.reflectors)."""

    width_m: float = Field(0.08, gt=0, le=2)
    points: Annotated[list[Point], Field(max_length=100_000)] = []


# ---------------------------------------------------------------------------------- robots
class FieldSetConfig(StrictConfig):
    name: Name
    protective: Polygon
    warning: Polygon | None = None
    speed_min_m_s: float = Field(-math.inf, description="inclusive; default: any")
    speed_max_m_s: float = Field(math.inf, description="exclusive; default: any")
    steer_min_deg: float = Field(-math.inf, description="inclusive; default: any")
    steer_max_deg: float = Field(math.inf, description="exclusive; default: any")

    # the open ends are the one place an infinity is allowed
    model_config = StrictConfig.model_config | {"allow_inf_nan": True}

    @model_validator(mode="after")
    def _no_nan(self) -> FieldSetConfig:
        for name in ("speed_min_m_s", "speed_max_m_s", "steer_min_deg", "steer_max_deg"):
            if math.isnan(getattr(self, name)):
                raise ValueError(f"{name}: NaN is not allowed")
        for poly in (self.protective, self.warning or []):
            if not all(math.isfinite(v) for p in poly for v in p):
                raise ValueError("polygon points must be finite numbers")
        return self


class SafetyConfig(StrictConfig):
    """A safety laser scanner on the robot's range sensor ``sensor``."""

    sensor: Name
    field_sets: Annotated[list[FieldSetConfig], Field(min_length=1, max_length=64)]
    response_time_s: float = Field(0.1, ge=0, le=10)
    decel_m_s2: float = Field(1.0, gt=0, le=100)
    warning_speed_m_s: float = Field(0.3, ge=0, le=100)
    check_lengths: bool = Field(
        True, description="refuse fields too short for their speeds (stopping distance)"
    )


class LineSensorConfig(StrictConfig):
    type: Literal["line"]
    name: Name | None = None
    elements: int = Field(16, ge=2, le=256)
    span_m: float = Field(0.16, gt=0, le=5)
    mount_x_m: float = Field(0.3, ge=-50, le=50)
    noise_std_m: float = Field(0.0, ge=0, le=1)
    spot_radius_m: float = Field(0.05, gt=0, le=5)


class FloorCameraConfig(StrictConfig):
    type: Literal["floor_camera"]
    name: Name | None = None
    width_px: int = Field(160, ge=16, le=2048)
    height_px: int = Field(160, ge=16, le=2048)
    m_per_px: float = Field(0.001, gt=0, le=0.05)
    mount_x_m: float = Field(0.0, ge=-50, le=50)
    mount_y_m: float = Field(0.0, ge=-50, le=50)
    rate_hz: float = Field(10.0, gt=0, le=1000)


# ---------------------------------------------------------------------------------- builders
def build_tape(cfg: TapeConfig) -> Tape:
    lines: list = []
    for line in cfg.lines:
        if line.arc is not None:
            a = line.arc
            lines.append(Arc(a.center[0], a.center[1], a.radius_m, a.start_deg, a.sweep_deg))
        else:
            lines.append(line.points)
    return Tape(lines, cfg.width_m, [Spot(s.x_m, s.y_m, s.code) for s in cfg.spots])


def build_floor_codes(cfg: FloorCodesConfig) -> FloorCodeGrid:
    return FloorCodeGrid(
        cfg.cols, cfg.rows, cfg.spacing_m, cfg.size_m, cfg.origin_xy_m, cfg.kind, cfg.dictionary
    )


def build_reflectors(cfg: ReflectorsConfig) -> ReflectorMap:
    return ReflectorMap(np.asarray(cfg.points, dtype=np.float64).reshape(-1, 2), cfg.width_m)


def safety_spec(cfg: SafetyConfig, where: str) -> SafetyScannerSpec:
    """The scanner of a robot's ``safety:`` block (``where`` names the block in messages);
    its lengths are checked by :func:`safety_problems` once the robot is known."""
    try:
        return SafetyScannerSpec(
            cfg.sensor,
            tuple(
                FieldSet(
                    f.name,
                    tuple(f.protective),
                    None if f.warning is None else tuple(f.warning),
                    f.speed_min_m_s,
                    f.speed_max_m_s,
                    math.radians(f.steer_min_deg),
                    math.radians(f.steer_max_deg),
                )
                for f in cfg.field_sets
            ),
            cfg.response_time_s,
            cfg.decel_m_s2,
            cfg.warning_speed_m_s,
        )
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None


def top_speed_m_s(model: KinematicModel) -> float:
    """The fastest straight drive (m/s) the model's wheel-speed limit allows: the limit over
    the fastest wheel's spin per m/s of forward speed (inverse kinematics of (1, 0, 0))."""
    spin = float(np.abs(np.asarray(model.inverse(np.array([[1.0, 0.0, 0.0]])).speeds)).max())
    limit = float(np.min(np.asarray(model.max_wheel_speed_rad_s)))
    return limit / spin if spin > 0 else math.inf


def safety_problems(
    cfg: SafetyConfig,
    spec: SafetyScannerSpec,
    where: str,
    sensor_names: list[str],
    front_m: float,
    rear_m: float,
    top_speed: float,
    decel_limit_m_s2: float | None = None,
    scan_period_s: float = 0.0,
) -> list[str]:
    """What is wrong with a robot's scanner, one message each naming ``where`` (the robot's
    ``safety`` block) and its field sets: a ``sensor`` that is not one of the robot's range
    sensors (``sensor_names``), and (unless ``check_lengths: false``) protective fields too
    short to stop in at ``top_speed`` m/s forwards and backwards. ``decel_limit_m_s2``: the
    most the robot's dynamics can brake; below ``decel_m_s2`` it is what the check uses.
    ``scan_period_s``: the sensor's period, which adds to the response time (a return can
    enter the field just after a scan and is seen one period later)."""
    out: list[str] = []
    if spec.sensor not in sensor_names:
        out.append(
            f"{where}.sensor: {spec.sensor!r} is not a range sensor of this robot "
            f"(its lidar / rangers sensors: {sensor_names}; give the sensor's 'name')"
        )
    if not cfg.check_lengths:
        return out
    used = replace(spec, response_time_s=spec.response_time_s + scan_period_s)
    note = (
        f" (the response counts response_time_s {spec.response_time_s:g} s and the "
        f"sensor's scan period {scan_period_s:g} s)"
        if scan_period_s > 0
        else ""
    )
    if decel_limit_m_s2 is not None and decel_limit_m_s2 < spec.decel_m_s2:
        used = replace(used, decel_m_s2=max(decel_limit_m_s2, 1e-9))
        note += (
            f" (decel_m_s2 {spec.decel_m_s2:g} is not reachable: the robot's dynamics brake at "
            f"most {decel_limit_m_s2:.3f} m/s^2 on this floor, dynamics.braking's limit, "
            "which this check uses)"
        )
    names = {f.name: j for j, f in enumerate(spec.field_sets)}
    for problem in check_fields(used, front_m, rear_m, top_speed, top_speed):
        head = re.match(r"field set '(.*?)': ", problem)
        if head and head.group(1) in names:
            j = names[head.group(1)]
            out.append(f"{where}.field_sets[{j}]: {problem[head.end() :]}{note}")
        else:
            out.append(f"{where}.field_sets: {problem}{note}")
    if len(out) > (spec.sensor not in sensor_names):
        out[-1] += " (or set check_lengths: false to run with them anyway)"
    return out


def line_sensor_spec(cfg: LineSensorConfig, name: str) -> LineSensorSpec:
    return LineSensorSpec(
        name, cfg.elements, cfg.span_m, cfg.mount_x_m, cfg.noise_std_m, cfg.spot_radius_m
    )


def floor_camera_spec(cfg: FloorCameraConfig, name: str) -> FloorCameraSpec:
    return FloorCameraSpec(
        name,
        cfg.width_px,
        cfg.height_px,
        cfg.m_per_px,
        (cfg.mount_x_m, cfg.mount_y_m),
        cfg.rate_hz,
    )


# ---------------------------------------------------------------------------------- behaviours
class LineFollowConfig(ControllerConfigBase):
    """``controller: {type: line_follow, sensor: line, speed_m_s: 0.5, junctions: [left]}``"""

    model_config = ConfigDict(str_max_length=200)

    type: Literal["line_follow"]
    sensor: Name = "line"
    speed_m_s: float = Field(0.5, gt=0, le=100)
    kp: float = Field(20.0, ge=0, le=10_000, description="rad/s per metre of offset")
    ki: float = Field(0.0, ge=0, le=10_000)
    kd: float = Field(1.0, ge=0, le=10_000)
    slow_offset_m: float = Field(0.05, gt=0, le=10, description="offset at the slowest speed")
    min_speed_frac: float = Field(0.3, gt=0, le=1)
    junctions: Annotated[list[JunctionChoice], Field(max_length=10_000)] = []
    spot_choices: dict[Annotated[int, Field(ge=0, le=2**31 - 1)], JunctionChoice] = Field(
        default={}, description="spot code -> the choice at the next junction"
    )


class RouteConfig(ControllerConfigBase):
    """``controller: {type: route, points: [[0, 0], [5, 0]], localization: floor_codes}``"""

    model_config = ConfigDict(str_max_length=200)

    type: Literal["route"]
    points: Annotated[list[Point], Field(min_length=2, max_length=100_000)]
    localization: Literal["odometry", "floor_codes", "reflectors"] = "odometry"
    lookahead_m: float = Field(0.6, gt=0, le=100)
    speed_m_s: float = Field(0.5, gt=0, le=100)
    tolerance_m: float = Field(0.15, gt=0, le=100)
    max_turn_rate_rad_s: float = Field(1.5, gt=0, le=100)
    camera: Name = Field("floor_camera", description="the floor camera (floor_codes)")
    sensor: Name = Field("lidar", description="the lidar that sees the reflectors")
    range_std_m: float = Field(0.02, gt=0, le=10, description="reflector filter")
    bearing_std_deg: float = Field(0.3, gt=0, le=90, description="reflector filter")
    gate_m: float = Field(0.5, gt=0, le=100, description="reflector association gate")
    odom_noise_per_m: float = Field(0.02, gt=0, le=10, description="reflector filter")


def build_line_follow(cfg: LineFollowConfig, ctx: ControllerContext) -> LineFollower:
    names = [s.name for s in getattr(ctx.spec, "line_sensors", ())]
    if cfg.sensor not in names:
        raise ValueError(f"sensor: the robot has no line sensor {cfg.sensor!r} (it has {names})")
    return construct(LineFollower, cfg, junctions=tuple(cfg.junctions))


def build_route(cfg: RouteConfig, ctx: ControllerContext) -> RouteFollower:
    world = ctx.world
    if cfg.localization == "floor_codes":
        names = [c.name for c in getattr(ctx.spec, "floor_cameras", ())]
        if cfg.camera not in names:
            raise ValueError(
                f"camera: localization floor_codes needs a floor_camera sensor {cfg.camera!r} "
                f"(the robot has {names})"
            )
        if getattr(world, "floor_codes", None) is None:
            raise ValueError("localization: floor_codes needs a world.floor_codes block")
    reflectors = getattr(world, "reflectors", None)
    if cfg.localization == "reflectors":
        names = [s.name for s in getattr(ctx.spec, "sensors", ())]
        if cfg.sensor not in names:
            raise ValueError(
                f"sensor: localization reflectors needs a range sensor {cfg.sensor!r} "
                f"(the robot has {names})"
            )
        if reflectors is None:
            raise ValueError("localization: reflectors needs a world.reflectors block")
    return construct(
        RouteFollower,
        cfg,
        reflectors=reflectors,
        bearing_std_rad=math.radians(cfg.bearing_std_deg),
        odom_noise=(cfg.odom_noise_per_m, cfg.odom_noise_per_m),
    )
