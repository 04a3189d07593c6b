"""What a robot's planar dynamics is made of (static description, built once, never stepped).

A robot with a ``DynamicsSpec`` is a rigid body of ``mass_kg`` and ``yaw_inertia_kg_m2`` whose
wheels push on the floor through friction; without one it moves kinematically, as before.
The floor's friction coefficient comes from ``FloorFriction`` (one value, with rectangular
regions of their own: a wet or dusty patch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

G_M_S2 = 9.81  # standard gravity used for the normal loads


class FrictionModel(StrEnum):
    """How the friction force grows with the slip speed |s| of a contact (m/s), saturating at
    mu N. ``coulomb``: linear up to ``slip_speed_m_s`` then constant (regularised Coulomb);
    ``tyre``: mu N tanh(|s| / slip_speed_m_s), a smooth tyre-like curve. Both have the same
    stiffness mu N / slip_speed_m_s at zero slip."""

    COULOMB = "coulomb"
    TYRE = "tyre"


def _check(owner: str, **values: float | None) -> None:
    for name, v in values.items():
        if v is None:
            continue
        if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
            raise ValueError(f"{owner}.{name} must be a positive finite number, got {v!r}")


@dataclass(frozen=True)
class MotorSpec:
    """One motor per driven wheel, through a gearbox of ``gear_ratio`` (motor turns per wheel
    turn). Torques and speeds are at the motor shaft. The available driving torque follows the
    DC-motor line ``min(torque_max_nm, stall_torque_nm (1 - |w_motor| / no_load_speed_rad_s))``
    (flat when ``no_load_speed_rad_s`` is None); braking may always use ``torque_max_nm``.

    The wheel-speed controller is proportional: wheel torque = K (target - speed) with K chosen
    so that an unloaded straight run follows the target with ``time_constant_s`` (first order)
    while no limit is hit: K = (J_wheel + m r^2 / n_driven) / time_constant_s."""

    gear_ratio: float = 20.0
    torque_max_nm: float = 1.0
    stall_torque_nm: float | None = None  # default 3 x torque_max_nm
    no_load_speed_rad_s: float | None = None
    rotor_inertia_kg_m2: float = 2e-5
    time_constant_s: float = 0.05

    def __post_init__(self) -> None:
        _check(
            "motor",
            gear_ratio=self.gear_ratio,
            torque_max_nm=self.torque_max_nm,
            stall_torque_nm=self.stall_torque_nm,
            no_load_speed_rad_s=self.no_load_speed_rad_s,
            rotor_inertia_kg_m2=self.rotor_inertia_kg_m2,
            time_constant_s=self.time_constant_s,
        )

    @property
    def wheel_torque_max_nm(self) -> float:
        return self.torque_max_nm * self.gear_ratio


@dataclass(frozen=True)
class SteeringActuatorSpec:
    """The steering motor of tricycle and Ackermann robots: a first-order servo on the
    steering angle (``time_constant_s``), its rate limited by the model's
    ``max_steer_rate_rad_s`` and its angular acceleration by ``torque_max_nm / inertia_kg_m2``
    (the tyre's self-aligning torque is not modelled)."""

    torque_max_nm: float = 20.0
    inertia_kg_m2: float = 0.05
    time_constant_s: float = 0.05

    def __post_init__(self) -> None:
        _check(
            "steering",
            torque_max_nm=self.torque_max_nm,
            inertia_kg_m2=self.inertia_kg_m2,
            time_constant_s=self.time_constant_s,
        )


@dataclass(frozen=True)
class LoadSpec:
    """A carried load: a point mass at ``offset_xy_m`` in the robot frame (from P)."""

    mass_kg: float = 0.0
    offset_xy_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0):
            raise ValueError(f"load.mass_kg must be >= 0, got {self.mass_kg!r}")


@dataclass(frozen=True)
class DynamicsSpec:
    """Mass, inertia, centre of mass, motors and contact of one robot.

    ``com_xy_m`` is the empty robot's centre of mass in the robot frame (from P); None puts it
    at the footprint centre. ``yaw_inertia_kg_m2`` is about that centre; None takes a uniform
    box of the body's size. ``max_substep_s`` caps the sub-step (None: one a step, halved
    where needed, see docs/dynamics.md)."""

    mass_kg: float = 40.0
    yaw_inertia_kg_m2: float | None = None
    com_xy_m: tuple[float, float] | None = None
    load: LoadSpec = field(default_factory=LoadSpec)
    wheel_inertia_kg_m2: float = 0.01
    motor: MotorSpec = field(default_factory=MotorSpec)
    steering: SteeringActuatorSpec = field(default_factory=SteeringActuatorSpec)
    friction_model: FrictionModel = FrictionModel.COULOMB
    slip_speed_m_s: float = 0.05
    max_substep_s: float | None = None

    def __post_init__(self) -> None:
        _check(
            "dynamics",
            mass_kg=self.mass_kg,
            yaw_inertia_kg_m2=self.yaw_inertia_kg_m2,
            wheel_inertia_kg_m2=self.wheel_inertia_kg_m2,
            slip_speed_m_s=self.slip_speed_m_s,
            max_substep_s=self.max_substep_s,
        )
        object.__setattr__(self, "friction_model", FrictionModel(self.friction_model))


@dataclass(frozen=True)
class FrictionRegion:
    """A rectangle of floor [x_min, x_max) x [y_min, y_max) (world, m) with its own mu."""

    x_min_m: float
    y_min_m: float
    x_max_m: float
    y_max_m: float
    mu: float
    name: str = ""

    def __post_init__(self) -> None:
        if not (self.x_max_m > self.x_min_m and self.y_max_m > self.y_min_m):
            raise ValueError(
                f"friction region {self.name!r}: x_max_m > x_min_m and y_max_m > y_min_m needed, "
                f"got x [{self.x_min_m}, {self.x_max_m}], y [{self.y_min_m}, {self.y_max_m}]"
            )
        _check(f"friction region {self.name!r}", mu=self.mu)


@dataclass(frozen=True)
class FloorFriction:
    """Wheel-floor friction coefficient: ``mu`` everywhere, except in ``regions`` (a later
    region wins where two overlap)."""

    mu: float = 0.8
    regions: tuple[FrictionRegion, ...] = ()

    def __post_init__(self) -> None:
        _check("floor", mu=self.mu)
        object.__setattr__(self, "regions", tuple(self.regions))

    def table(self) -> np.ndarray:
        """(R, 5) rows x_min, y_min, x_max, y_max, mu for the kernels."""
        rows = [(r.x_min_m, r.y_min_m, r.x_max_m, r.y_max_m, r.mu) for r in self.regions]
        return np.array(rows, dtype=np.float64).reshape(-1, 5)

    def mu_at(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Friction coefficient at world points (any matching shapes)."""
        x, y = np.broadcast_arrays(np.asarray(x_m, float), np.asarray(y_m, float))
        mu = np.full(x.shape, self.mu)
        for r in self.regions:
            inside = (x >= r.x_min_m) & (x < r.x_max_m) & (y >= r.y_min_m) & (y < r.y_max_m)
            mu[inside] = r.mu
        return mu

    @property
    def mu_max(self) -> float:
        return max([self.mu, *(r.mu for r in self.regions)])
