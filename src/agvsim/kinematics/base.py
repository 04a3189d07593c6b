"""Shared kinematics: the model protocol, SE(2) integration and wheel-limit helpers.

Arrays are batched over robots: a pose or twist array is ``(N, 3)``; wheel speeds are
``(N, W)`` in rad/s; steering angles are in rad. A model's parameters may be Python floats (one
shared value) or ``(N,)`` arrays (one value per robot); the equations broadcast either way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import ClassVar, Protocol, TypeVar

import numpy as np
from numba import njit

from agvsim.angles import wrap_angle, wrap_scalar


@njit(cache=True, error_model="numpy")
def se2_step(x: float, y: float, th: float, vx: float, vy: float, w: float, dt: float):
    """One pose moved by a body twist held for ``dt`` s, exactly (scalar kernel; see
    ``integrate_se2``). Returns (x, y, theta) with theta wrapped to (-pi, pi]."""
    a = w * dt
    if abs(a) < 1e-6:  # series of sin(a)/a and (1 - cos a)/a
        sa = 1.0 - a * a / 6.0
        ca = a / 2.0 - a * a * a / 24.0
    else:  # (1 - cos a)/a written as 2 sin^2(a/2)/a: no cancellation for small a
        sa = math.sin(a) / a
        h = math.sin(0.5 * a)
        ca = 2.0 * h * h / a
    dx = (vx * sa - vy * ca) * dt
    dy = (vx * ca + vy * sa) * dt
    ct, st = math.cos(th), math.sin(th)
    return x + ct * dx - st * dy, y + st * dx + ct * dy, wrap_scalar(th + a)


@njit(cache=True)
def _integrate_rows(poses: np.ndarray, twists: np.ndarray, dt: float, out: np.ndarray) -> None:
    for i in range(poses.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = se2_step(
            poses[i, 0], poses[i, 1], poses[i, 2], twists[i, 0], twists[i, 1], twists[i, 2], dt
        )


def integrate_se2(poses: np.ndarray, twists: np.ndarray, dt: float) -> np.ndarray:
    """Move poses ``(N, 3)`` (x, y, theta; world) by body twists ``(N, 3)`` (vx, vy, omega; robot
    frame) held constant for ``dt`` seconds, exactly (SE(2) exponential map, not Euler steps).

    In the robot frame at the start of the step the displacement is
        dx = (vx sin(w dt) - vy (1 - cos(w dt))) / w
        dy = (vx (1 - cos(w dt)) + vy sin(w dt)) / w
    with the limits vx dt, vy dt as w -> 0 (a Taylor series is used for small w dt).
    One scalar kernel (``se2_step``) does this for every caller.
    """
    p = np.asarray(poses, dtype=np.float64)
    t = np.asarray(twists, dtype=np.float64)
    shape = np.broadcast_shapes(p.shape, t.shape)
    p2 = np.ascontiguousarray(np.broadcast_to(p, shape).reshape(-1, 3))
    t2 = np.ascontiguousarray(np.broadcast_to(t, shape).reshape(-1, 3))
    out = np.empty_like(p2)
    _integrate_rows(p2, t2, float(dt), out)
    return out.reshape(shape)


def columns(*cols: np.ndarray | float) -> np.ndarray:
    """``np.stack(cols, axis=-1)`` as float64 for columns of the first one's shape (a number
    fills a whole column), without ``np.stack``'s per-call overhead: a simulation step calls
    the kinematics once per model on a few robots, where that overhead outweighs the sums."""
    out = np.empty(np.shape(cols[0]) + (len(cols),))
    for k, c in enumerate(cols):
        out[..., k] = c
    return out


def saturation_scale(speeds: np.ndarray, max_speed: np.ndarray | float) -> np.ndarray:
    """Per-robot factor in (0, 1] that brings every wheel speed of ``speeds (N, W)`` within
    ``max_speed`` rad/s. Scaling all wheels of a robot by one factor keeps the direction of
    the commanded motion (the twist is linear in the wheel speeds)."""
    if speeds.shape[-1] == 0:
        return np.ones(speeds.shape[:-1])
    peak = np.abs(speeds).max(axis=-1)
    return np.minimum(1.0, max_speed / np.maximum(peak, 1e-300))


def wheel_heading(px: np.ndarray | float, py: np.ndarray | float, twists: np.ndarray):
    """Steering angle and signed speed (m/s) that a steered standard wheel at (px, py) in the
    robot frame needs for body twist(s) ``(N, 3)``. The angle is in (-pi/2, pi/2]; driving
    backwards gives a negative speed rather than a flipped wheel."""
    vx, vy, w = twists[..., 0], twists[..., 1], twists[..., 2]
    return contact_heading(vx - w * py, vy + w * px)


def contact_heading(ux: np.ndarray, uy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``wheel_heading`` from the wheel's contact-point velocity (ux, uy) in the robot frame
    (several wheels at once when the arrays have a column per wheel)."""
    angle = np.arctan2(uy, ux)
    speed = np.hypot(ux, uy)
    flip = (angle > np.pi / 2) | (angle <= -np.pi / 2)
    if flip.any():  # (the common case, every wheel rolling forwards, skips both)
        angle = np.where(flip, wrap_angle(angle + np.pi), angle)
        speed = np.where(flip, -speed, speed)
    # no motion: keep the wheel straight
    still = (np.abs(ux) < 1e-12) & (np.abs(uy) < 1e-12)
    if still.any():
        angle, speed = np.where(still, 0.0, angle), np.where(still, 0.0, speed)
    return angle, speed


