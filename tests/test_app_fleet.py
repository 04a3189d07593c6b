"""The browser app with the fleet layer: a scenario's layout drawn in the 3D scene, and a
scenario with a ``vda5050:`` block served as VDA 5050 vehicles that a master drives over
MQTT (the embedded broker; no browser)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from fleet_helpers import SLOW_MACHINE, Master, order, room_scenario

from agvsim.scenario import ScenarioError

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
ROW = ["r4c1", "r4c2", "r4c3", "r4c4"]


def test_a_vda5050_scenario_served_by_the_app_takes_orders_over_mqtt(tmp_path: Path) -> None:
    pytest.importorskip("viser")
    from agvsim.app.fleet_view import FleetSession
    from agvsim.app.server import open_session

    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    s = open_session(path, master=False)  # the test is the master (serve --no-master)
    assert isinstance(s, FleetSession) and s.broker is not None and s.link is None
    m = None
    try:
        assert s.broker_url.startswith("mqtt://127.0.0.1:")
        assert s.banner() == [
            f"VDA 5050 2.1.0: 1 vehicles on the embedded broker {s.broker_url}, "
            "topics uagv/v2/agvsim/<serial>/<topic>; waiting for your master's orders"
        ]
        host, port = s.broker_url.removeprefix("mqtt://").rsplit(":", 1)
        m = Master(host, int(port))

        def pump(cond, max_s: float, what: str) -> None:
            t0 = time.monotonic()
            while not cond():
                assert time.monotonic() - t0 < max_s * SLOW_MACHINE, f"timed out waiting for {what}"
                s.step()  # what the app's stepping thread does: step, flush, poll
                time.sleep(0.002)

        pump(lambda: m.last("agv1", "factsheet") is not None, 10, "the retained factsheet")
        x0 = s.sim.state.poses[0, :2].copy()
        assert x0 == pytest.approx(s.fleet.layout.node_xy("r4c1"))
        m.send("agv1", "order", order(s.fleet.layout, ROW))
        pump(lambda: (m.last("agv1", "state") or {}).get("orderId") == "o1", 10, "accept")
        pump(lambda: m.last("agv1", "state")["lastNodeId"] == "r4c4", 60, "the last node")
        assert np.hypot(*(s.sim.state.poses[0, :2] - s.fleet.layout.node_xy("r4c4"))) < 0.2
        assert np.hypot(*(s.sim.state.poses[0, :2] - x0)) > 2.5  # it drove 3 m along the row
        s.pause()
        assert s.advance(0.05) == 0  # paused: no step, the sockets are still served
        # reset rebuilds the fleet: the vehicle reconnects at its start node, with no order
        old = s.transport
        s.reset()
        assert s.transport is not old and s.transport is not None
        assert s.sim.state.poses[0, :2] == pytest.approx(x0)
        pump(lambda: m.last("agv1", "state")["lastNodeId"] == "r4c1", 10, "the state after reset")
        assert m.last("agv1", "state")["orderId"] == ""
        assert m.last("agv1", "connection")["connectionState"] == "ONLINE"
    finally:
        s.close()
    assert s.broker is None and s.transport is None
    if m is not None:
        m.close()


def test_closing_the_app_publishes_offline(tmp_path: Path) -> None:
    pytest.importorskip("viser")
    from agvsim.app.server import open_session

    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    s = open_session(path, master=False)
    host, port = s.broker_url.removeprefix("mqtt://").rsplit(":", 1)
    m = Master(host, int(port))
    try:
        t0 = time.monotonic()
        while (m.last("agv1", "connection") or {}).get("connectionState") != "ONLINE":
            assert time.monotonic() - t0 < 20, "no ONLINE"
            s.step()
            time.sleep(0.01)
    finally:
        s.close()
    t0 = time.monotonic()
    while m.last("agv1", "connection")["connectionState"] != "OFFLINE":
        assert time.monotonic() - t0 < 20, "no OFFLINE after close"
        time.sleep(0.02)
    m.close()


def test_the_app_runs_the_built_in_master_over_its_broker(tmp_path: Path) -> None:
    """``agvsim serve`` on a scenario with transports: agvsim's master control connects to the
    app's embedded broker like any master and has the vehicle carry the load; a reset starts
    the master afresh with the fleet."""
    pytest.importorskip("viser")
    from agvsim.app.server import open_session

    path = room_scenario(
        tmp_path,
        [("agv1", "differential", "r4c1", 0.0)],
        extra="master:\n  transports:\n    - {source: r4c4, destination: r2c2}\n",
    )
    s = open_session(path)
    try:
        assert s.link is not None and "agvsim's master control drives them" in s.banner()[0]
        master = s.link.master
        t0 = time.monotonic()
        while master.transports[0].delivered_s is None:
            assert time.monotonic() - t0 < 120, "the transport was not delivered"
            s.step()
        tr = master.transports[0]
        assert tr.vehicle == "agv1" and 0 < tr.delivered_s <= s.sim.state.t_s
        assert s.sim.state.robot_collisions.sum() == 0
        s.reset()
        assert s.link is not None and s.link.master is not master
        assert s.link.master.transports[0].delivered_s is None
    finally:
        s.close()
    assert s.link is None


def test_broker_is_refused_for_a_scenario_without_vehicles(tmp_path: Path) -> None:
    pytest.importorskip("viser")
    from agvsim.app.server import open_session

    path = tmp_path / "plain.yaml"
    path.write_text("world: {maze: thesis_c1}\nrobots: [{name: a, model: differential}]\n")
    with pytest.raises(ScenarioError, match="--broker needs a scenario with a 'vda5050:'"):
        open_session(path, broker="mqtt://127.0.0.1:1883")


def test_the_layout_is_drawn_in_the_scene_and_follows_a_loaded_scenario(tmp_path: Path) -> None:
    pytest.importorskip("viser")
    from agvsim.app.server import App, open_session
    from agvsim.fleet.build import load_layout
    from agvsim.fleet.viz import layout_geometry
    from agvsim.net import free_port

    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    text = path.read_text().split("vda5050:")[0]  # a layout, no vehicles: a plain session
    path.write_text(text)
    app = App(open_session(path), port=free_port())  # loops not started: driven here
    try:
        sc = app.session._scenario(app.session.config)
        want = layout_geometry(load_layout(sc, sc._base_dir))
        app.scene.update()
        by_name = {h.name: h for h in app.scene._layout_nodes}
        assert set(by_name) == {"/layout/edges", "/layout/nodes"}
        assert np.asarray(by_name["/layout/edges"].points) == pytest.approx(want.segments)
        nodes = np.asarray(by_name["/layout/nodes"].points, np.float64)  # viser: float16
        assert nodes == pytest.approx(want.nodes, abs=2e-3)
        assert len(want.nodes) == 49  # the 7 x 7 free cells of the room
        live = app.server.scene._handle_from_node_name
        assert "/layout/edges" in live and "/layout/nodes" in live
        # a scenario without a layout: the drawing goes away with the old world
        app.session.load_yaml("world: {maze: thesis_c1}\nrobots: [{name: a, model: differential}]")
        app.scene.update()
        assert app.scene._layout_nodes == []
        assert not any(n.startswith("/layout/") for n in app.server.scene._handle_from_node_name)
    finally:
        app.server.stop()


def test_serve_refuses_a_bad_broker_address(tmp_path: Path) -> None:
    pytest.importorskip("viser")
    from typer.testing import CliRunner

    from agvsim.cli import app

    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    res = CliRunner().invoke(
        app, ["serve", str(path), "--broker", "http://h:1"], env={"COLUMNS": "200"}
    )
    assert res.exit_code == 2
    assert "expected mqtt://HOST:PORT" in res.output
