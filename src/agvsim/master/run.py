"""The master and the vehicles in one process, without a broker: each step the simulation
moves the vehicles, what they published (state, factsheet) goes to the master, and what the
master decides (order, instantActions) goes to the vehicles' ``receive``, to be handled at
their next step. The messages are the very dicts the MQTT path would carry as JSON.

Scheduled breakdowns (``master.breakdowns``) are applied to the vehicles here: they belong
to the simulated world, not to the master, which only sees the FATAL error in the state.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from agvsim.control.mobility import Mobility
from agvsim.fleet.build import Fleet, build_fleet
from agvsim.gc_policy import long_run_gc
from agvsim.master.config import MasterConfig
from agvsim.master.master import Master
from agvsim.master.orders import scheduled_transports
from agvsim.scenario import Scenario, ScenarioError
from agvsim.sim.engine import Simulation

EPOCH = datetime(2026, 1, 1, tzinfo=UTC)


def with_fleet_size(sc: Scenario, n: int) -> Scenario:
    """The scenario with only its first ``n`` VDA 5050 vehicles (and their robots)."""
    cfg = sc.vda5050
    if cfg is None:
        raise ScenarioError(sc._source, ["the scenario has no 'vda5050:' block of vehicles"])
    if not 1 <= n <= len(cfg.vehicles):
        raise ScenarioError(
            sc._source,
            [f"master.fleet_size: {n}; the scenario has 1..{len(cfg.vehicles)} vehicles"],
        )
    keep = cfg.vehicles[:n]
    names = {v.robot for v in keep}
    out = sc.model_copy(
        update={
            "robots": [r for r in sc.robots if r.name in names],
            "vda5050": cfg.model_copy(update={"vehicles": keep}),
        }
    )
    out._base_dir, out._source = sc._base_dir, sc._source
    return out


def build_master(
    sc: Scenario, fleet: Fleet, seed: int, horizon_s: float, epoch: datetime = EPOCH
) -> Master:
    """The scenario's master (its ``master:`` block, or the defaults); ScenarioError names
    every bad station, node or vehicle. ``epoch``: time zero of the messages' timestamps."""
    if fleet.layout is None:
        raise ScenarioError(sc._source, ["the master needs a 'layout:' block"])
    cfg = sc.master or MasterConfig()
    serials = [v.cfg.serial for v in fleet.vehicles]
    problems = [
        f"master.breakdowns[{k}].vehicle: {b.vehicle!r} is not a vehicle; serials: {serials}"
        for k, b in enumerate(cfg.breakdowns)
        if b.vehicle not in serials
    ]
    try:
        transports = scheduled_transports(fleet.layout, cfg, seed, horizon_s)
    except ValueError as e:
        problems.append(str(e))
    if problems:
        raise ScenarioError(sc._source, problems)
    radii = {}
    for v in fleet.vehicles:
        mob = Mobility.of(v.spec.model)
        if mob.car_like and not mob.holonomic:
            radii[v.cfg.serial] = mob.min_radius_m
    return Master(fleet.layout, cfg, transports, epoch, turn_radius_m=radii)


class Breakdowns:
    """Run observer: fails each vehicle at its scheduled time (``master.breakdowns``)."""

    def __init__(self, sc: Scenario, fleet: Fleet):
        cfg = sc.master or MasterConfig()
        self.due = sorted((b.at_s, b.vehicle) for b in cfg.breakdowns)
        self.fleet = fleet

    def on_step(self, sim: Simulation) -> None:
        t = float(sim.state.t_s)
        while self.due and self.due[0][0] <= t + 1e-9:
            _, serial = self.due.pop(0)
            self.fleet.vehicle(serial).break_down(f"scheduled breakdown at t={t:.2f} s")

    def close(self) -> None:
        pass


class MasterLink:
    """Run observer, the in-process bridge: hands what the vehicles published to the master,
    lets the master decide every ``period_s`` and hands its messages to the vehicles."""

    def __init__(self, master: Master, fleet: Fleet, period_s: float):
        self.master, self.fleet, self.period_s = master, fleet, period_s
        self.by_serial = {v.cfg.serial: v for v in fleet.vehicles}
        self._next_tick_s = 0.0

    def on_step(self, sim: Simulation) -> None:
        t = float(sim.state.t_s)
        m = self.master
        for v in self.fleet.vehicles:
            if not v.outbox:  # most vehicles publish nothing in a step
                continue
            for topic, msg, _retained in v.drain():
                if topic in ("state", "factsheet"):
                    m.receive(v.cfg.serial, topic, msg)
        if t + 1e-9 >= self._next_tick_s:
            self._next_tick_s += self.period_s
            for serial, topic, msg in m.tick(t):
                self.by_serial[serial].receive(topic, msg)
        m.metrics.collisions = int(sim.state.robot_collisions.sum())

    def close(self) -> None:
        pass


class InProcessRun:
    """The scenario's fleet driven by the master, no broker. ``master_period_s``: how often
    the master decides (default: every simulation step)."""

    def __init__(
        self,
        sc: Scenario,
        seed: int | None = None,
        duration_s: float | None = None,
        master_period_s: float | None = None,
    ):
        if sc.master is not None and sc.master.fleet_size is not None:
            sc = with_fleet_size(sc, sc.master.fleet_size)
        self.seed = sc.seed if seed is None else seed
        self.duration_s = sc.duration_s if duration_s is None else duration_s
        self.fleet = build_fleet(sc, epoch=EPOCH, seed=self.seed)
        self.master = build_master(sc, self.fleet, self.seed, self.duration_s)
        self.period_s = master_period_s or self.fleet.sim.dt_s
        # after each step, in order (agvsim.run_loop's observer protocol)
        self.observers: list[Any] = [
            Breakdowns(sc, self.fleet),
            MasterLink(self.master, self.fleet, self.period_s),
        ]

    @property
    def t_s(self) -> float:
        return float(self.fleet.sim.state.t_s)

    def step(self) -> None:
        sim = self.fleet.sim
        sim.step()
        for o in self.observers:
            o.on_step(sim)

    def run(
        self,
        until_s: float | None = None,
        stop_when_done: bool = False,
        progress: Callable[[float], None] | None = None,
    ) -> None:
        end = self.duration_s if until_s is None else until_s
        with long_run_gc():  # agvsim.gc_policy: a quarter of the time at 1,000 vehicles
            while self.t_s < end - 1e-9:
                self.step()
                if stop_when_done and self.master.all_delivered and self._all_parked():
                    break
                if progress is not None:
                    progress(self.t_s)

    def _all_parked(self) -> bool:
        return all(a.order_done or a.broken for a in self.master.agvs.values())

    def summary(self) -> dict[str, Any]:
        return self.master.metrics.summary(self.master, self.t_s)
