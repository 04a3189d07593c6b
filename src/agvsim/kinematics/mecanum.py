"""Four Mecanum (Swedish 45 deg) wheels (thesis eq. 5-6, Hamid, Qiao & Ghaeminezhad 2015).

Wheels 1 front-left, 2 front-right, 3 rear-left, 4 rear-right at (+-lx, +-ly); k = lx + ly.

    forward:  vx = r/4 (w1 + w2 + w3 + w4)
              vy = r/4 (-w1 + w2 + w3 - w4)
              omega = r/(4k) (-w1 + w2 - w3 + w4)
    inverse:  w1 = (vx - vy - k omega)/r   w2 = (vx + vy + k omega)/r
              w3 = (vx + vy - k omega)/r   w4 = (vx - vy + k omega)/r
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from agvsim.kinematics.base import WheelState, as_twists, columns
from agvsim.kinematics.params import check_params, param


@dataclass(frozen=True)
class Mecanum:
    wheel_radius_m: float | np.ndarray = param(0.05, doc="r: wheel radius")
    half_length_m: float | np.ndarray = param(0.2, doc="lx: centre to the front and rear axles")
    half_width_m: float | np.ndarray = param(
        0.2, doc="ly: centre to the left and right wheel planes"
    )
    max_wheel_speed_rad_s: float | np.ndarray = param(30.0, doc="every wheel's speed limit")

    kind: ClassVar[str] = "mecanum"
    wheel_names: ClassVar[tuple[str, ...]] = (
        "front_left",
        "front_right",
        "rear_left",
        "rear_right",
    )
    driven_wheels: ClassVar[tuple[int, ...]] = (0, 1, 2, 3)
    steered_wheels: ClassVar[tuple[int, ...]] = ()
    has_steering: ClassVar[bool] = False
    holonomic: ClassVar[bool] = True

    def __post_init__(self) -> None:
        check_params(self)

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray:
        r = self.wheel_radius_m
        k = self.half_length_m + self.half_width_m
        w1, w2, w3, w4 = drive[..., 0], drive[..., 1], drive[..., 2], drive[..., 3]
        vx = r / 4.0 * (w1 + w2 + w3 + w4)
        vy = r / 4.0 * (-w1 + w2 + w3 - w4)
        om = r / (4.0 * k) * (-w1 + w2 - w3 + w4)
        return columns(vx, vy, om)

    def inverse(self, twist: np.ndarray) -> WheelState:
        t = as_twists(twist)
        n = t.shape[:-1]
        return WheelState(self.drive_for(t, None), np.zeros(n + (0,)), np.zeros(n))

    def drive_for(self, twist: np.ndarray, steering: np.ndarray | None) -> np.ndarray:
        r = self.wheel_radius_m
        k = self.half_length_m + self.half_width_m
        vx, vy, om = twist[..., 0], twist[..., 1], twist[..., 2]
        return columns(
            (vx - vy - k * om) / r,
            (vx + vy + k * om) / r,
            (vx + vy - k * om) / r,
            (vx - vy + k * om) / r,
        )

    def wheel_positions_m(self) -> np.ndarray:
        lx = np.asarray(self.half_length_m, dtype=np.float64)
        ly = np.asarray(self.half_width_m, dtype=np.float64) + 0.0 * lx
        lx = lx + 0.0 * ly
        pts = [(lx, ly), (lx, -ly), (-lx, ly), (-lx, -ly)]
        return np.stack([np.stack(p, -1) for p in pts], axis=-2)

    def steering_limits(self) -> tuple[float, float]:
        return (0.0, 0.0)
