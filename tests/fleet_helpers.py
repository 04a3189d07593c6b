"""A minimal VDA 5050 master for the fleet tests: builds orders on a layout, publishes over
MQTT (or hands them in-process to a vehicle), and records what the vehicles send."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import paho.mqtt.client as mqtt
import pytest

from agvsim.net import free_port
from agvsim.world.lif import Layout

# A wait for a message over MQTT is bounded to catch a hang, never to time the broker: the
# bound a test names is what an idle machine needs, and a loaded one (the suite on every core,
# other jobs) may take this many times as long.
SLOW_MACHINE = 6.0

STAMP = "2026-01-01T00:00:00.00Z"


def order(
    layout: Layout,
    route: list[str],
    order_id: str = "o1",
    update: int = 0,
    serial: str = "agv1",
    seq0: int = 0,
    released: int | None = None,
    node_actions: dict | None = None,
    edge_actions: dict | None = None,
    version: str = "2.1.0",
    header: int = 1,
) -> dict:
    """An order over ``route`` (node ids); the first ``released`` nodes are the base."""
    released = len(route) if released is None else released
    node_actions, edge_actions = node_actions or {}, edge_actions or {}
    nodes = []
    for k, nid in enumerate(route):
        x, y = layout.node_xy(nid)
        nodes.append(
            {
                "nodeId": nid,
                "sequenceId": seq0 + 2 * k,
                "released": k < released,
                "nodePosition": {"x": x, "y": y, "mapId": "map"},
                "actions": node_actions.get(nid, []),
            }
        )
    edges = []
    for k, (a, b) in enumerate(zip(route, route[1:], strict=False)):
        edges.append(
            {
                "edgeId": f"{a}-{b}",
                "sequenceId": seq0 + 2 * k + 1,
                "released": k + 1 < released,
                "startNodeId": a,
                "endNodeId": b,
                "actions": edge_actions.get(f"{a}-{b}", []),
            }
        )
    return {
        "headerId": header,
        "timestamp": STAMP,
        "version": version,
        "manufacturer": "agvsim",
        "serialNumber": serial,
        "orderId": order_id,
        "orderUpdateId": update,
        "nodes": nodes,
        "edges": edges,
    }


def instant(
    *actions: tuple[str, str],
    serial: str = "agv1",
    version: str = "2.1.0",
    params: dict | None = None,
) -> dict:
    acts = []
    for aid, kind in actions:
        a = {"actionId": aid, "actionType": kind, "blockingType": "NONE"}
        if params and aid in params:
            a["actionParameters"] = [{"key": k, "value": v} for k, v in params[aid].items()]
        acts.append(a)
    return {
        "headerId": 1,
        "timestamp": STAMP,
        "version": version,
        "manufacturer": "agvsim",
        "serialNumber": serial,
        "actions": acts,
    }


def action(aid: str, kind: str, blocking: str = "HARD", **params) -> dict:
    a = {"actionId": aid, "actionType": kind, "blockingType": blocking}
    if params:
        a["actionParameters"] = [{"key": k, "value": v} for k, v in params.items()]
    return a


class Master:
    """Subscribes to everything under ``prefix/#`` and keeps the messages by topic."""

    def __init__(self, host: str, port: int, prefix: str = "uagv/v2/agvsim"):
        self.prefix, self.lock = prefix, threading.Lock()
        self.got: list[tuple[str, dict, bool, float]] = []
        self.c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"master{time.time()}")
        self.c.on_message = self._on
        self.c.connect(host, port)
        self.c.subscribe(f"{prefix}/#", qos=1)
        self.c.loop_start()

    def _on(self, _c, _u, msg) -> None:
        if msg.topic.endswith(("/order", "/instantActions")):
            return  # what the master itself sent
        with self.lock:
            self.got.append((msg.topic, json.loads(msg.payload), msg.retain, time.monotonic()))

    def send(self, serial: str, topic: str, payload: dict | bytes) -> float:
        data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        self.c.publish(f"{self.prefix}/{serial}/{topic}", data, qos=0).wait_for_publish(5)
        return time.monotonic()

    def messages(self, serial: str, topic: str) -> list[dict]:
        with self.lock:
            return [m for t, m, _, _ in self.got if t == f"{self.prefix}/{serial}/{topic}"]

    def last(self, serial: str, topic: str) -> dict | None:
        ms = self.messages(serial, topic)
        return ms[-1] if ms else None

    def close(self) -> None:
        self.c.loop_stop()
        self.c.disconnect()


