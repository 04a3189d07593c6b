"""Kinematic models of wheeled robots, batched over robots.

``MODELS`` is the registry: scenario files name a model by its key.
"""

from agvsim.kinematics.ackermann import Ackermann
from agvsim.kinematics.actuation import Actuation, from_drive, from_twist, from_wheels
from agvsim.kinematics.base import (
    KinematicModel,
    WheelState,
    integrate_se2,
    saturation_scale,
    stack_models,
    wrap_angle,
)
from agvsim.kinematics.differential import DifferentialDrive
from agvsim.kinematics.mecanum import Mecanum
from agvsim.kinematics.omni3 import Omni3
from agvsim.kinematics.tricycle import Tricycle

MODELS: dict[str, type] = {
    "differential": DifferentialDrive,
    "tricycle": Tricycle,
    "ackermann": Ackermann,
    "mecanum": Mecanum,
    "omni3": Omni3,
}

__all__ = [
    "MODELS",
    "Ackermann",
    "Actuation",
    "DifferentialDrive",
    "KinematicModel",
    "Mecanum",
    "Omni3",
    "Tricycle",
    "WheelState",
    "from_drive",
    "from_twist",
    "from_wheels",
    "integrate_se2",
    "saturation_scale",
    "stack_models",
    "wrap_angle",
]
