"""Planar dynamics (optional per robot): mass, inertia, motors, steering actuators and
wheel-floor friction with slip. See docs/dynamics.md."""

from agvsim.dynamics.braking import (
    braking_deceleration_m_s2,
    friction_deceleration_m_s2,
    stopping_distance_m,
)
from agvsim.dynamics.spec import (
    DynamicsSpec,
    FloorFriction,
    FrictionModel,
    FrictionRegion,
    LoadSpec,
    MotorSpec,
    SteeringActuatorSpec,
)

__all__ = [
    "DynamicsSpec",
    "FloorFriction",
    "FrictionModel",
    "FrictionRegion",
    "LoadSpec",
    "MotorSpec",
    "SteeringActuatorSpec",
    "braking_deceleration_m_s2",
    "friction_deceleration_m_s2",
    "stopping_distance_m",
]
