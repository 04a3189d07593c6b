"""The fleet through real brokers: the embedded amqtt broker and Debian's Mosquitto (started
by the tests on a free port; skipped without it unless AGVSIM_REQUIRE_MOSQUITTO=1).

A master (paho, in this process) sends orders and instant actions over MQTT and checks what the
vehicles publish; every message it receives is validated against the official schema."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from fleet_helpers import (
    SLOW_MACHINE,
    Master,
    Mosquitto,
    action,
    charger_room,
    instant,
    order,
    room_scenario,
)

from agvsim.fleet.broker import EmbeddedBroker
from agvsim.fleet.run import FleetRun
from agvsim.fleet.schemas import problems
from agvsim.scenario import load_scenario

ROW = ["r4c1", "r4c2", "r4c3", "r4c4"]
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture(params=["embedded", "mosquitto"])
def broker(request) -> Iterator[str]:
    if request.param == "embedded":
        b = EmbeddedBroker().start()
        yield b.url
        b.stop()
    else:
        m = Mosquitto().start()
        yield f"mqtt://127.0.0.1:{m.port}"
        m.stop()


def host_port(url: str) -> tuple[str, int]:
    hp = url.split("://", 1)[1]
    return hp.rsplit(":", 1)[0], int(hp.rsplit(":", 1)[1])


def pump(run: FleetRun, cond: Callable[[], object], max_s: float, what: str) -> None:
    """Step the fleet (20 steps per wall second at most: the master has time to answer)."""
    t0 = time.monotonic()
    while not cond():
        assert time.monotonic() - t0 < max_s * SLOW_MACHINE, f"timed out waiting for {what}"
        run.step()
        run.transport.poll(0.002)


def all_valid(m: Master) -> None:
    with m.lock:
        got = list(m.got)
    for topic, msg, _, _ in got:
        name = topic.rsplit("/", 1)[-1]
        if name in ("state", "visualization", "connection", "factsheet"):
            assert problems("2.1.0", name, msg) == [], (topic, msg)


def start(tmp: Path, url: str, vehicles=None) -> tuple[FleetRun, Master]:
    vehicles = vehicles or [("agv1", "differential", "r4c1", 0.0)]
    run = FleetRun(load_scenario(room_scenario(tmp, vehicles)), url)
    assert run.connect() == len(vehicles)
    m = Master(*host_port(url))
    pump(run, lambda: m.last("agv1", "factsheet") is not None, 10, "retained factsheet")
    return run, m


def test_full_order_over_mqtt(tmp_path: Path, broker: str) -> None:
    run, m = start(tmp_path, broker)
    try:
        lay = run.fleet.layout
        # retained: a master that connects later still gets ONLINE and the factsheet
        assert m.last("agv1", "connection")["connectionState"] == "ONLINE"
        acts = {"r4c4": [action("pk", "pick", "HARD")]}
        m.send("agv1", "order", order(lay, ROW, node_actions=acts))
        pump(run, lambda: (m.last("agv1", "state") or {}).get("orderId") == "o1", 10, "accept")
        pump(run, lambda: m.last("agv1", "state")["loads"], 60, "the pick")
        s = m.last("agv1", "state")
        assert s["lastNodeId"] == "r4c4" and s["nodeStates"] == []
        assert s["actionStates"] == [
            {"actionId": "pk", "actionType": "pick", "actionStatus": "FINISHED"}
        ]
        # a bad message is an error in the state, and the vehicle stays online
        m.send("agv1", "order", b"{nope")
        pump(run, lambda: m.last("agv1", "state")["errors"], 10, "the error")
        assert m.last("agv1", "state")["errors"][0]["errorType"] == "validationError"
        # cancel mid edge
        m.send("agv1", "order", order(lay, ROW[::-1], order_id="o2"))
        pump(run, lambda: m.last("agv1", "state")["driving"], 10, "driving")
        m.send("agv1", "instantActions", instant(("c", "cancelOrder")))
        pump(run, lambda: m.last("agv1", "state")["nodeStates"] == [], 10, "cancelled")
        assert not m.last("agv1", "state")["driving"]
        vis = m.messages("agv1", "visualization")
        ids = [v["headerId"] for v in vis]  # QoS 0 on a local broker: none lost
        assert len(ids) >= 3 and ids == list(range(ids[0], ids[0] + len(ids)))
        all_valid(m)
    finally:
        run.close()
    pump_master = time.monotonic()
    while m.last("agv1", "connection")["connectionState"] != "OFFLINE":
        assert time.monotonic() - pump_master < 30, "no OFFLINE"
        time.sleep(0.02)
    m.close()


FLEET_CHILD = """
import sys
from agvsim.fleet.run import FleetRun
from agvsim.scenario import load_scenario
run = FleetRun(load_scenario(sys.argv[1]), sys.argv[2])
run.connect()
print("ONLINE", flush=True)
run.run(None, speed=1.0)
"""


def test_last_will_when_the_process_dies(tmp_path: Path, broker: str) -> None:
    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    child = subprocess.Popen(
        [sys.executable, "-c", FLEET_CHILD, str(path), broker],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    m = Master(*host_port(broker))
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "ONLINE"
        t0 = time.monotonic()
        while (m.last("agv1", "connection") or {}).get("connectionState") != "ONLINE":
            assert time.monotonic() - t0 < 20
            time.sleep(0.05)
        child.send_signal(signal.SIGKILL)
        child.wait(10)
        t0 = time.monotonic()
        while m.last("agv1", "connection")["connectionState"] != "CONNECTIONBROKEN":
            assert time.monotonic() - t0 < 30, "no last will"
            time.sleep(0.05)
        assert problems("2.1.0", "connection", m.last("agv1", "connection")) == []
    finally:
        child.kill()
        m.close()


def test_broker_restart_vehicles_reconnect_and_republish(tmp_path: Path) -> None:
    mosq = Mosquitto().start()
    url = f"mqtt://127.0.0.1:{mosq.port}"
    run = FleetRun(
        load_scenario(room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0)])), url
    )
    try:
        assert run.connect() == 1
        pump(run, lambda: run.transport.links[0].online, 5, "online")
        mosq.stop()
        pump(run, lambda: not run.transport.links[0].online, 10, "the loss")
        mosq = Mosquitto(mosq.port).start()
        m = Master("127.0.0.1", mosq.port)
        pump(run, lambda: run.transport.links[0].online, 15, "reconnecting")
        pump(run, lambda: m.last("agv1", "state") is not None, 10, "a state")
        assert m.last("agv1", "connection")["connectionState"] == "ONLINE"
        assert m.last("agv1", "factsheet") is not None
        # and it takes orders again
        m.send("agv1", "order", order(run.fleet.layout, ["r4c1", "r4c2"]))
        pump(run, lambda: m.last("agv1", "state")["lastNodeId"] == "r4c2", 30, "the order")
        m.close()
    finally:
        run.close()
        mosq.stop()


def test_cli_fleet_runs_and_stops_on_sigint(tmp_path: Path) -> None:
    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    exe = Path(sys.executable).parent / "agvsim"
    child = subprocess.Popen(
        [str(exe), "fleet", str(path), "--speed", "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=dict(os.environ, NUMBA_NUM_THREADS="1"),
    )
    assert child.stdout is not None
    first = child.stdout.readline()
    assert first.startswith("embedded broker mqtt://127.0.0.1:"), first
    assert "1/1 vehicles online" in first
    host, port = host_port(first.split()[2].rstrip(";"))
    head = [child.stdout.readline() for _ in range(3)]  # topics, the vehicle, the master line
    # no master: block, so agvsim's master stays out of the way of the one driving it
    assert "master: none - the scenario has no 'master:' block" in head[-1], head
    assert child.stdout.readline().startswith("running (1x real time)")
    m = Master(host, port)
    t0 = time.monotonic()  # the time bounds only catch a hang (a loaded machine is slow)
    while m.last("agv1", "state") is None:
        assert time.monotonic() - t0 < 60
        time.sleep(0.05)
    t_sent = m.send("agv1", "order", order_json := order_for_room())
    while (m.last("agv1", "state") or {}).get("orderId") != "o1":
        assert time.monotonic() - t_sent < 60, json.dumps(order_json)[:80]
        time.sleep(0.01)
    m.close()
    child.send_signal(signal.SIGINT)
    rest = child.communicate(timeout=60)[0]
    assert child.returncode == 130 and "OFFLINE" in rest


def order_for_room() -> dict:
    from fleet_helpers import ROOM

    from agvsim.world.lif import layout_from_grid
    from agvsim.world.loaders import parse_text_picture

    lay = layout_from_grid(parse_text_picture(ROOM, 1.0, None), ["agvsim.differential"])
    return order(lay, ["r4c1", "r4c2"])


def test_update_pause_loads_charging_and_safety_over_mqtt(tmp_path: Path, broker: str) -> None:
    layout = charger_room(tmp_path, "r4c6")
    run = FleetRun(
        load_scenario(room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)], layout)),
        broker,
    )
    assert run.connect() == 1
    m = Master(*host_port(broker))
    v = run.fleet.vehicle("agv1")

    def state() -> dict:
        return m.last("agv1", "state") or {}

    try:
        pump(run, lambda: state(), 10, "a first state")
        lay = run.fleet.layout
        # base r4c1..r4c2 with a pick, horizon to r4c4; the update releases it, adds a drop
        acts = {"r4c2": [action("pk", "pick", "HARD", loadId="L1")]}
        m.send(
            "agv1",
            "order",
            order(lay, ["r4c1", "r4c2", "r4c3", "r4c4"], released=2, node_actions=acts),
        )
        pump(run, lambda: state().get("loads"), 30, "the pick")
        pump(run, lambda: state().get("newBaseRequest"), 10, "a base request")
        assert state()["lastNodeId"] == "r4c2" and not state()["driving"]
        m.send(
            "agv1",
            "order",
            order(
                lay,
                ["r4c2", "r4c3", "r4c4"],
                update=1,
                seq0=2,
                node_actions={"r4c4": [action("dp", "drop", "HARD")]},
            ),
        )
        pump(run, lambda: state().get("driving"), 10, "driving on")
        # pause mid edge, resume
        m.send("agv1", "instantActions", instant(("p1", "startPause")))
        pump(run, lambda: state().get("paused"), 10, "paused")
        here = run.fleet.sim.state.poses[0].copy()
        for _ in range(20):
            run.step()
        assert (run.fleet.sim.state.poses[0] == here).all()
        m.send("agv1", "instantActions", instant(("p2", "stopPause")))
        pump(
            run,
            lambda: state().get("lastNodeId") == "r4c4" and not state()["loads"],
            30,
            "the drop at r4c4",
        )
        # a box on the way on to the charger stops it; removed, it goes on and charges
        run.fleet.sim.set_boxes(np.array([[1.5, 0.0, 0.0, 0.15, 0.15]]))
        m.send(
            "agv1",
            "order",
            order(
                lay,
                ["r4c4", "r4c5", "r4c6"],
                order_id="o2",
                node_actions={"r4c6": [action("c", "startCharging")]},
            ),
        )
        pump(run, lambda: state().get("safetyState", {}).get("fieldViolation"), 20, "the stop")
        assert state()["lastNodeId"] in ("r4c4", "r4c5") and not state()["driving"]
        run.fleet.sim.set_boxes(np.zeros((0, 5)))
        pump(run, lambda: state().get("batteryState", {}).get("charging"), 30, "charging")
        assert v.errors == [] and run.fleet.sim.state.collisions.sum() == 0
        all_valid(m)
    finally:
        run.close()
        m.close()
