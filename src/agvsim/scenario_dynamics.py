"""Scenario schema of planar dynamics: a robot's optional ``dynamics:`` block and the world's
optional ``floor:`` block (friction coefficient and regions), and their conversion to the
core's specs (``agvsim.dynamics.spec``). Documented in docs/dynamics.md.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from agvsim.config_base import StrictConfig
from agvsim.dynamics.spec import (
    DynamicsSpec,
    FloorFriction,
    FrictionModel,
    FrictionRegion,
    LoadSpec,
    MotorSpec,
    SteeringActuatorSpec,
)


class MotorConfig(StrictConfig):
    gear_ratio: float = Field(
        default=20.0, gt=0, le=10000, description="motor turns per wheel turn"
    )
    torque_max_nm: float = Field(default=1.0, gt=0, le=1e5, description="peak motor torque (shaft)")
    stall_torque_nm: float | None = Field(
        default=None, gt=0, le=1e5, description="torque-speed line at zero speed; default 3 x peak"
    )
    no_load_speed_rad_s: float | None = Field(
        default=None,
        gt=0,
        le=1e6,
        description="motor shaft speed at zero torque; default: flat curve",
    )
    rotor_inertia_kg_m2: float = Field(default=2e-5, gt=0, le=100)
    time_constant_s: float = Field(
        default=0.05, gt=0, le=100, description="wheel-speed controller, first order"
    )


class SteeringActuatorConfig(StrictConfig):
    torque_max_nm: float = Field(default=20.0, gt=0, le=1e5)
    inertia_kg_m2: float = Field(default=0.05, gt=0, le=1e3)
    time_constant_s: float = Field(default=0.05, gt=0, le=100)


class LoadConfig(StrictConfig):
    mass_kg: float = Field(default=0.0, ge=0, le=1e5, description="carried load, a point mass")
    x_m: float = Field(default=0.0, ge=-100, le=100, description="load position ahead of P")
    y_m: float = Field(default=0.0, ge=-100, le=100, description="load position left of P")


class DynamicsConfig(StrictConfig):
    """A robot's planar dynamics; leave the block out for a kinematic robot."""

    mass_kg: float = Field(default=40.0, gt=0, le=1e5, description="empty robot")
    yaw_inertia_kg_m2: float | None = Field(
        default=None, gt=0, le=1e6, description="about the centre of mass; default: a uniform box"
    )
    com_x_m: float | None = Field(
        default=None, ge=-100, le=100, description="centre of mass ahead of P; default: body centre"
    )
    com_y_m: float = Field(default=0.0, ge=-100, le=100)
    load: LoadConfig = LoadConfig()
    wheel_inertia_kg_m2: float = Field(
        default=0.01, gt=0, le=100, description="each wheel, no motor"
    )
    motor: MotorConfig = MotorConfig()
    steering: SteeringActuatorConfig = SteeringActuatorConfig()
    friction_model: Literal["coulomb", "tyre"] = "coulomb"
    slip_speed_m_s: float = Field(
        default=0.05, gt=0, le=10, description="slip speed where friction reaches (about) mu N"
    )
    max_substep_s: float | None = Field(
        default=None, gt=0, le=1, description="cap on the automatic sub-step"
    )


class FrictionRegionConfig(StrictConfig):
    name: str = ""
    x_min_m: float
    y_min_m: float
    x_max_m: float
    y_max_m: float
    mu: float = Field(gt=0, le=5, description="friction coefficient in the region")

    @model_validator(mode="after")
    def _ordered(self) -> FrictionRegionConfig:
        if not (self.x_max_m > self.x_min_m and self.y_max_m > self.y_min_m):
            raise ValueError(
                "a friction region needs x_max_m > x_min_m and y_max_m > y_min_m "
                f"(got x [{self.x_min_m}, {self.x_max_m}], y [{self.y_min_m}, {self.y_max_m}])"
            )
        return self


class FloorConfig(StrictConfig):
    """Wheel-floor friction for robots with dynamics (kinematic robots ignore it)."""

    mu: float = Field(default=0.8, gt=0, le=5, description="friction coefficient of the floor")
    regions: list[FrictionRegionConfig] = Field(
        default=[], description="rectangles with their own mu (a later one wins where they overlap)"
    )


def dynamics_spec(cfg: DynamicsConfig | None, body_offset_x_m: float) -> DynamicsSpec | None:
    """The core spec of a ``dynamics:`` block (None stays None); the centre of mass defaults
    to the body's centre, ``body_offset_x_m`` ahead of P."""
    if cfg is None:
        return None
    com_x = body_offset_x_m if cfg.com_x_m is None else cfg.com_x_m
    return DynamicsSpec(
        mass_kg=cfg.mass_kg,
        yaw_inertia_kg_m2=cfg.yaw_inertia_kg_m2,
        com_xy_m=(com_x, cfg.com_y_m),
        load=LoadSpec(cfg.load.mass_kg, (cfg.load.x_m, cfg.load.y_m)),
        wheel_inertia_kg_m2=cfg.wheel_inertia_kg_m2,
        motor=MotorSpec(**cfg.motor.model_dump()),
        steering=SteeringActuatorSpec(**cfg.steering.model_dump()),
        friction_model=FrictionModel(cfg.friction_model),
        slip_speed_m_s=cfg.slip_speed_m_s,
        max_substep_s=cfg.max_substep_s,
    )


def floor_spec(cfg: FloorConfig | None) -> FloorFriction:
    if cfg is None:
        return FloorFriction()
    return FloorFriction(
        cfg.mu,
        tuple(
            FrictionRegion(r.x_min_m, r.y_min_m, r.x_max_m, r.y_max_m, r.mu, r.name)
            for r in cfg.regions
        ),
    )
