"""A battery: state of charge (%) drains with time and distance and fills while charging."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Battery:
    """``charge_pct`` in [0, 100]. Per second: -idle_pct_s, -drive_pct_m per metre driven,
    +charge_pct_s while charging (and only then)."""

    charge_pct: float = 80.0
    idle_pct_s: float = 0.002
    drive_pct_m: float = 0.05
    charge_pct_s: float = 0.5
    charging: bool = False

    def update(self, dt_s: float, distance_m: float) -> None:
        if self.charging:
            self.charge_pct = min(100.0, self.charge_pct + self.charge_pct_s * dt_s)
        else:
            used = self.idle_pct_s * dt_s + self.drive_pct_m * abs(distance_m)
            self.charge_pct = max(0.0, self.charge_pct - used)

    @property
    def empty(self) -> bool:
        return self.charge_pct <= 0.0

    @property
    def reach_m(self) -> float:
        """How far the remaining charge drives (m), idle drain left aside."""
        return self.charge_pct / self.drive_pct_m if self.drive_pct_m > 0 else 0.0

    def state_json(self, v3: bool) -> dict:
        if v3:
            return {
                "stateOfCharge": round(self.charge_pct, 3),
                "charging": self.charging,
                "range": round(self.reach_m, 3),
            }
        return {
            "batteryCharge": round(self.charge_pct, 3),
            "charging": self.charging,
            "reach": round(self.reach_m, 3),
        }
