"""``agvsim fleet``: the fleet on MQTT, simulated time paced to real time (times ``speed``).

Each step: the simulation steps (the vehicles read what arrived, drive and queue messages),
the transport publishes, then waits on the sockets until the step's wall-clock time is due.
Ctrl-C (or ``duration_s``) ends the run: every vehicle publishes OFFLINE and disconnects.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from datetime import datetime
from typing import Any

from agvsim.fleet.broker import EmbeddedBroker
from agvsim.fleet.build import Fleet, build_fleet
from agvsim.fleet.transport import BrokerAddress, MqttTransport
from agvsim.gc_policy import long_run_gc
from agvsim.scenario import Scenario
from agvsim.sim.engine import Simulation


class TransportLink:
    """The VDA 5050 bridge as a run observer (agvsim.run_loop's protocol): after each step it
    publishes what the vehicles queued and serves the sockets once."""

    def __init__(self, transport: MqttTransport):
        self.transport = transport

    def on_step(self, sim: Simulation) -> None:
        self.transport.flush()
        self.transport.poll(0.0)

    def close(self) -> None:
        pass  # the run closes the transport (every vehicle OFFLINE first)


class FleetRun:
    """A fleet connected to a broker (the embedded one unless ``broker_url`` is given)."""

    def __init__(
        self,
        sc: Scenario,
        broker_url: str | None = None,
        epoch: datetime | None = None,
        seed: int | None = None,
    ):
        self.fleet: Fleet = build_fleet(sc, epoch=epoch, seed=seed)
        self.broker = None if broker_url else EmbeddedBroker().start()
        url = broker_url or self.broker.url  # type: ignore[union-attr]
        self.address = BrokerAddress.parse(url)
        self.transport = MqttTransport(self.address, self.fleet.vehicles, self.fleet.interface_name)
        # what runs after each step, in order (agvsim.run_loop's observer protocol)
        self.observers: list[Any] = [TransportLink(self.transport)]

    def connect(self, timeout_s: float = 10.0) -> int:
        return self.transport.connect(timeout_s)

    def step(self) -> None:
        sim = self.fleet.sim
        sim.step()
        for o in self.observers:
            o.on_step(sim)

    def run(
        self,
        duration_s: float | None,
        speed: float = 1.0,
        progress: Callable[[float], None] | None = None,
    ) -> None:
        """Step until ``duration_s`` of simulated time (None: for ever), paced so that
        simulated time runs ``speed`` times real time (``speed <= 0``: as fast as it can)."""
        sim = self.fleet.sim
        t0_wall, t0_sim = time.monotonic(), sim.state.t_s
        next_report = 0.0
        with long_run_gc():  # agvsim.gc_policy
            while duration_s is None or sim.state.t_s - t0_sim < duration_s - 1e-9:
                self.step()
                if speed > 0:
                    due = t0_wall + (sim.state.t_s - t0_sim) / speed
                    while (left := due - time.monotonic()) > 0:
                        self.transport.poll(left)
                if progress is not None and time.monotonic() >= next_report:
                    next_report = time.monotonic() + 1.0
                    progress(sim.state.t_s)

    def close(self) -> None:
        self.transport.close()
        if self.broker is not None:  # the transport saw its OFFLINE messages passed on
            self.broker.stop()
