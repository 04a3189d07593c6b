"""From a controller's command to the motion a model really makes, with every limit applied.

Both control modes end in the same place: driven-wheel speeds (saturated together, so the
direction of motion is kept) and a steering angle (clamped and rate limited), then the forward
kinematics gives the body twist that is integrated. So in either mode the executed twist is
``forward(drive, steering)`` and the driven wheels never exceed their limits (passive
wheels, such as a tricycle's rear wheels, turn as the motion requires).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agvsim.kinematics.base import KinematicModel, saturation_scale


@dataclass(frozen=True)
class Actuation:
    twist: np.ndarray  # (N, 3) executed body twist
    drive: np.ndarray  # (N, D) driven wheel speeds, rad/s
    wheel_speeds: np.ndarray  # (N, W) every wheel, rad/s
    steer_angles: np.ndarray  # (N, S) every steered wheel, rad
    steering: np.ndarray  # (N,) bicycle steering angle, rad (0 for models without)


def limit_steering(
    model: KinematicModel, target: np.ndarray, current: np.ndarray, dt: float
) -> np.ndarray:
    """Clamp the steering target to +-max_steer and move towards it at most max_rate * dt."""
    if not model.has_steering:
        return np.zeros_like(current)
    max_angle, max_rate = model.steering_limits()
    target = np.clip(target, -np.asarray(max_angle), np.asarray(max_angle))
    step = np.asarray(max_rate) * dt
    return current + np.clip(target - current, -step, step)


def forward_command(model: KinematicModel, twists: np.ndarray) -> np.ndarray:
    """The forward-mode command ``(N, D [+ 1])`` asking for body twists ``(N, 3)``: the driven
    wheel speeds from the model's inverse kinematics, then the steering angle for car-like
    models (what a twist-level behaviour hands a robot driven in forward mode)."""
    wheels = model.inverse(np.asarray(twists, dtype=np.float64))
    drive = wheels.speeds[..., list(model.driven_wheels)]
    if model.has_steering:
        return np.concatenate([drive, wheels.steering[..., None]], axis=-1)
    return drive


def from_drive(model: KinematicModel, drive: np.ndarray, steering: np.ndarray) -> Actuation:
    """Saturate driven wheel speeds ``(N, D)`` and apply them with steering ``(N,)`` (already
    limited)."""
    drive = np.asarray(drive, dtype=np.float64)
    drive = drive * saturation_scale(drive, model.max_wheel_speed_rad_s)[..., None]
    twist = model.forward(drive, steering)
    if not model.has_steering and len(model.driven_wheels) == len(model.wheel_names):
        # every wheel is driven (differential, Mecanum, omni): the drive is the whole story
        return Actuation(twist, drive, drive, np.zeros(drive.shape[:-1] + (0,)), steering)
    speeds = model.inverse(twist).speeds.copy()  # passive wheels turn as the motion requires
    speeds[..., list(model.driven_wheels)] = drive
    steer_angles = model.steer_angles_for(steering)  # type: ignore[attr-defined]
    return Actuation(twist, drive, speeds, steer_angles, steering)


def from_twist(
    model: KinematicModel, twist: np.ndarray, steering_now: np.ndarray, dt: float
) -> Actuation:
    """Inverse mode: command body twists ``(N, 3)``. Unreachable parts are dropped (vy for
    non-holonomic models), steering is limited, wheel speeds saturated."""
    t = np.array(twist, dtype=np.float64)
    if not model.holonomic:
        t[..., 1] = 0.0
    if model.has_steering:
        target = model.inverse(t).steering
        still = (np.abs(t[..., 0]) < 1e-12) & (np.abs(t[..., 2]) < 1e-12)
        target = np.where(still, steering_now, target)
        steering = limit_steering(model, target, steering_now, dt)
    else:
        steering = np.zeros(t.shape[:-1])
    return from_drive(model, model.drive_for(t, steering), steering)


def from_wheels(
    model: KinematicModel,
    drive: np.ndarray,
    steering_target: np.ndarray,
    steering_now: np.ndarray,
    dt: float,
) -> Actuation:
    """Forward mode: command driven wheel speeds ``(N, D)`` rad/s and, for car-like models,
    a steering angle ``(N,)`` rad."""
    steering = limit_steering(model, np.asarray(steering_target, float), steering_now, dt)
    return from_drive(model, drive, steering)
