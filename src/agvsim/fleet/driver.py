"""The fleet's controller: one batch controller that steps every vehicle agent."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agvsim.control.api import BatchObservation
from agvsim.fleet.vehicle import Vehicle


class FleetDriver:
    """Drives robots ``k`` = vehicles (same order) with their agents; inverse mode (twists).
    ``sensor`` names the safety lidar every one of them carries (None: no protective field)."""

    def __init__(self, vehicles: Sequence[Vehicle], sensor: str | None):
        self.vehicles, self.sensor = list(vehicles), sensor

    def reset(self, k: int, rng: np.random.Generator) -> None:
        if k != len(self.vehicles):
            raise ValueError(f"FleetDriver drives {len(self.vehicles)} vehicles, not {k}")

    def step(self, obs: BatchObservation) -> np.ndarray:
        out = np.zeros((len(self.vehicles), 3))
        ranges = obs.ranges[self.sensor] if self.sensor and self.sensor in obs.ranges else None
        for j, v in enumerate(self.vehicles):
            try:
                out[j] = v.control(obs.t_s, obs.true_pose[j], None if ranges is None else ranges[j])
            except Exception as exc:  # noqa: BLE001 - one vehicle's fault stops it, not the run
                v.fault(exc)
        return out

    def state_names(self) -> list[str]:
        return [
            "paused"
            if v.paused
            else "field"
            if v.field_violation
            else "driving"
            if v.driving
            else "busy"
            if v.busy
            else "idle"
            for v in self.vehicles
        ]
