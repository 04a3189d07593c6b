"""What each kinematic model can do, and the motion primitives the behaviours share.

The behaviours (go to goal, pure pursuit, the A* maze solver) think in body twists and leave the
wheels to ``command_for``: a twist in inverse mode, the robot's own inverse kinematics (driven
wheel speeds + steering) in forward mode. How each model moves:

* **holonomic** (mecanum, omni3): translate straight at the target, sideways if need be;
  the heading is held (``GoToGoal``) or turned towards the direction of travel
  (``PurePursuit(face_travel=True)``).
* **can turn on the spot** (differential; tricycle with +-90 deg steering): turn towards the
  target, drive when it is roughly ahead.
* **car-like** (Ackermann; tricycle with less steering): the curvature is clipped to
  ``1 / R_min = tan(max_steer) / wheelbase``; the inverse kinematics turns curvature into a
  steering angle.

``Mobility`` reads these abilities off a model, ``pursuit_twist`` is the pure-pursuit law for
each kind and ``SteeringGuard`` lets a steered wheel reach its angle before the robot drives
on. Poses come from the ground truth (``pose_source="true_pose"``) or from wheel odometry
(``pose_of``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from agvsim.angles import wrap_scalar
from agvsim.control.api import Observation

PoseSource = Literal["true_pose", "odometry"]


def wrap(a: float) -> float:
    """Angle in rad wrapped to (-pi, pi] (:func:`agvsim.angles.wrap_scalar`)."""
    return float(wrap_scalar(a))


def pose_of(obs: Observation, source: str) -> np.ndarray:
    """(3,) x, y, theta from the ground truth or from wheel odometry."""
    return obs.true_pose if source == "true_pose" else obs.odom_pose


def check_pose_source(source: str) -> None:
    if source not in ("true_pose", "odometry"):
        raise ValueError(f"pose_source must be 'true_pose' or 'odometry', got {source!r}")


# ------------------------------------------------------------------------------------ model
@dataclass(frozen=True)
class Mobility:
    """What a kinematic model can do, as the behaviours need it."""

    holonomic: bool
    can_spin: bool
    max_curvature_1_m: float  # inf for models that turn on the spot
    wheelbase_m: float  # 0 for models without steering
    max_steer_rad: float
    max_steer_rate_rad_s: float

    @classmethod
    def of(cls, model: object) -> Mobility:
        if not getattr(model, "has_steering", False):
            return cls(bool(getattr(model, "holonomic", False)), True, math.inf, 0.0, 0.0, 0.0)
        max_steer = float(np.min(model.max_steer_rad))  # type: ignore[attr-defined]
        rate = float(np.min(model.max_steer_rate_rad_s))  # type: ignore[attr-defined]
        L = float(np.min(model.wheelbase_m))  # type: ignore[attr-defined]
        can_spin = max_steer >= math.pi / 2 - 1e-9
        kmax = math.inf if can_spin else math.tan(max_steer) / L
        return cls(False, can_spin, kmax, L, max_steer, rate)

    @property
    def car_like(self) -> bool:
        return not self.can_spin

    @property
    def min_radius_m(self) -> float:
        return 0.0 if self.can_spin else 1.0 / self.max_curvature_1_m


def pursuit_twist(
    pose: np.ndarray,
    target_xy: np.ndarray,
    speed_m_s: float,
    mob: Mobility,
    *,
    travel_heading_rad: float | None = None,
    max_turn_rate_rad_s: float = 1.5,
    spin_above_rad: float = 1.0,
    curve_slowdown_m: float = 0.5,
) -> tuple[float, float, float]:
    """The pure-pursuit body twist (vx, vy, omega) towards ``target_xy``.

    Curvature ``k = 2 sin(alpha) / d`` for a target at bearing alpha and distance d (the arc
    through the robot and the target, tangent to the heading). The speed drops in curves as
    ``v / (1 + curve_slowdown_m * |k|)``. Models that turn on the spot turn in place while
    ``|alpha| > spin_above_rad``; car-like models clip k to +-1/R_min (full lock when the
    target is behind). Holonomic models translate straight at the target and turn towards
    ``travel_heading_rad`` when given."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    dx, dy = float(target_xy[0]) - x, float(target_xy[1]) - y
    c, s = math.cos(th), math.sin(th)
    bx, by = c * dx + s * dy, -s * dx + c * dy
    dist = math.hypot(bx, by)
    if dist < 1e-9:
        return 0.0, 0.0, 0.0
    if mob.holonomic:
        w = 0.0
        if travel_heading_rad is not None:
            w = max(
                -max_turn_rate_rad_s, min(max_turn_rate_rad_s, 2.0 * wrap(travel_heading_rad - th))
            )
        return speed_m_s * bx / dist, speed_m_s * by / dist, w
    alpha = math.atan2(by, bx)
    k = 2.0 * math.sin(alpha) / dist
    if mob.can_spin:
        if abs(alpha) > spin_above_rad:
            return 0.0, 0.0, math.copysign(max_turn_rate_rad_s, alpha)
        v = speed_m_s / (1.0 + curve_slowdown_m * abs(k))
        if abs(v * k) > max_turn_rate_rad_s:
            v = max_turn_rate_rad_s / abs(k)
        return v, 0.0, v * k
    if abs(alpha) > math.pi / 2:
        k = math.copysign(mob.max_curvature_1_m, alpha)
    k = max(-mob.max_curvature_1_m, min(mob.max_curvature_1_m, k))
    v = speed_m_s / (1.0 + curve_slowdown_m * abs(k))
    return v, 0.0, v * k


class SteeringGuard:
    """Keeps a steered wheel (tricycle, Ackermann) from driving while far from its angle.

    The steering turns at a limited rate, so a command whose angle is far from the present one
    (a tricycle about to turn on the spot, a car changing lock) would drive the wheel while it
    swings. The guard tracks the angle the robot must have (it mirrors the engine: the inverse
    kinematics' angle in (-pi/2, pi/2], clamped, rate limited) and, while the angle a command
    needs is more than ``settle_rad`` away, sends a standing command with that angle instead
    (a speed of 1e-6 m/s along the wanted wheel direction). A turn on the spot gets a tiny
    forward speed so that clockwise turns ask for -90 deg rather than +90 deg."""

    def __init__(self, settle_rad: float = 0.35):
        self.settle_rad = settle_rad
        self.reset()

    def reset(self) -> None:
        self.angle_rad = 0.0
        self.waiting = False

    def _target(self, v: float, w: float, mob: Mobility) -> float:
        if abs(v) < 1e-12 and abs(w) < 1e-12:
            return self.angle_rad
        a = math.atan2(mob.wheelbase_m * w, v)
        if a > math.pi / 2 or a <= -math.pi / 2:
            a = wrap(a + math.pi)
        return max(-mob.max_steer_rad, min(mob.max_steer_rad, a))

    def __call__(
        self, v: float, vy: float, w: float, mob: Mobility, dt_s: float
    ) -> tuple[float, float, float]:
        self.waiting = False
        if mob.wheelbase_m == 0.0:
            return v, vy, w
        if abs(v) < 1e-6 and abs(w) > 1e-9:  # turn on the spot: keep the wheel on w's side
            v = 1e-6
        target = self._target(v, w, mob)
        step = mob.max_steer_rate_rad_s * dt_s
        self.angle_rad += max(-step, min(step, target - self.angle_rad))
        if abs(target - self.angle_rad) > self.settle_rad:
            self.waiting = True
            eps = 1e-6
            return eps * math.cos(target), 0.0, eps * math.sin(target) / mob.wheelbase_m
        return v, vy, w
