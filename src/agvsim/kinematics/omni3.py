"""Three-wheel omni (kiwi) drive: omni wheels 120 deg apart at ``base_radius_m`` R from the
centre (the thesis's future work). Wheel i sits at angle a_i = (0, 120, 240) deg in the robot
frame ("front", "rear_left", "rear_right") and rolls along the tangent (-sin a_i, cos a_i):

    inverse:  phi_i = (-sin(a_i) vx + cos(a_i) vy + R omega) / r
    forward:  vx = (2 r / 3) sum(-sin(a_i) phi_i),  vy = (2 r / 3) sum(cos(a_i) phi_i),
              omega = r / (3 R) sum(phi_i)
(the forward matrix is the exact inverse because sum sin^2 = sum cos^2 = 3/2 for 120 deg spacing)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from agvsim.kinematics.base import WheelState, as_twists, columns
from agvsim.kinematics.params import check_params, param

_A = np.deg2rad([0.0, 120.0, 240.0])
_S, _C = np.sin(_A), np.cos(_A)


@dataclass(frozen=True)
class Omni3:
    wheel_radius_m: float | np.ndarray = param(0.05, doc="r: wheel radius")
    base_radius_m: float | np.ndarray = param(0.2, doc="R: centre to each wheel")
    max_wheel_speed_rad_s: float | np.ndarray = param(30.0, doc="every wheel's speed limit")

    kind: ClassVar[str] = "omni3"
    wheel_names: ClassVar[tuple[str, ...]] = ("front", "rear_left", "rear_right")
    driven_wheels: ClassVar[tuple[int, ...]] = (0, 1, 2)
    steered_wheels: ClassVar[tuple[int, ...]] = ()
    has_steering: ClassVar[bool] = False
    holonomic: ClassVar[bool] = True

    def __post_init__(self) -> None:
        check_params(self)

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray:
        r, R = self.wheel_radius_m, self.base_radius_m
        vx = 2.0 * r / 3.0 * (drive @ -_S)
        vy = 2.0 * r / 3.0 * (drive @ _C)
        om = r / (3.0 * R) * drive.sum(axis=-1)
        return columns(vx, vy, om)

    def inverse(self, twist: np.ndarray) -> WheelState:
        t = as_twists(twist)
        n = t.shape[:-1]
        return WheelState(self.drive_for(t, None), np.zeros(n + (0,)), np.zeros(n))

    def drive_for(self, twist: np.ndarray, steering: np.ndarray | None) -> np.ndarray:
        r = np.asarray(self.wheel_radius_m, dtype=np.float64)[..., None]
        R = np.asarray(self.base_radius_m, dtype=np.float64)[..., None]
        vx, vy, om = twist[..., 0:1], twist[..., 1:2], twist[..., 2:3]
        return (-_S * vx + _C * vy + R * om) / r

    def wheel_positions_m(self) -> np.ndarray:
        R = np.asarray(self.base_radius_m, dtype=np.float64)[..., None]
        return np.stack([R * _C, R * _S], axis=-1)

    def steering_limits(self) -> tuple[float, float]:
        return (0.0, 0.0)
