"""Differential drive: two fixed driven wheels on one axle (thesis eq. 1-2, Siegwart et al.).

Reference point P is the axle centre; ``half_track_m`` is l, the distance from P to each wheel.

    forward:  vx = r (phi_r + phi_l) / 2,   vy = 0,   omega = r (phi_r - phi_l) / (2 l)
    inverse:  phi_r = (vx + omega l) / r,   phi_l = (vx - omega l) / r      (vy is not reachable)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from agvsim.kinematics.base import WheelState, as_twists, columns
from agvsim.kinematics.params import check_params, param


@dataclass(frozen=True)
class DifferentialDrive:
    wheel_radius_m: float | np.ndarray = param(0.1, doc="r: wheel radius")
    half_track_m: float | np.ndarray = param(0.25, doc="l: axle centre to each wheel")
    max_wheel_speed_rad_s: float | np.ndarray = param(20.0, doc="every wheel's speed limit")

    kind: ClassVar[str] = "differential"
    wheel_names: ClassVar[tuple[str, ...]] = ("left", "right")
    driven_wheels: ClassVar[tuple[int, ...]] = (0, 1)
    steered_wheels: ClassVar[tuple[int, ...]] = ()
    has_steering: ClassVar[bool] = False
    holonomic: ClassVar[bool] = False

    def __post_init__(self) -> None:
        check_params(self)

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray:
        """drive ``(N, 2)`` = (phi_left, phi_right) rad/s -> twist ``(N, 3)``."""
        r, l = self.wheel_radius_m, self.half_track_m
        pl, pr = drive[..., 0], drive[..., 1]
        vx = r * (pr + pl) / 2.0
        w = r * (pr - pl) / (2.0 * l)
        return columns(vx, 0.0, w)

    def inverse(self, twist: np.ndarray) -> WheelState:
        t = as_twists(twist)
        speeds = self.drive_for(t, None)
        n = t.shape[:-1]
        return WheelState(speeds, np.zeros(n + (0,)), np.zeros(n))

    def drive_for(self, twist: np.ndarray, steering: np.ndarray | None) -> np.ndarray:
        r, l = self.wheel_radius_m, self.half_track_m
        vx, w = twist[..., 0], twist[..., 2]
        return columns((vx - w * l) / r, (vx + w * l) / r)

    def wheel_positions_m(self) -> np.ndarray:
        l = np.asarray(self.half_track_m, dtype=np.float64)
        z = np.zeros_like(l)
        return np.stack([np.stack([z, l], -1), np.stack([z, -l], -1)], axis=-2)

    def steering_limits(self) -> tuple[float, float]:
        return (0.0, 0.0)
