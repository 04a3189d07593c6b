"""A battery: state of charge (%) drains with time and distance and fills while charging."""

from __future__ import annotations

import numpy as np


class _Cell:
    """A float attribute kept in a one-element array (``_<name>``): a view into a bank row
    once bound, so the batch tick and the object share one value."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = "_" + name

    def __get__(self, obj: object, objtype: type | None = None) -> float:
        return float(getattr(obj, self.slot)[0])

    def __set__(self, obj: object, value: float) -> None:
        getattr(obj, self.slot)[0] = value


class Battery:
    """``charge_pct`` in [0, 100]. Per second: -idle_pct_s, -drive_pct_m per metre driven,
    +charge_pct_s while charging (and only then). A robot with dynamics drains by energy
    instead: ``pct_per_j`` per joule its motors deliver (``drive_pct_m`` 0); energy braking
    returns is not recovered.

    The charge and the two drain rates live in one-element views (``bind``): a fleet keeps
    them in its ``VehicleBank`` rows, where the batch tick drains them too."""

    def __init__(
        self,
        charge_pct: float = 80.0,
        idle_pct_s: float = 0.002,
        drive_pct_m: float = 0.05,
        charge_pct_s: float = 0.5,
        charging: bool = False,
        pct_per_j: float = 0.0,
    ):
        self._charge_pct = np.array([float(charge_pct)])
        self._idle_pct_s = np.array([float(idle_pct_s)])
        self._drive_pct_m = np.array([float(drive_pct_m)])
        self.charge_pct_s = charge_pct_s
        self.charging = charging
        self.pct_per_j = pct_per_j

    charge_pct = _Cell()
    idle_pct_s = _Cell()
    drive_pct_m = _Cell()

    def bind(self, charge: np.ndarray, idle: np.ndarray, drive: np.ndarray) -> None:
        """Keep the charge and the drain rates in these (1,) views from now on."""
        charge[0], idle[0], drive[0] = self.charge_pct, self.idle_pct_s, self.drive_pct_m
        self._charge_pct, self._idle_pct_s, self._drive_pct_m = charge, idle, drive

    @classmethod
    def of_energy(cls, charge_pct: float, capacity_wh: float) -> Battery:
        """A battery drained by the motors' energy (robots with dynamics)."""
        return cls(charge_pct, drive_pct_m=0.0, pct_per_j=100.0 / (capacity_wh * 3600.0))

    def update(self, dt_s: float, distance_m: float, energy_j: float = 0.0) -> None:
        """``energy_j``: what the motors delivered over ``dt_s`` (robots with dynamics)."""
        if self.charging:
            self.charge_pct = min(100.0, self.charge_pct + self.charge_pct_s * dt_s)
        else:
            used = self.idle_pct_s * dt_s + self.drive_pct_m * abs(distance_m)
            used += self.pct_per_j * energy_j
            self.charge_pct = max(0.0, self.charge_pct - used)

    @property
    def empty(self) -> bool:
        return self.charge_pct <= 0.0

    @property
    def reach_m(self) -> float:
        """How far the remaining charge drives (m), idle drain left aside."""
        return self.charge_pct / self.drive_pct_m if self.drive_pct_m > 0 else 0.0

    def state_json(self, v3: bool) -> dict:
        charge, per_m = float(self._charge_pct[0]), float(self._drive_pct_m[0])
        reach = charge / per_m if per_m > 0 else 0.0  # reach_m, read once (every state has it)
        if v3:
            return {
                "stateOfCharge": round(charge, 3),
                "charging": self.charging,
                "range": round(reach, 3),
            }
        return {
            "batteryCharge": round(charge, 3),
            "charging": self.charging,
            "reach": round(reach, 3),
        }
