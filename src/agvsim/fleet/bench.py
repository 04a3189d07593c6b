"""The fleet benchmark behind ``agvsim bench --fleet`` (and ``benchmarks/bench_fleet.py``).

Workload: N differential vehicles, each on its own 4 x 2 m loop track (tracks 6 m apart in an
open hall), each carrying a 91-beam 270 deg 5 m safety lidar at 10 Hz, kinematics at 20 Hz,
vehicle control at 10 Hz, state every second plus on every event, visualization at 1 Hz. A
master in a separate process (paho) subscribes to every state and visualization and sends the
orders (node positions given). Measured, per broker (the embedded amqtt one, and Debian's
Mosquitto when installed):

* ``unpaced``: every vehicle gets one order of several laps (so all drive throughout), then
  the fleet runs as fast as it can; ``realtime_factor`` is simulated seconds per wall second
  (>= 1: N vehicles can run paced to real time);
* ``paced``: the fleet paced to real time, the master sending one lap per order and the next
  as soon as a vehicle reports the last one done; ``msgs_per_s`` is what the master received
  per second, ``accept_ms_p50`` / ``p95`` the wall time from the master publishing an order to
  it receiving the first state that shows it accepted.

Figures are printed, never asserted.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agvsim.fleet.broker import EmbeddedBroker
from agvsim.fleet.run import FleetRun
from agvsim.net import free_port
from agvsim.scenario import parse_scenario
from agvsim.world.lif import Edge, EdgeProps, Layout, Node, NodeProps, save_lif

TRACK = [(0.0, 0.0), (2.0, 0.0), (4.0, 0.0), (4.0, 2.0), (0.0, 2.0)]  # loop back to the start
SPACING_M = 6.0


def _layout(n: int) -> tuple[Layout, int, int]:
    cols = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / cols)
    nodes: dict[str, Node] = {}
    edges: dict[str, Edge] = {}
    props = {"agvsim.differential": NodeProps()}
    eprops = {"agvsim.differential": EdgeProps(True, 1.0)}
    for k in range(n):
        x0, y0 = 3.0 + SPACING_M * (k % cols), 3.0 + SPACING_M * (k // cols)
        ids = [f"v{k}n{j}" for j in range(len(TRACK))]
        for nid, (dx, dy) in zip(ids, TRACK, strict=True):
            nodes[nid] = Node(nid, x0 + dx, y0 + dy, props)
        for a, b in zip(ids, ids[1:] + ids[:1], strict=True):
            edges[f"{a}-{b}"] = Edge(f"{a}-{b}", a, b, eprops)
    return Layout("bench", nodes, edges, name="bench"), cols, rows


def _scenario(n: int, folder: Path) -> Any:
    layout, cols, rows = _layout(n)
    save_lif(folder / "bench.lif.json", [layout])
    w, h = int(SPACING_M * cols) + 2, int(SPACING_M * rows) + 2
    picture = "\n".join(["#" * w] + ["#" + "." * (w - 2) + "#"] * (h - 2) + ["#" * w])
    robots = [
        {
            "name": f"v{k}",
            "model": "differential",
            "params": {"wheel_radius_m": 0.1, "half_track_m": 0.2},
            "body": {"length_m": 0.5, "width_m": 0.4},
            "pose": {"x_m": layout.nodes[f"v{k}n0"].x_m, "y_m": layout.nodes[f"v{k}n0"].y_m},
            "sensors": [
                {"type": "lidar", "beams": 91, "fov_deg": 270, "range_max_m": 5.0, "rate_hz": 10}
            ],
        }
        for k in range(n)
    ]
    sc = parse_scenario(
        {
            "dt_s": 0.05,
            "world": {"cell_size_m": 1.0, "origin_xy_m": [0.0, 0.0], "picture": picture},
            "layout": {"file": "bench.lif.json"},
            "robots": robots,
            "vda5050": {
                "vehicles": [{"robot": f"v{k}", "start_node": f"v{k}n0"} for k in range(n)]
            },
        }
    )
    sc._base_dir = folder
    return sc, layout


def _master(
    host: str, port: int, n: int, nodes_json: str, seconds: float, q: Any, laps: int = 1
) -> None:
    """The master process: subscribe to every state, send each vehicle an order of ``laps``
    laps of its track, and the next one as soon as it reports the last one done."""
    import paho.mqtt.client as mqtt

    positions = json.loads(nodes_json)
    sent: dict[str, tuple[str, float]] = {}
    accepted: set[str] = set()
    latencies: list[float] = []
    count = [0]
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="agvsim-bench-master")
    serial_no = [0]

    def send(serial: str) -> None:
        serial_no[0] += 1
        oid = f"{serial}-{serial_no[0]}"
        k = int(serial[1:])
        ids = [f"v{k}n{j}" for _ in range(laps) for j in range(len(TRACK))] + [f"v{k}n0"]
        nodes = [
            {
                "nodeId": nid,
                "sequenceId": 2 * j,
                "released": True,
                "actions": [],
                "nodePosition": {"x": positions[nid][0], "y": positions[nid][1], "mapId": "map"},
            }
            for j, nid in enumerate(ids)
        ]
        edges = [
            {
                "edgeId": f"{a}-{b}",
                "sequenceId": 2 * j + 1,
                "released": True,
                "startNodeId": a,
                "endNodeId": b,
                "actions": [],
            }
            for j, (a, b) in enumerate(zip(ids, ids[1:], strict=False))
        ]
        msg = {
            "headerId": serial_no[0],
            "timestamp": "2026-01-01T00:00:00.00Z",
            "version": "2.1.0",
            "manufacturer": "agvsim",
            "serialNumber": serial,
            "orderId": oid,
            "orderUpdateId": 0,
            "nodes": nodes,
            "edges": edges,
        }
        sent[serial] = (oid, time.monotonic())
        c.publish(f"uagv/v2/agvsim/{serial}/order", json.dumps(msg))

    def on_message(_c: Any, _u: Any, m: Any) -> None:
        count[0] += 1
        if not m.topic.endswith("/state"):
            return
        s = json.loads(m.payload)
        serial = s["serialNumber"]
        oid, t = sent.get(serial, ("", 0.0))
        if s["orderId"] == oid and oid and oid not in accepted:
            accepted.add(oid)
            latencies.append((time.monotonic() - t) * 1000.0)
        if oid == "" or (s["orderId"] == oid and not s["nodeStates"] and not s["driving"]):
            send(serial)

    c.on_message = on_message
    c.connect(host, port)
    c.subscribe("uagv/v2/agvsim/+/state")
    c.subscribe("uagv/v2/agvsim/+/visualization")
    c.loop_start()
    q.put("ready")
    t0 = time.monotonic()
    time.sleep(seconds)
    c.loop_stop()
    wall = time.monotonic() - t0
    lat = np.array(latencies) if latencies else np.array([math.nan])
    q.put(
        {
            "msgs_per_s": round(count[0] / wall, 1),
            "orders": len(accepted),
            "accept_ms_p50": round(float(np.percentile(lat, 50)), 1),
            "accept_ms_p95": round(float(np.percentile(lat, 95)), 1),
        }
    )


def run_one(n: int, broker: str, sim_seconds: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        sc, layout = _scenario(n, Path(tmp))
        mosq = None
        if broker == "mosquitto":
            exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
            port = free_port()
            conf = Path(tmp) / "m.conf"
            conf.write_text(
                f"listener {port} 127.0.0.1\nallow_anonymous true\n"
                "persistence false\nmax_connections -1\n"
            )
            mosq = subprocess.Popen(
                [exe, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
            time.sleep(0.5)
            url: str | None = f"mqtt://127.0.0.1:{port}"
        else:
            url = None
        run = FleetRun(sc, url)
        try:
            online = run.connect(timeout_s=60)
            a = run.address
            ctx = mp.get_context("spawn")
            q = ctx.Queue()
            pos = {k: (v.x_m, v.y_m) for k, v in layout.nodes.items()}
            budget = 4.0 * sim_seconds + 30
            laps = int(sim_seconds // 10) + 2  # a lap takes about 14 s: busy throughout
            master = ctx.Process(
                target=_master, args=(a.host, a.port, n, json.dumps(pos), budget, q, laps)
            )
            master.start()
            q.get(timeout=60)
            t_wait = time.monotonic()
            while sum(v.busy for v in run.fleet.vehicles) < n and time.monotonic() - t_wait < 60:
                run.step()  # until every vehicle has its order
                run.transport.poll(0.005)
            t0, s0 = time.monotonic(), run.fleet.sim.state.t_s
            run.run(sim_seconds, speed=0.0)
            wall = time.monotonic() - t0
            sim_s = run.fleet.sim.state.t_s - s0
            master.terminate()
            master.join(5)
            driving = sum(v.driving or v.busy for v in run.fleet.vehicles)
        finally:
            run.close()
            if mosq is not None:
                mosq.terminate()
                mosq.wait(10)
    return {
        "vehicles": n,
        "online": online,
        "busy_at_end": driving,
        "realtime_factor": round(sim_s / wall, 2),
    }


def run_latency(n: int, broker: str, seconds: float) -> dict:
    """Order -> accepted latency with the fleet paced to real time."""
    with tempfile.TemporaryDirectory() as tmp:
        sc, layout = _scenario(n, Path(tmp))
        b = EmbeddedBroker().start() if broker == "embedded" else None
        mosq = None
        if b is None:
            exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
            port = free_port()
            conf = Path(tmp) / "m.conf"
            conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\n")
            mosq = subprocess.Popen(
                [exe, "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
            )
            time.sleep(0.5)
            url = f"mqtt://127.0.0.1:{port}"
        else:
            url = b.url
        run = FleetRun(sc, url)
        try:
            run.connect(timeout_s=60)
            ctx = mp.get_context("spawn")
            q = ctx.Queue()
            pos = {k: (v.x_m, v.y_m) for k, v in layout.nodes.items()}
            master = ctx.Process(
                target=_master,
                args=(run.address.host, run.address.port, n, json.dumps(pos), seconds, q),
            )
            master.start()
            q.get(timeout=60)
            run.run(seconds + 1.0, speed=1.0)
            out = q.get(timeout=30)
            master.join(5)
        finally:
            run.close()
            if b is not None:
                b.stop()
            if mosq is not None:
                mosq.terminate()
                mosq.wait(10)
    return {"vehicles": n, "paced": True} | out


def fleet_benchmark(quick: bool = False, log: Callable[[str], object] | None = None) -> dict:
    say = log or (lambda _m: None)
    brokers = ["embedded"] + (
        ["mosquitto"] if shutil.which("mosquitto") or Path("/usr/sbin/mosquitto").exists() else []
    )
    sizes = {
        "embedded": [100, 200] if quick else [100, 200, 300, 400],
        "mosquitto": [200, 400] if quick else [200, 400, 600, 1000],
    }
    seconds = 10.0 if quick else 20.0
    out: dict = {
        "workload": "N differential vehicles looping 4 x 2 m tracks; state 1 Hz + "
        "events, visualization 1 Hz, 91-beam lidar 10 Hz, dt 0.05 s"
    }
    for b in brokers:
        out[b] = {"unpaced": [], "paced": []}
        for n in sizes[b]:
            say(f"{b}: {n} vehicles, {seconds:g} simulated s unpaced ...")
            out[b]["unpaced"].append(run_one(n, b, seconds))
        n_lat = 100 if b == "embedded" else 300
        say(f"{b}: latency with {n_lat} vehicles paced to real time ...")
        out[b]["paced"].append(run_latency(n_lat, b, 10.0 if quick else 20.0))
    return out
