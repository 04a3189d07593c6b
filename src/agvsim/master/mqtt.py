"""The master over MQTT: one paho client that subscribes to every vehicle's ``state`` and
``factsheet`` under the interface name, hands them to the same ``Master`` as the in-process
runner, and publishes its ``order`` / ``instantActions`` to
``interfaceName/majorVersion/manufacturer/serialNumber/topic`` (QoS 0, VDA 5050 6.2).

Received messages wait in a queue (paho's network thread fills it) until ``tick``, which the
caller runs on its own clock: ``MasteredFleetRun`` ticks it with the simulated time of the
fleet it runs beside, the vehicles' side knowing nothing of it but the broker.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque
from datetime import UTC, datetime
from typing import Any

import paho.mqtt.client as mqtt

from agvsim.fleet.run import FleetRun
from agvsim.fleet.transport import BrokerAddress
from agvsim.master.master import Master
from agvsim.master.run import Breakdowns, build_master, with_fleet_size
from agvsim.scenario import Scenario
from agvsim.sim.engine import Simulation

LISTEN = ("state", "factsheet")


class MqttMaster:
    def __init__(self, master: Master, address: BrokerAddress, interface_name: str):
        self.master, self.address, self.interface = master, address, interface_name
        self.inbox: deque[tuple[str, str, bytes]] = deque()
        self.connected = threading.Event()
        self.received = 0
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="agvsim-master")
        c.on_connect = self._on_connect
        c.on_message = self._on_message
        self.client = c

    def _on_connect(self, client: Any, _u: Any, _f: Any, reason: Any, _p: Any) -> None:
        if reason.is_failure:
            return
        client.subscribe([(f"{self.interface}/+/+/+/{t}", 0) for t in LISTEN])
        self.connected.set()

    def _on_message(self, _c: Any, _u: Any, msg: Any) -> None:
        parts = msg.topic.split("/")
        if len(parts) == 5 and parts[4] in LISTEN:
            self.inbox.append((parts[3], parts[4], msg.payload))

    def connect(self, timeout_s: float = 10.0) -> bool:
        self.client.connect(self.address.host, self.address.port, keepalive=30)
        self.client.loop_start()
        return self.connected.wait(timeout_s)

    def tick(self, t_s: float) -> int:
        """Hand over what arrived, decide, publish; returns how many messages were sent."""
        m = self.master
        while self.inbox:
            serial, topic, payload = self.inbox.popleft()
            try:
                msg = json.loads(payload)
            except (json.JSONDecodeError, UnicodeDecodeError):
                continue  # not ours to fix: a vehicle's broken message is ignored
            if isinstance(msg, dict):
                self.received += 1
                m.receive(serial, topic, msg)
        sent = m.tick(t_s)
        for serial, topic, msg in sent:
            agv = m.agvs[serial]
            major = "v" + agv.version.split(".")[0]
            self.client.publish(
                f"{self.interface}/{major}/{agv.manufacturer}/{serial}/{topic}",
                json.dumps(msg, separators=(",", ":")),
                qos=0,
            )
        return len(sent)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


class MqttMasterTick:
    """Run observer: the master decides every ``period_s`` (its messages go out on MQTT)."""

    def __init__(self, link: MqttMaster, master: Master, period_s: float):
        self.link, self.master, self.period_s = link, master, period_s
        self._next_tick_s = 0.0

    def on_step(self, sim: Simulation) -> None:
        t = float(sim.state.t_s)
        if t + 1e-9 >= self._next_tick_s:
            self._next_tick_s += self.period_s
            self.link.tick(t)
        self.master.metrics.collisions = int(sim.state.robot_collisions.sum())

    def close(self) -> None:
        pass


class MasteredFleetRun(FleetRun):
    """``agvsim fleet``'s run with the master beside the vehicles, both on the broker only
    (scheduled breakdowns are applied to the simulated vehicles, as in-process)."""

    def __init__(
        self,
        sc: Scenario,
        broker_url: str | None = None,
        epoch: datetime | None = None,
        seed: int | None = None,
        horizon_s: float | None = None,
        master_period_s: float = 0.25,
    ):
        if sc.master is not None and sc.master.fleet_size is not None:
            sc = with_fleet_size(sc, sc.master.fleet_size)
        epoch = epoch or datetime.now(UTC)  # on the wire: wall-clock timestamps
        super().__init__(sc, broker_url, epoch, seed)
        s = sc.seed if seed is None else seed
        self.master = build_master(sc, self.fleet, s, horizon_s or sc.duration_s, epoch)
        self.link = MqttMaster(self.master, self.address, self.fleet.interface_name)
        self.period_s = master_period_s
        self.observers += [
            Breakdowns(sc, self.fleet),
            MqttMasterTick(self.link, self.master, master_period_s),
        ]

    def connect(self, timeout_s: float = 10.0) -> int:
        online = super().connect(timeout_s)
        if not self.link.connect(timeout_s):
            raise OSError(f"the master could not connect to {self.address.host}")
        return online

    def wait_settled(self, timeout_s: float = 2.0) -> None:
        """Serve the sockets until the vehicles' last messages reached the master."""
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout_s:
            self.transport.poll(0.02)

    def close(self) -> None:
        self.link.close()
        super().close()
