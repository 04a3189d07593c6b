"""The master over a real broker (Mosquitto): it learns the vehicles from their factsheets
and states, and its orders drive them through the crossing; what the vehicles saw on the
wire is the same protocol the in-process tests validate."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import paho.mqtt.client as mqtt
import pytest
from fleet_helpers import Mosquitto, room_scenario
from test_master_fleet import PLUS

from agvsim.fleet.schemas import problems
from agvsim.master.mqtt import MasteredFleetRun
from agvsim.scenario import load_scenario


class Orders:
    """Listens to the orders on the wire (what any vehicle would get)."""

    def __init__(self, port: int):
        self.got: list[tuple[str, dict]] = []
        self.lock = threading.Lock()
        self.ready = threading.Event()
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="order-listener")
        self.c.on_message = self._on
        self.c.on_subscribe = lambda *_a: self.ready.set()
        self.c.connect("127.0.0.1", port)
        self.c.subscribe("uagv/v2/agvsim/+/order", qos=0)
        self.c.loop_start()
        assert self.ready.wait(10)

    def _on(self, _c, _u, msg) -> None:
        with self.lock:
            self.got.append((msg.topic.split("/")[3], json.loads(msg.payload)))

    def of(self, serial: str) -> list[dict]:
        with self.lock:
            return [m for s, m in self.got if s == serial]

    def close(self) -> None:
        self.c.disconnect()
        self.c.loop_stop()


def test_master_over_mosquitto_delivers_both_orders(tmp_path: Path) -> None:
    mosq = Mosquitto().start()
    path = room_scenario(
        tmp_path,
        [("agvW", "differential", "r4c1", 0.0), ("agvE", "omni3", "r4c7", 180.0)],
        picture=PLUS,
        extra="master:\n  transports:\n"
        "    - {source: r4c2, destination: r4c6}\n"
        "    - {source: r4c6, destination: r4c2}\n",
    )
    run = MasteredFleetRun(load_scenario(path), f"mqtt://127.0.0.1:{mosq.port}")
    spy = Orders(mosq.port)
    try:
        assert run.connect() == 2
        m = run.master
        t0 = time.monotonic()
        while not (m.all_delivered and all(a.order_done for a in m.agvs.values())):
            assert time.monotonic() - t0 < 90, [t for t in m.transports]
            run.step()
            run.transport.poll(0.002)
        assert set(m.agvs) == {"agvW", "agvE"}
        assert m.agvs["agvE"].vehicle_type == "agvsim.omni3"  # from its factsheet
        assert run.link.received > 0
        # one transport each; which one depends on whose state reaches the master first over
        # the broker (nearest-idle dispatch itself: test_master_dispatch.py)
        assert sorted(t.vehicle for t in m.transports) == ["agvE", "agvW"]
        assert run.fleet.sim.state.robot_collisions.sum() == 0
        s = m.metrics.summary(m, float(run.fleet.sim.state.t_s))
        assert (s["orders_completed"], s["deadlocks"], s["stalls"]) == (2, 0, 0)
        run.wait_settled(0.5)
        orders = spy.of("agvW")
        assert orders and all(not problems("2.1.0", "order", o) for o in orders)
        assert orders[0]["orderUpdateId"] == 0 and orders[-1]["orderUpdateId"] == len(orders) - 1
        # base plus horizon: the first order already shows the whole route, mostly unreleased
        first = orders[0]["nodes"]
        assert first[-1]["nodeId"] == "r4c1" and not first[-1]["released"]
    finally:
        spy.close()
        run.close()
        mosq.stop()


def test_cli_fleet_runs_the_master_and_writes_its_outputs(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from agvsim.cli import app

    path = room_scenario(
        tmp_path,
        [("agvW", "differential", "r4c1", 0.0), ("agvE", "differential", "r4c7", 180.0)],
        picture=PLUS,
        extra="master:\n  transports:\n    - {source: r4c2, destination: r4c6}\n",
    )
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["fleet", str(path), "--speed", "8", "--duration", "30", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "master: agvsim's" in res.output
    doc = json.loads((out / "summary.json").read_text())
    s = doc["master"]
    assert (s["orders_placed"], s["orders_completed"], s["collisions"]) == (1, 1, 0)
    assert s["lead_time_mean_s"] > 0 and s["orders_per_hour"] == pytest.approx(3600 / 30, rel=0.01)
    assert (out / "waiting.png").stat().st_size > 1000
    assert f"outputs: {out}/summary.json, waiting.png" in res.output
