"""Normalised actions: a point of ``[-1, 1]^A`` -> the command a robot's control mode takes.

* **inverse** mode: a body twist. Non-holonomic models (differential, tricycle, ackermann)
  take ``A = 2``: ``(vx, omega)``; holonomic ones (mecanum, omni3) ``A = 3``:
  ``(vx, vy, omega)``. Each component is scaled by the model's own limit along that axis
  (``twist_limits``), so ``+1`` is the fastest the wheels allow along it alone; a combined
  command beyond the wheel limits is scaled down by the engine, keeping its direction.
* **forward** mode: the driven wheels' speeds, scaled by ``max_wheel_speed_rad_s``, then for
  car-like models (tricycle, ackermann) the steering angle, scaled by ``max_steer_rad``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agvsim.control.api import ControlMode
from agvsim.kinematics import Tricycle


def twist_limits(model) -> np.ndarray:
    """``(3,)`` the largest |vx| m/s, |vy| m/s and |omega| rad/s that ``model`` reaches along
    each axis alone with every driven wheel within ``max_wheel_speed_rad_s`` (and, for car-like
    models, the steering within ``max_steer_rad``); 0 for an axis it cannot move along.

    Hand-worked for the defaults: differential (r 0.1 m, 20 rad/s, l 0.25 m) vx 2 m/s, omega
    8 rad/s; mecanum (r 0.05 m, 30 rad/s, k 0.4 m) vx = vy = 1.5 m/s, omega 3.75 rad/s."""
    w_max = float(np.max(model.max_wheel_speed_rad_s))
    out = np.zeros(3)
    for axis in range(3):
        if (axis == 1 and not model.holonomic) or (axis == 2 and model.has_steering):
            continue
        unit = np.zeros((1, 3))
        unit[0, axis] = 1.0
        drive = np.abs(model.inverse(unit).speeds[0, list(model.driven_wheels)])
        peak = float(drive.max())
        out[axis] = w_max / peak if peak > 0 else 0.0
    if model.has_steering:
        steer = float(np.min(model.max_steer_rad))
        wheelbase = float(np.max(model.wheelbase_m))
        if isinstance(model, Tricycle):  # omega = r u sin(delta) / L, at most at delta = pi/2
            r = float(np.max(model.wheel_radius_m))
            out[2] = r * w_max * math.sin(min(steer, math.pi / 2)) / wheelbase
        else:  # bicycle: omega = vx tan(delta) / L
            out[2] = out[0] * math.tan(steer) / wheelbase
    return out


@dataclass(frozen=True)
class ActionMap:
    """How a normalised action of width ``width`` becomes a command of width ``cmd_width``
    (3 twist values in inverse mode; driven wheels (+ steering) in forward mode)."""

    mode: ControlMode
    names: tuple[str, ...]  # one per action component, e.g. ("vx", "omega")
    scale: np.ndarray  # (A,) the unit of each component: m/s, rad/s or rad
    columns: np.ndarray  # (A,) int: the command column each component lands in
    cmd_width: int

    @property
    def width(self) -> int:
        return len(self.names)

    @classmethod
    def for_model(cls, model, mode: ControlMode) -> ActionMap:
        if mode == ControlMode.INVERSE:
            limits = twist_limits(model)
            axes = [0, 1, 2] if model.holonomic else [0, 2]
            names = tuple(("vx", "vy", "omega")[a] for a in axes)
            return cls(mode, names, limits[axes], np.array(axes), 3)
        n_drive = len(model.driven_wheels)
        names = tuple(model.wheel_names[k] for k in model.driven_wheels)
        scale = [float(np.max(model.max_wheel_speed_rad_s))] * n_drive
        if model.has_steering:
            names += ("steering",)
            scale.append(float(np.min(model.max_steer_rad)))
        return cls(mode, names, np.array(scale), np.arange(len(names)), len(names))

    def to_command(self, actions: np.ndarray) -> np.ndarray:
        """``(N, A)`` actions, clipped to [-1, 1] -> ``(N, cmd_width)`` commands (float64)."""
        a = np.clip(np.asarray(actions, dtype=np.float64), -1.0, 1.0)
        cmd = np.zeros((a.shape[0], self.cmd_width))
        cmd[:, self.columns] = a * self.scale
        return cmd


def check_actions(actions: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``actions`` as a float64 array of ``shape`` holding finite numbers, or a ValueError that
    names the expected shape and what came instead."""
    try:
        a = np.asarray(actions, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what}: expected numbers in an array of shape {shape}, got {actions!r}"
        ) from None
    if a.shape != shape:
        raise ValueError(f"{what}: expected an array of shape {shape}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what}: every component must be a finite number, got {a.tolist()}")
    return a
