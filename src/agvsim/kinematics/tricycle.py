"""Tricycle drive: one steered, driven front wheel and two passive rear wheels (thesis 4.2.1).

Reference point P is the rear axle centre; ``wheelbase_m`` L from P to the front wheel;
``half_track_m`` l from P to each rear wheel. The command is the front wheel speed u (rad/s) and
its steering angle delta (the bicycle model):

    forward:  vx = r u cos(delta),   vy = 0,   omega = r u sin(delta) / L
    inverse:  delta = atan(L omega / vx),  u = vx / (r cos delta)  (= |(vx, L omega)| / r, signed)
              rear wheels (R -/+ l) vx / (R r) = (vx -/+ omega l) / r  with R = L / tan(delta)
The front wheel may steer to +-90 deg (turning on the spot about the rear axle centre) unless
``max_steer_rad`` says less.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from agvsim.kinematics.base import WheelState, as_twists, columns, wheel_heading
from agvsim.kinematics.params import check_params, param


@dataclass(frozen=True)
class Tricycle:
    wheel_radius_m: float | np.ndarray = param(0.1, doc="r: wheel radius")
    wheelbase_m: float | np.ndarray = param(0.5, doc="L: rear axle centre to the front axle")
    half_track_m: float | np.ndarray = param(0.2, doc="l: rear axle centre to each rear wheel")
    max_wheel_speed_rad_s: float | np.ndarray = param(20.0, doc="every wheel's speed limit")
    max_steer_rad: float | np.ndarray = param(np.pi / 2, doc="steering angle limit")
    max_steer_rate_rad_s: float | np.ndarray = param(3.0, doc="steering rate limit")

    kind: ClassVar[str] = "tricycle"
    wheel_names: ClassVar[tuple[str, ...]] = ("front", "rear_left", "rear_right")
    driven_wheels: ClassVar[tuple[int, ...]] = (0,)
    steered_wheels: ClassVar[tuple[int, ...]] = (0,)
    has_steering: ClassVar[bool] = True
    holonomic: ClassVar[bool] = False

    def __post_init__(self) -> None:
        check_params(self)

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray:
        """drive ``(N, 1)`` front wheel rad/s, steering ``(N,)`` rad -> twist ``(N, 3)``."""
        r, L = self.wheel_radius_m, self.wheelbase_m
        u = drive[..., 0]
        d = np.zeros_like(u) if steering is None else steering
        return columns(r * u * np.cos(d), 0.0, r * u * np.sin(d) / L)

    def inverse(self, twist: np.ndarray) -> WheelState:
        t = as_twists(twist)
        r, L, l = self.wheel_radius_m, self.wheelbase_m, self.half_track_m
        vx, w = t[..., 0], t[..., 2]
        planar = columns(vx, 0.0, w)
        delta, speed = wheel_heading(L, 0.0, planar)
        speeds = columns(speed / r, (vx - w * l) / r, (vx + w * l) / r)
        return WheelState(speeds, delta[..., None], delta)

    def drive_for(self, twist: np.ndarray, steering: np.ndarray) -> np.ndarray:
        """Front wheel speed that best realises ``twist`` with the wheel held at ``steering``:
        the projection of the wheel's required velocity (vx, L omega) on its rolling direction."""
        r, L = self.wheel_radius_m, self.wheelbase_m
        u = (twist[..., 0] * np.cos(steering) + twist[..., 2] * L * np.sin(steering)) / r
        return u[..., None]

    def steer_angles_for(self, steering: np.ndarray) -> np.ndarray:
        return np.asarray(steering, dtype=np.float64)[..., None]

    def wheel_positions_m(self) -> np.ndarray:
        L = np.asarray(self.wheelbase_m, dtype=np.float64)
        l = np.asarray(self.half_track_m, dtype=np.float64) + 0.0 * L
        L = L + 0.0 * l
        z = np.zeros_like(L)
        pts = [(L, z), (z, l), (z, -l)]
        return np.stack([np.stack(p, -1) for p in pts], axis=-2)

    def steering_limits(self) -> tuple[float | np.ndarray, float | np.ndarray]:
        return (self.max_steer_rad, self.max_steer_rate_rad_s)
