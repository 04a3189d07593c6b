"""The fleet's controller: one batch controller that steps every vehicle agent."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from agvsim.control.api import BatchObservation
from agvsim.dynamics.spec import LoadSpec
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
        self._carried: dict[int, float] = {}  # vehicle row -> load mass applied (dynamics)

    def watch_power(self, sim: Simulation, robots: Sequence[int]) -> None:
        """Vehicles whose robot has dynamics drain their battery by the energy their motors
        deliver: each step adds the last step's positive wheel power times dt_s."""
        dyn = [j for j, v in enumerate(self.vehicles) if v.spec.dynamics is not None]
        if dyn:
            self._power = (sim, np.asarray(robots)[dyn], np.asarray(dyn))
            self._carried = dict.fromkeys(dyn, 0.0)

    def _carry(self, sim: Simulation, robots: np.ndarray, rows: np.ndarray) -> None:
        """A vehicle with dynamics that picked or dropped a load: its robot's load becomes the
        scenario's plus the loads on board, at the footprint centre (mass, centre of mass,
        inertia and braking follow from the next step)."""
        assert sim.dynamics is not None
        for r, j in zip(robots, rows, strict=True):
            v = self.vehicles[j]
            kg = v.load_kg
            if kg == self._carried[j]:
                continue
            self._carried[j] = kg
            spec = v.spec.dynamics
            assert spec is not None
            base = spec.load
            m = base.mass_kg + kg
            cx = v.spec.body_offset_x_m
            x = (base.mass_kg * base.offset_xy_m[0] + kg * cx) / m if m > 0 else 0.0
            y = base.mass_kg * base.offset_xy_m[1] / m if m > 0 else 0.0
            sim.dynamics.set_load(int(r), LoadSpec(m, (x, y)))

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
            self._carry(sim, robots, rows)
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