@dataclass(frozen=True)
class WheelState:
    """What the inverse kinematics gives for body twists ``(N, 3)``."""

    speeds: np.ndarray  # (N, W) rad/s of every wheel, in the model's ``wheel_names`` order
    steer_angles: np.ndarray  # (N, S) rad of every steered wheel, ``steered_wheels`` order
    steering: np.ndarray  # (N,) rad: the single steering command (bicycle angle), 0 if none


class KinematicModel(Protocol):
    """A wheeled-robot kinematic model.

    forward(drive, steering) -> twist: what the robot does for given driven-wheel speeds (and
    steering angle, for car-like models). inverse(twist) -> WheelState: every wheel's speed and
    every steered wheel's angle for a body twist. Both are batched over robots.
    """

    kind: ClassVar[str]
    wheel_names: ClassVar[tuple[str, ...]]
    driven_wheels: ClassVar[tuple[int, ...]]  # indices commanded in forward mode
    steered_wheels: ClassVar[tuple[int, ...]]  # indices that have a steering angle
    has_steering: ClassVar[bool]  # True when the command includes a steering angle
    holonomic: ClassVar[bool]

    @property
    def wheel_radius_m(self) -> float | np.ndarray: ...

    @property
    def max_wheel_speed_rad_s(self) -> float | np.ndarray: ...

    def forward(self, drive: np.ndarray, steering: np.ndarray | None = None) -> np.ndarray: ...

    def inverse(self, twist: np.ndarray) -> WheelState: ...

    def drive_for(self, twist: np.ndarray, steering: np.ndarray) -> np.ndarray: ...

    def wheel_positions_m(self) -> np.ndarray: ...

    def steering_limits(self) -> tuple[np.ndarray | float, np.ndarray | float]: ...


M = TypeVar("M")


def stack_models(models: list[M]) -> M:
    """One model whose parameters are ``(N,)`` arrays, from N models of the same class."""
    if not models:
        raise ValueError("stack_models needs at least one model")
    cls = type(models[0])
    if any(type(m) is not cls for m in models):
        raise TypeError("stack_models needs models of one class")
    values = {}
    for f in fields(models[0]):  # type: ignore[arg-type]
        vals = [getattr(m, f.name) for m in models]
        if isinstance(vals[0], int | float | np.floating | np.ndarray):
            values[f.name] = np.asarray(vals, dtype=np.float64)
        else:
            if any(v != vals[0] for v in vals):
                raise ValueError(f"models differ in non-numeric field {f.name!r}: {vals}")
            values[f.name] = vals[0]
    return replace(models[0], **values)  # type: ignore[type-var]


def as_twists(twist: np.ndarray) -> np.ndarray:
    t = np.asarray(twist, dtype=np.float64)
    if t.shape[-1] != 3:
        raise ValueError(f"a twist array must end in 3 values (vx, vy, omega), got shape {t.shape}")
    return t