def mosquitto_or_skip() -> str:
    exe = shutil.which("mosquitto") or (
        "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None
    )
    if exe is None:
        why = "Debian's mosquitto is not installed (apt-get install -y mosquitto)"
        if os.environ.get("AGVSIM_REQUIRE_MOSQUITTO") == "1":
            pytest.fail(why)
        pytest.skip(why)
    return exe


class Mosquitto:
    """A private Mosquitto on a free 127.0.0.1 port (its own config, no persistence)."""

    def __init__(self, port: int | None = None):
        self.exe = mosquitto_or_skip()
        self.port = port or free_port()
        self.dir = tempfile.mkdtemp(prefix="agvsim-mosq-")
        self.conf = Path(self.dir) / "m.conf"
        self.conf.write_text(
            f"listener {self.port} 127.0.0.1\nallow_anonymous true\n"
            "persistence false\nmax_keepalive 60\n"
        )
        self.proc: subprocess.Popen | None = None

    def start(self) -> Mosquitto:
        self.proc = subprocess.Popen(
            [self.exe, "-c", str(self.conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        t0 = time.monotonic()
        while time.monotonic() - t0 < 10:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return self
            except OSError:
                time.sleep(0.05)
        raise RuntimeError("mosquitto did not start")

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(10)
            self.proc = None


ROOM = """\
#########
#.......#
#.......#
#.......#
#.......#
#.......#
#.......#
#.......#
#########"""

BODIES = {
    "differential": "{wheel_radius_m: 0.1, half_track_m: 0.2}",
    "tricycle": "{wheel_radius_m: 0.1, wheelbase_m: 0.45, half_track_m: 0.2}",
    "ackermann": "{wheel_radius_m: 0.1, wheelbase_m: 0.45, half_track_m: 0.2}",
    "mecanum": "{wheel_radius_m: 0.05, half_length_m: 0.2, half_width_m: 0.2}",
    "omni3": "{wheel_radius_m: 0.05, base_radius_m: 0.2}",
}


def room_scenario(
    tmp: Path,
    vehicles: list[tuple[str, str, str, float]],
    layout: str = "{from_grid: true, simplify: false}",
    version: str = "2.1.0",
    picture: str = ROOM,
    extra: str = "",
) -> Path:
    """A 7 x 7 m walled room (node ``r{row}c{col}`` at x = col - 4, y = 4 - row) with
    vehicles ``(name, model, start node, heading deg)``."""
    rows = "\n".join(f"    {r}" for r in picture.splitlines())
    lines = [
        f"name: fleet test\ndt_s: 0.05\nworld:\n  cell_size_m: 1.0\n  picture: |\n{rows}",
        f"layout: {layout}",
        "robots:",
    ]
    for name, model, _node, th in vehicles:
        lines += [
            f"  - name: {name}",
            f"    model: {model}",
            f"    params: {BODIES[model]}",
            "    body: {length_m: 0.5, width_m: 0.4}",
            f"    pose: {{x_m: 0, y_m: 0, theta_deg: {th}}}",
            "    sensors:",
            "      - {type: lidar, beams: 91, fov_deg: 270, range_max_m: 5, rate_hz: 20}",
        ]
    lines += [f"vda5050:\n  version: {version}\n  pick_time_s: 2\n  drop_time_s: 2\n  vehicles:"]
    lines += [f"    - {{robot: {n}, start_node: {node}}}" for n, _m, node, _t in vehicles]
    path = tmp / "fleet.yaml"
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def charger_room(tmp: Path, charger: str = "r4c3") -> str:
    """Write ``room.lif.json`` (the ROOM's derived layout, ``charger`` offering
    startCharging to differential vehicles) into ``tmp``; returns the scenario's layout
    block."""
    import dataclasses

    from agvsim.world.lif import NodeProps, layout_from_grid, save_lif
    from agvsim.world.loaders import parse_text_picture

    lay = layout_from_grid(parse_text_picture(ROOM, 1.0, None), ["agvsim.differential"], "room")
    offer = ({"actionType": "startCharging", "blockingType": "HARD"},)
    nodes = dict(lay.nodes)
    nodes[charger] = dataclasses.replace(
        lay.nodes[charger], types={"agvsim.differential": NodeProps(None, offer)}
    )
    save_lif(tmp / "room.lif.json", [dataclasses.replace(lay, nodes=nodes)])
    return "{file: room.lif.json}"
