"""The actuation of the car-like models (tricycle, Ackermann) in one numba kernel a group.

:mod:`agvsim.kinematics.actuation` is the reference: ``from_twist`` and ``from_wheels`` in
NumPy, batched over robots. On the few robots of a simulation step their dozens of small NumPy
calls cost more than the sums (60 and 90 microseconds a call for one tricycle and one
Ackermann robot, against 16 for a differential drive), so the engine runs the same equations,
in the same order, row by row in :func:`actuate_car`. Both modes, mixed in one group:

* inverse (a twist): vy dropped; the steering target is the bicycle wheel's heading for the
  twist (the present angle when the twist is zero), clamped and rate limited; the driven
  wheels get ``drive_for`` that steering;
* forward (wheel speeds and a steering angle): the angle clamped and rate limited;

then the driven wheels are saturated together, the forward kinematics gives the executed twist,
the passive wheels turn as it requires and each steered wheel gets its angle.
``tests/test_kinematics_fused.py`` holds the kernel to the NumPy path.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from agvsim.angles import wrap_scalar
from agvsim.kinematics.ackermann import Ackermann
from agvsim.kinematics.tricycle import Tricycle

__all__ = ["ACKERMANN", "PARAMS", "TRICYCLE", "actuate_car", "car_kind", "car_params"]

TRICYCLE, ACKERMANN = 0, 1
# the columns of car_params, in the kernel's order
PARAMS = (
    "wheel_radius_m",
    "wheelbase_m",
    "half_track_m",
    "max_wheel_speed_rad_s",
    "max_steer_rad",
    "max_steer_rate_rad_s",
)


def car_kind(model: Any) -> int | None:
    """TRICYCLE or ACKERMANN for a model the kernel runs; None for any other."""
    if type(model) is Tricycle:
        return TRICYCLE
    if type(model) is Ackermann:
        return ACKERMANN
    return None


def car_params(model: Any, k: int) -> np.ndarray:
    """``(k, 6)`` parameters of a (stacked) car-like model, columns :data:`PARAMS`."""
    out = np.empty((k, len(PARAMS)))
    for c, name in enumerate(PARAMS):
        out[:, c] = np.asarray(getattr(model, name), dtype=np.float64)
    return out


@njit(cache=True, error_model="numpy")
def _heading(ux: float, uy: float) -> tuple[float, float]:
    """``base.contact_heading`` for one wheel: (angle in (-pi/2, pi/2], signed speed)."""
    angle = math.atan2(uy, ux)
    speed = math.hypot(ux, uy)
    if angle > math.pi / 2 or angle <= -math.pi / 2:
        angle = wrap_scalar(angle + math.pi)
        speed = -speed
    if abs(ux) < 1e-12 and abs(uy) < 1e-12:
        return 0.0, 0.0
    return angle, speed


@njit(cache=True, error_model="numpy")
def actuate_car(
    kind: int,
    parallel: bool,
    p: np.ndarray,  # (k, 6) car_params
    is_twist: np.ndarray,  # (k,) bool
    cmd_twist: np.ndarray,  # (k, 3)
    cmd_wheels: np.ndarray,  # (k, >= D + 1): driven wheel speeds, then the steering angle
    steer_now: np.ndarray,  # (k,)
    dt: float,
    twist: np.ndarray,  # out (k, 3) executed twist
    wheels: np.ndarray,  # out (k, W) every wheel's speed, the model's wheel_names order
    steering: np.ndarray,  # out (k,) bicycle steering angle
    angles: np.ndarray,  # out (k, S) every steered wheel's angle
) -> None:
    """One step's actuation of ``k`` robots of one car-like model (see the module's text)."""
    n_drive = 1 if kind == TRICYCLE else 2
    for i in range(p.shape[0]):
        r, L, l, max_w, max_d, rate = p[i, 0], p[i, 1], p[i, 2], p[i, 3], p[i, 4], p[i, 5]
        now = steer_now[i]
        vx, w = cmd_twist[i, 0], cmd_twist[i, 2]
        if is_twist[i]:
            if abs(vx) < 1e-12 and abs(w) < 1e-12:
                target = now
            else:
                target = _heading(vx, w * L)[0]  # the front wheel at (L, 0)
        else:
            target = cmd_wheels[i, n_drive]
        target = min(max(target, -max_d), max_d)
        step = rate * dt
        s = now + min(max(target - now, -step), step)
        # the driven wheels: drive_for the steering, or as commanded
        if is_twist[i]:
            if kind == TRICYCLE:
                d0 = (vx * math.cos(s) + w * L * math.sin(s)) / r
                d1 = 0.0
            else:
                wd = vx * math.tan(s) / L
                d0, d1 = (vx - wd * l) / r, (vx + wd * l) / r
        else:
            d0 = cmd_wheels[i, 0]
            d1 = cmd_wheels[i, 1] if kind == ACKERMANN else 0.0
        peak = abs(d0) if kind == TRICYCLE else max(abs(d0), abs(d1))
        scale = min(1.0, max_w / max(peak, 1e-300))
        d0, d1 = d0 * scale, d1 * scale
        steering[i] = s
        if kind == TRICYCLE:
            ox = r * d0 * math.cos(s)
            ow = r * d0 * math.sin(s) / L
            wheels[i, 0] = d0
            wheels[i, 1] = (ox - ow * l) / r
            wheels[i, 2] = (ox + ow * l) / r
            angles[i, 0] = s
        else:
            ox = r * (d0 + d1) / 2.0
            ow = ox * math.tan(s) / L
            wheels[i, 0] = _heading(ox - ow * l, ow * L)[1] / r
            wheels[i, 1] = _heading(ox + ow * l, ow * L)[1] / r
            wheels[i, 2], wheels[i, 3] = d0, d1
            if parallel:
                angles[i, 0], angles[i, 1] = s, s
            else:
                c = math.tan(s) / L  # curvature
                angles[i, 0] = math.atan(c * L / (1.0 - c * l))
                angles[i, 1] = math.atan(c * L / (1.0 + c * l))
        twist[i, 0], twist[i, 1], twist[i, 2] = ox, 0.0, ow
