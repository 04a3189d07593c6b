"""The fleet's controller: one batch controller that steps every vehicle agent."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agvsim.control.api import BatchObservation
from agvsim.fleet.bank import VehicleBank, run_tick
from agvsim.fleet.vehicle import Vehicle
from agvsim.sim.engine import Simulation


class FleetDriver:
    """Drives robots ``k`` = vehicles (same order) with their agents; inverse mode (twists).
    ``sensor`` names the safety lidar every one of them carries (None: no protective field).

    The vehicles' hot values share one ``VehicleBank``; each step ``agvsim.fleet.bank.tick``
    handles the quiet vehicles' control ticks in one numba loop and flags the rest, whose
    Python ``control`` then runs (messages, actions, nodes passed, publishing, fields).
    ``batch=False``: every vehicle's ``control`` runs every step (the reference)."""

    def __init__(self, vehicles: Sequence[Vehicle], sensor: str | None, batch: bool = True):
        self.vehicles, self.sensor, self.batch = list(vehicles), sensor, batch
        self.bank = VehicleBank(len(self.vehicles))
        for k, v in enumerate(self.vehicles):
            v.bind(self.bank, k)
        n = len(self.vehicles)
        self._out, self._slow = np.zeros((n, 3)), np.zeros(n, dtype=np.bool_)
        self._publish = np.zeros(n, dtype=np.bool_)
        self._no_ranges = np.full(n, np.inf)
        self.python_ticks = 0  # vehicle ticks that ran in Python (for benchmarks)
        self._power: tuple[Simulation, np.ndarray, np.ndarray] | None = None

    def watch_power(self, sim: Simulation, robots: Sequence[int]) -> None:
        """Vehicles whose robot has dynamics drain their battery by the energy their motors
        deliver: each step adds the last step's positive wheel power times dt_s."""
        dyn = [j for j, v in enumerate(self.vehicles) if v.spec.dynamics is not None]
        if dyn:
            self._power = (sim, np.asarray(robots)[dyn], np.asarray(dyn))

    def reset(self, k: int, rng: np.random.Generator) -> None:
        if k != len(self.vehicles):
            raise ValueError(f"FleetDriver drives {len(self.vehicles)} vehicles, not {k}")

    def step(self, obs: BatchObservation) -> np.ndarray:
        vs = self.vehicles
        ranges = obs.ranges[self.sensor] if self.sensor and self.sensor in obs.ranges else None
        rmin = self._no_ranges if ranges is None else ranges.min(axis=1)
        mail = self.bank.mail
        poses = np.ascontiguousarray(obs.true_pose, dtype=np.float64)
        out, slow, publish = self._out, self._slow, self._publish
        if self._power is not None:
            sim, robots, rows = self._power
            power_w = np.maximum(sim.state.wheel_power_w[robots], 0.0).sum(axis=1)
            self.bank.energy_j[rows] += power_w * sim.dt_s
        if self.batch:
            run_tick(self.bank, float(obs.t_s), poses, rmin, mail, out, slow, publish)
            for j in np.flatnonzero(publish):
                vs[j].publish_periodic()
        else:  # every vehicle in Python (the reference the batch tick is tested against)
            slow[:] = True
        todo = np.flatnonzero(slow)
        self.python_ticks += len(todo)
        for j in todo:
            v = vs[j]
            mail[j] = False  # before control empties the inbox: a message meanwhile sets it
            try:
                out[j] = v.control(obs.t_s, poses[j], None if ranges is None else ranges[j])
            except Exception as exc:  # noqa: BLE001 - one vehicle's fault stops it, not the run
                v.fault(exc)
                out[j] = 0.0
        return out.copy()

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
