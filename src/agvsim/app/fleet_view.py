"""The browser app and the VDA 5050 fleet layer (docs/fleet.md).

``draw_session_layout`` draws a scenario's ``layout:`` (nodes, edges, stations) into the 3D
scene; the scene calls it whenever it rebuilds the world (start, a loaded scenario, a maze
edit), so the drawing follows the world.

``FleetSession`` is the ``Session`` of a scenario with a ``vda5050:`` block: its simulation
is the fleet's (``build_fleet``), its vehicles are connected to an MQTT broker (the embedded
one, or ``agvsim serve --broker mqtt://HOST:PORT``), and every simulation step publishes
what the vehicles queued and reads what arrived, as ``FleetRun.step`` does: an external
master drives the vehicles shown in the browser; unless ``with_master`` is False, agvsim's own
master control (agvsim.master, docs/master.md) is that master: it connects to the same broker
as any other would and runs the scenario's ``master:`` block (transport orders, charging,
breakdowns). While the run is paused the sockets are
still served (keepalive; orders wait for the next step). Reset or editing a robot rebuilds
the fleet: every vehicle reconnects at its start node, its order gone. ``close()`` publishes
OFFLINE and stops the embedded broker.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any

from agvsim.app.session import DEFAULT_OUT, EditError, Session
from agvsim.fleet.broker import EmbeddedBroker
from agvsim.fleet.build import Fleet, build_fleet, load_layout
from agvsim.fleet.run import TransportLink
from agvsim.fleet.transport import BrokerAddress, MqttTransport
from agvsim.fleet.viz import draw_layout
from agvsim.scenario import Scenario, ScenarioError
from agvsim.sim.engine import Simulation
from agvsim.world.lif import Layout

log = logging.getLogger("agvsim.app")


class BrokerError(RuntimeError):
    """The embedded broker did not start, or no vehicle could connect to the broker."""


def session_layout(session: Session) -> Layout | None:
    """The layout the session's scenario runs on (None: no ``layout:`` block, or one that
    cannot be read here, e.g. a layout file that an uploaded scenario did not bring)."""
    if isinstance(session, FleetSession):
        return session.fleet.layout if session.fleet is not None else None
    with session.lock:
        cfg = session.config
        if cfg.get("layout") is None:
            return None
        try:
            sc = session._scenario(cfg)
            return load_layout(sc, sc._base_dir)
        except (ScenarioError, OSError, ValueError) as err:
            log.warning("the scenario's layout is not drawn: %s", err)
            return None


def draw_session_layout(scene: Any, session: Session, old: list[Any]) -> list[Any]:
    """Replace the handles ``old`` by the session's layout drawn in ``scene``; returns the
    new handles (empty without a layout)."""
    for handle in old:
        handle.remove()
    layout = session_layout(session)
    return [] if layout is None else draw_layout(scene, layout)


class FleetSession(Session):
    """A Session whose robots are the VDA 5050 vehicles of the scenario's ``vda5050:`` block,
    connected to the broker at ``broker_url`` (None: an embedded broker on 127.0.0.1)."""

    def __init__(
        self,
        scenario: Scenario,
        source: str = "scenario",
        broker_url: str | None = None,
        out_dir: str | Path = DEFAULT_OUT,
        connect_timeout_s: float = 10.0,
        with_master: bool = True,
        master_period_s: float = 0.25,
    ):
        if scenario.vda5050 is None:
            raise ScenarioError(source, ["the scenario has no 'vda5050:' block of vehicles"])
        self.lock = threading.RLock()  # Session's own; close() may run before it is set
        self.fleet: Fleet | None = None
        self.transport: MqttTransport | None = None
        self.link: Any = None  # the built-in master's MQTT side (agvsim.master.mqtt.MqttMaster)
        self.with_master, self.master_period_s = with_master, master_period_s
        # after each step, in order (agvsim.run_loop's observer protocol): the VDA 5050
        # bridge, then (with the built-in master) breakdowns and the master's decisions
        self.fleet_observers: list[Any] = []
        self.connect_timeout_s = connect_timeout_s
        self.address = BrokerAddress.parse(broker_url) if broker_url else None
        try:
            self.broker = None if broker_url else EmbeddedBroker().start()
        except (OSError, RuntimeError) as err:
            raise BrokerError(str(err)) from None  # it names the embedded broker
        if self.address is None:
            assert self.broker is not None
            self.address = BrokerAddress.parse(self.broker.url)
        try:
            super().__init__(scenario, source, allow_python=True, out_dir=out_dir)
        except BaseException:
            self.close()
            raise

    @property
    def broker_url(self) -> str:
        assert self.address is not None
        return f"mqtt://{self.address.host}:{self.address.port}"

    def topic_prefix(self) -> str:
        """``interfaceName/majorVersion/manufacturer`` (a serial and a topic follow)."""
        assert self.fleet is not None
        v0 = self.fleet.vehicles[0]
        return self.fleet.topic(v0, "x").rsplit("/", 2)[0]

    def _build(self, cfg: dict[str, Any]) -> Simulation:
        """The fleet's simulation; the vehicles (new ones on every rebuild) connected."""
        sc = self._scenario(cfg)
        fleet = build_fleet(sc)
        assert self.address is not None
        if self.transport is not None:
            self.transport.close()  # the old vehicles go OFFLINE
        self.fleet, self.transport = fleet, None
        transport = MqttTransport(self.address, fleet.vehicles, fleet.interface_name)
        online = transport.connect(self.connect_timeout_s)
        if online == 0 and "sim" not in self.__dict__:  # at start; later ones retry each second
            transport.close()
            raise BrokerError(f"no vehicle could connect to {self.broker_url}")
        self.transport = transport
        self.fleet_observers = [TransportLink(transport)]
        self._start_master(fleet, sc)
        return fleet.sim

    def _start_master(self, fleet: Fleet, sc: Scenario) -> None:
        """The built-in master for this (new) fleet, on the same broker, from t = 0."""
        if self.link is not None:
            self.link.close()
            self.link = None
        if not self.with_master or fleet.layout is None:
            return
        from datetime import UTC, datetime

        from agvsim.master.mqtt import MqttMaster, MqttMasterTick
        from agvsim.master.run import Breakdowns, build_master

        master = build_master(sc, fleet, sc.seed, sc.duration_s, datetime.now(UTC))
        assert self.address is not None
        link = MqttMaster(master, self.address, fleet.interface_name)
        if not link.connect(self.connect_timeout_s):
            link.close()
            raise BrokerError(f"the master could not connect to {self.broker_url}")
        self.link = link
        # as in agvsim fleet: scheduled breakdowns hit the simulated vehicles, the master
        # decides every master_period_s of simulated time
        self.fleet_observers += [
            Breakdowns(sc, fleet),
            MqttMasterTick(link, master, self.master_period_s),
        ]

    def _replace(self, cfg: dict[str, Any], fresh: set[str] = frozenset()) -> list[str]:  # type: ignore[assignment]
        """A rebuilt fleet's vehicles start at their start nodes, with no order: every robot
        starts afresh (a live pose carried over would not match the vehicle's last node)."""
        return super()._replace(cfg, fresh={r["name"] for r in cfg.get("robots", [])})

    def _step_once(self) -> bool:
        ok = super()._step_once()
        for o in self.fleet_observers:
            o.on_step(self.sim)
        return ok

    def advance(self, wall_dt_s: float, max_work_s: float = 0.03) -> int:
        taken = super().advance(wall_dt_s, max_work_s)
        if taken == 0:
            with self.lock:  # paused: keep the connections alive, read what arrives
                if self.transport is not None:
                    self.transport.poll(0.0)
        return taken

    def load_upload(self, name: str, content: bytes) -> None:
        raise EditError(
            "this app runs a VDA 5050 fleet; to run another scenario, restart agvsim serve with it"
        )

    def close(self) -> None:
        """Every vehicle publishes OFFLINE and disconnects; the embedded broker stops."""
        with self.lock:
            self.fleet_observers = []
            link, self.link = self.link, None
            if link is not None:
                link.close()
            transport, self.transport = self.transport, None
            if transport is not None:
                transport.close()
            broker, self.broker = self.broker, None
            if broker is not None:  # the transport saw its OFFLINE messages passed on
                broker.stop()

    def banner(self) -> list[str]:
        """What ``agvsim serve`` prints about the fleet."""
        assert self.fleet is not None
        where = "embedded broker" if self.broker is not None else "broker"
        n = len(self.fleet.vehicles)
        master = (
            "agvsim's master control drives them (serve --no-master: leave them to yours)"
            if self.link is not None
            else "waiting for your master's orders"
        )
        return [
            f"VDA 5050 {self.fleet.config.version}: {n} vehicles on the {where} "
            f"{self.broker_url}, topics {self.topic_prefix()}/<serial>/<topic>; {master}"
        ]
