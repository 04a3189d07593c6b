"""Ackermann steering: two steered front wheels, two driven rear wheels (thesis 4.2.1, eq. 3-4).

Reference point P is the rear axle centre; ``wheelbase_m`` L, ``half_track_m`` l. The command
is the rear wheel speeds and the bicycle steering angle delta (the angle of a virtual wheel
midway between the front wheels):

    forward:  vx = r (phi_rl + phi_rr) / 2,   vy = 0,   omega = vx tan(delta) / L
    inverse:  R = L / tan(delta) = vx / omega
              rear wheels  (R -/+ l) vx / (R r) = (vx -/+ omega l) / r
              front wheels angle atan(L / (R -/+ l)), speed sqrt((R -/+ l)^2 + L^2) |omega| / r
The true Ackermann geometry gives each front wheel its own angle (inner wheel steers more).
``steering_geometry="parallel"`` reproduces the thesis's approximation (both wheels at delta).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from agvsim.kinematics.base import WheelState, as_twists, columns, contact_heading
from agvsim.kinematics.params import HALF_TURN, check_params, param


@dataclass(frozen=True)
class Ackermann:
    wheel_radius_m: float | np.ndarray = param(0.1, doc="r: wheel radius")
    wheelbase_m: float | np.ndarray = param(0.5, doc="L: rear axle centre to the front axle")
    half_track_m: float | np.ndarray = param(0.2, doc="l: axle centre to each wheel")
    max_wheel_speed_rad_s: float | np.ndarray = param(20.0, doc="every wheel's speed limit")
    max_steer_rad: float | np.ndarray = param(
        np.deg2rad(35.0), HALF_TURN, doc="steering angle limit"
    )
    max_steer_rate_rad_s: float | np.ndarray = param(2.0, doc="steering rate limit")
    steering_geometry: Literal["ackermann", "parallel"] = param(
        "ackermann", None, doc="ackermann: each front wheel its own angle; parallel: the thesis's"
    )

    kind: ClassVar[str] = "ackermann"
    wheel_names: ClassVar[tuple[str, ...]] = (
        "front_left",
        "front_right",
        "rear_left",
        "rear_right",
    )
    driven_wheels: ClassVar[tuple[int, ...]] = (2, 3)
    steered_wheels: ClassVar[tuple[int, ...]] = (0, 1)
    has_steering: ClassVar[bool] = True
    holonomic: ClassVar[bool] = False

    def __post_init__(self) -> None:
        check_params(self)

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray:
        """drive ``(N, 2)`` rear (left, right) rad/s, steering ``(N,)`` rad -> twist ``(N, 3)``."""
        r, L = self.wheel_radius_m, self.wheelbase_m
        vx = r * (drive[..., 0] + drive[..., 1]) / 2.0
        d = np.zeros_like(vx) if steering is None else steering
        return columns(vx, 0.0, vx * np.tan(d) / L)

    def inverse(self, twist: np.ndarray) -> WheelState:
        t = as_twists(twist)
        r, L, l = self.wheel_radius_m, self.wheelbase_m, self.half_track_m
        vx, w = t[..., 0], t[..., 2]
        # the bicycle wheel (L, 0) and the front wheels (L, l), (L, -l) in one call: a column
        # each; vy = 0, so a point (px, py) moves at (vx - omega py, 0 + omega px)
        lcol = np.asarray(l, dtype=np.float64)[..., None]
        py = np.concatenate([np.zeros_like(lcol), lcol, -lcol], axis=-1)
        wc = w[..., None]
        angle, speed = contact_heading(vx[..., None] - wc * py, 0.0 + wc * np.asarray(L)[..., None])
        delta, a_fl, a_fr = angle[..., 0], angle[..., 1], angle[..., 2]
        s_fl, s_fr = speed[..., 1], speed[..., 2]
        if self.steering_geometry == "parallel":
            a_fl, a_fr = delta, delta
        speeds = columns(s_fl / r, s_fr / r, (vx - w * l) / r, (vx + w * l) / r)
        return WheelState(speeds, columns(a_fl, a_fr), delta)

    def drive_for(self, twist: np.ndarray, steering: np.ndarray) -> np.ndarray:
        """Rear wheel speeds that keep the commanded forward speed with the wheels at
        ``steering`` (the yaw rate then follows from the steering: omega = vx tan(delta) / L)."""
        r, L, l = self.wheel_radius_m, self.wheelbase_m, self.half_track_m
        vx = twist[..., 0]
        w = vx * np.tan(steering) / L
        return columns((vx - w * l) / r, (vx + w * l) / r)

    def steer_angles_for(self, steering: np.ndarray) -> np.ndarray:
        """Per-wheel angles (front_left, front_right) for bicycle angle(s) ``steering``."""
        d = np.asarray(steering, dtype=np.float64)
        if self.steering_geometry == "parallel":
            return columns(d, d)
        L, l = self.wheelbase_m, self.half_track_m
        k = np.tan(d) / L  # curvature
        # wheel at (L, +-l): direction of (1 - k*(+-l), k L)
        # atan (not atan2): an inner wheel past 90 deg is reported folded into (-pi/2, pi/2],
        # as inverse() does, rolling backwards rather than turned round
        with np.errstate(divide="ignore"):
            return np.stack(
                [np.arctan(k * L / (1.0 - k * l)), np.arctan(k * L / (1.0 + k * l))], axis=-1
            )

    def wheel_positions_m(self) -> np.ndarray:
        L = np.asarray(self.wheelbase_m, dtype=np.float64)
        l = np.asarray(self.half_track_m, dtype=np.float64) + 0.0 * L
        L = L + 0.0 * l
        z = np.zeros_like(L)
        pts = [(L, l), (L, -l), (z, l), (z, -l)]
        return np.stack([np.stack(p, -1) for p in pts], axis=-2)

    def steering_limits(self) -> tuple[float | np.ndarray, float | np.ndarray]:
        return (self.max_steer_rad, self.max_steer_rate_rad_s)
