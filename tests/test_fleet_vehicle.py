"""VDA 5050 vehicles driven in-process (no broker): orders, updates, actions, pause, cancel,
loads, charging, battery and the protective field. Every message a vehicle publishes in these
tests is validated against the official schema."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from fleet_helpers import ROOM, action, instant, order, room_scenario

from agvsim.fleet.build import Fleet, build_fleet
from agvsim.fleet.schemas import problems
from agvsim.fleet.vehicle import Vehicle
from agvsim.scenario import load_scenario
from agvsim.world.lif import NodeProps, layout_from_grid, save_lif
from agvsim.world.loaders import parse_text_picture

EPOCH = datetime(2026, 1, 1, tzinfo=UTC)


class Run:
    """Steps a fleet and keeps (and validates) every message its vehicles publish."""

    def __init__(self, fleet: Fleet):
        self.fleet, self.sim = fleet, fleet.sim
        self.sent: dict[str, list[tuple[str, dict]]] = {v.cfg.serial: [] for v in fleet.vehicles}

    def v(self, serial: str = "agv1") -> Vehicle:
        return self.fleet.vehicle(serial)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.sim.step()
            for v in self.fleet.vehicles:
                for topic, msg, _ in v.drain():
                    bad = problems(v.dialect.version, topic, msg)
                    assert not bad, (topic, bad)
                    self.sent[v.cfg.serial].append((topic, msg))

    def until(self, cond: Callable[[], bool], max_s: float, what: str) -> float:
        t0 = self.sim.state.t_s
        while not cond():
            assert self.sim.state.t_s - t0 < max_s, f"no {what} within {max_s} s"
            self.step()
        return self.sim.state.t_s - t0

    def states(self, serial: str = "agv1") -> list[dict]:
        return [m for t, m in self.sent[serial] if t == "state"]

    def last_state(self, serial: str = "agv1") -> dict:
        self.v(serial)._dirty = True
        self.step()
        return self.states(serial)[-1]

    def pose(self, serial: str = "agv1") -> np.ndarray:
        return self.sim.state.poses[self.sim.robot_index(serial)].copy()


def make(tmp: Path, vehicles=(("agv1", "differential", "r4c1", 0.0),), **kw) -> Run:
    sc = load_scenario(room_scenario(tmp, list(vehicles), **kw))
    return Run(build_fleet(sc, epoch=EPOCH))


def statuses(state: dict) -> dict[str, str]:
    return {a["actionId"]: a["actionStatus"] for a in state["actionStates"]}


ROW4 = ["r4c1", "r4c2", "r4c3", "r4c4", "r4c5"]


@pytest.mark.parametrize("model", ["differential", "tricycle", "mecanum", "omni3", "ackermann"])
def test_full_order_every_model(tmp_path: Path, model: str) -> None:
    r = make(tmp_path, [("agv1", model, "r4c1", 0.0)])
    lay = r.fleet.layout
    route = [*ROW4, "r3c5", "r2c5"]
    acts = {"r2c5": [action("pick1", "pick", "HARD", loadId="L7", loadType="EPAL")]}
    r.v().receive("order", order(lay, route, node_actions=acts))
    r.step()
    s = r.states()[-1]
    assert (s["orderId"], s["lastNodeId"], s["lastNodeSequenceId"]) == ("o1", "r4c1", 0)
    assert [n["nodeId"] for n in s["nodeStates"]] == route[1:]
    assert [e["sequenceId"] for e in s["edgeStates"]] == [1, 3, 5, 7, 9, 11]
    assert statuses(s) == {"pick1": "WAITING"}
    # every node is passed in order
    r.until(lambda: r.v().last_node.node_id == "r2c5", 40, "arrival")
    passed = [m["lastNodeId"] for m in r.states()]
    assert [n for k, n in enumerate(passed) if k == 0 or n != passed[k - 1]] == route
    end = r.pose()
    assert math.hypot(end[0] - 1.0, end[1] - 2.0) <= 0.1  # r2c5 = (1, 2), allowed deviation
    assert r.last_state()["actionStates"][0]["actionStatus"] == "RUNNING"
    r.until(lambda: r.v().order_actions["pick1"].status == "FINISHED", 3, "pick")
    s = r.last_state()
    assert s["loads"] == [
        {"loadId": "L7", "loadPosition": "LHD1", "loadType": "EPAL", "weight": 50.0}
    ]  # the default load_kg: the action gave no weight
    assert s["nodeStates"] == [] and s["edgeStates"] == [] and not s["driving"]
    assert s["errors"] == []


def test_state_on_events_and_every_second(tmp_path: Path) -> None:
    r = make(tmp_path)
    r.step(int(round(5.0 / r.sim.dt_s)))  # idle: control at t = 0, 0.05, ..., 4.95 s
    stamps = [m["timestamp"] for m in r.states()]
    assert stamps == [f"2026-01-01T00:00:0{k}.000Z" for k in range(5)]
    ids = [m["headerId"] for m in r.states()]
    assert ids == list(range(len(ids)))
    vis = [m for t, m in r.sent["agv1"] if t == "visualization"]
    assert len(vis) == 5 and vis[1]["agvPosition"]["x"] == -3.0
    facts = [m for t, m in r.sent["agv1"] if t == "factsheet"]
    assert facts[0]["typeSpecification"]["agvKinematic"] == "DIFF"


def test_blocking_types_order_the_actions(tmp_path: Path) -> None:
    r = make(tmp_path)
    acts = {
        "r4c2": [
            action("look", "detectObject", "NONE"),
            action("pick", "pick", "HARD"),
            action("align", "finePositioning", "SOFT"),
        ]
    }
    r.v().receive("order", order(r.fleet.layout, ["r4c1", "r4c2", "r4c3"], node_actions=acts))
    r.until(lambda: r.v().last_node.node_id == "r4c2", 10, "r4c2")
    a = r.v().order_actions
    seen = []
    while a["align"].status != "FINISHED":
        seen.append((a["look"].status, a["pick"].status, a["align"].status, r.v().driving))
        r.step()
    # NONE runs at once, HARD waits for it, SOFT waits for the HARD one; no driving meanwhile
    assert seen[0] == ("RUNNING", "WAITING", "WAITING", False)
    assert ("FINISHED", "RUNNING", "WAITING", False) in seen
    assert ("FINISHED", "FINISHED", "RUNNING", False) in seen
    assert not any(d for *_, d in seen)
    # 1 s + 2 s + 1 s of actions at 20 Hz
    assert len(seen) == pytest.approx(80, abs=3)
    r.until(lambda: r.v().last_node.node_id == "r4c3", 10, "r4c3")


def test_edge_actions_run_on_the_edge(tmp_path: Path) -> None:
    r = make(tmp_path)
    acts = {"r4c2-r4c3": [action("scan", "detectObject", "NONE")]}
    r.v().receive(
        "order", order(r.fleet.layout, ["r4c1", "r4c2", "r4c3", "r4c4"], edge_actions=acts)
    )
    r.until(lambda: r.v().last_node.node_id == "r4c2", 10, "r4c2")
    assert r.v().order_actions["scan"].status in ("WAITING", "RUNNING")
    r.until(lambda: r.v().order_actions["scan"].status == "RUNNING", 0.2, "the edge action")
    assert r.v().driving
    r.until(lambda: r.v().last_node.node_id == "r4c3", 10, "r4c3")
    assert r.v().order_actions["scan"].status == "FINISHED"


def test_update_stitches_at_the_decision_point(tmp_path: Path) -> None:
    r = make(tmp_path)
    lay = r.fleet.layout
    route = [*ROW4, "r3c5"]
    r.v().receive("order", order(lay, route, released=3))  # base r4c1..r4c3, horizon after
    r.step()
    s = r.states()[-1]
    assert [(n["nodeId"], n["released"]) for n in s["nodeStates"]] == [
        ("r4c2", True),
        ("r4c3", True),
        ("r4c4", False),
        ("r4c5", False),
        ("r3c5", False),
    ]
    assert s["newBaseRequest"] is False
    r.until(lambda: r.v().last_node.node_id == "r4c3", 20, "decision point")
    r.step(40)  # it waits there
    s = r.last_state()
    assert not s["driving"] and s["lastNodeId"] == "r4c3" and s["newBaseRequest"] is True
    assert abs(r.pose()[0] + 1.0) <= 0.1  # r4c3 is at x = -1
    # a wrong stitch is refused and the order goes on as it was
    bad = order(lay, ["r4c4", "r4c5"], update=1, seq0=6)
    r.v().receive("order", bad)
    r.step()
    s = r.states()[-1]
    assert [e["errorType"] for e in s["errors"]] == ["orderUpdateError"]
    assert s["orderUpdateId"] == 0
    # the right one: starts at r4c3 (sequenceId 4), changes the horizon and releases it
    upd = order(lay, ["r4c3", "r4c4", "r3c4", "r2c4"], update=1, seq0=4)
    r.v().receive("order", upd)
    r.step()
    s = r.states()[-1]
    assert s["errors"] == [] and s["orderUpdateId"] == 1
    assert [(n["nodeId"], n["sequenceId"]) for n in s["nodeStates"]] == [
        ("r4c4", 6),
        ("r3c4", 8),
        ("r2c4", 10),
    ]
    r.until(lambda: r.v().last_node.node_id == "r2c4", 20, "end of the update")
    # an outdated update is refused
    r.v().receive("order", order(lay, ["r4c3", "r4c4"], update=0, seq0=4))
    assert [e["errorType"] for e in r.last_state()["errors"]] == ["orderUpdateError"]


def test_update_while_driving_extends_the_leg(tmp_path: Path) -> None:
    r = make(tmp_path)
    lay = r.fleet.layout
    r.v().receive("order", order(lay, [*ROW4], released=3))
    r.until(lambda: r.v().last_node.node_id == "r4c2", 20, "r4c2")
    r.v().receive("order", order(lay, ["r4c3", "r4c4", "r4c5"], update=1, seq0=4))
    stops = 0
    while r.v().last_node.node_id != "r4c5":
        r.step()
        stops += r.v().route_nodes != [] and not r.v().driving
        assert r.sim.state.t_s < 30
    assert stops <= 1  # it drove on through r4c3 without stopping


def test_cancel_mid_edge(tmp_path: Path) -> None:
    r = make(tmp_path)
    acts = {"r4c4": [action("p", "pick")]}
    r.v().receive("order", order(r.fleet.layout, ROW4, node_actions=acts))
    r.until(lambda: r.pose()[0] > -1.5, 10, "mid edge")
    r.v().receive("instantActions", instant(("c1", "cancelOrder")))
    r.step()
    here = r.pose()
    r.step(20)
    assert np.allclose(r.pose(), here)
    s = r.states()[-1]
    assert s["nodeStates"] == [] and s["edgeStates"] == [] and not s["driving"]
    assert statuses(s) == {"p": "FAILED", "c1": "FINISHED"}
    assert s["orderId"] == "o1" and s["lastNodeId"] == "r4c2"
    # nothing left to cancel
    r.v().receive("instantActions", instant(("c2", "cancelOrder")))
    s = r.last_state()
    assert statuses(s)["c2"] == "FAILED"
    assert s["errors"][-1]["errorType"] == "noOrderToCancel"
    assert {"referenceKey": "actionId", "referenceValue": "c2"} in s["errors"][-1][
        "errorReferences"
    ]
    # an update of the cancelled order is refused; a new order from where it stands is taken
    r.v().receive("order", order(r.fleet.layout, ["r4c2", "r4c3"], update=1, seq0=2))
    assert r.last_state()["errors"][-1]["errorType"] == "orderUpdateError"
    o2 = order(r.fleet.layout, ["r4c2", "r4c3"], order_id="o2")
    o2["nodes"][0]["nodePosition"]["allowedDeviationXY"] = 1.0
    r.v().receive("order", o2)
    r.until(lambda: r.v().last_node.node_id == "r4c3", 10, "new order")
    assert r.last_state()["errors"] == []


def test_pause_and_resume(tmp_path: Path) -> None:
    r = make(tmp_path)
    r.v().receive("order", order(r.fleet.layout, ROW4))
    r.until(lambda: r.pose()[0] > -1.5, 10, "mid edge")
    r.v().receive("instantActions", instant(("p1", "startPause")))
    r.step()
    here = r.pose()
    r.step(40)
    s = r.states()[-1]
    assert np.allclose(r.pose(), here) and s["paused"] and not s["driving"]
    r.v().receive("instantActions", instant(("p2", "stopPause")))
    r.step()
    assert not r.states()[-1]["paused"]
    r.until(lambda: r.v().last_node.node_id == "r4c5", 10, "the end")
    assert statuses(r.last_state()) == {"p1": "FINISHED", "p2": "FINISHED"}


def test_pick_then_drop_and_a_drop_with_nothing(tmp_path: Path) -> None:
    r = make(tmp_path)
    acts = {"r4c2": [action("pk", "pick", loadId="box")], "r4c4": [action("dp", "drop")]}
    r.v().receive("order", order(r.fleet.layout, ROW4, node_actions=acts))
    loads = []
    r.until(lambda: loads.append(len(r.v().loads)) or r.v().last_node.node_id == "r4c5", 30, "end")
    assert 1 in loads and loads[-1] == 0
    assert r.v().order_actions["dp"].status == "FINISHED"
    acts = {"r4c4": [action("dp2", "drop")]}
    r.v().receive(
        "order", order(r.fleet.layout, ["r4c5", "r4c4"], order_id="o2", node_actions=acts)
    )
    r.until(lambda: r.v().last_node.node_id == "r4c4", 10, "r4c4")
    s = r.last_state()
    assert statuses(s)["dp2"] == "FAILED" and s["errors"][-1]["errorType"] == "actionError"


def test_charging_only_on_a_charger(tmp_path: Path) -> None:
    grid = parse_text_picture(ROOM, 1.0, None)
    lay = layout_from_grid(grid, ["agvsim.differential"], "room")
    charger = lay.nodes["r4c3"]
    offer = ({"actionType": "startCharging", "blockingType": "HARD"},)
    nodes = dict(lay.nodes)
    nodes["r4c3"] = dataclasses.replace(
        charger, types={"agvsim.differential": NodeProps(None, offer)}
    )
    save_lif(tmp_path / "room.lif.json", [dataclasses.replace(lay, nodes=nodes)])
    r = make(tmp_path, layout="{file: room.lif.json}")
    r.v().receive("instantActions", instant(("c0", "startCharging")))
    s = r.last_state()
    assert statuses(s)["c0"] == "FAILED" and not s["batteryState"]["charging"]
    r.v().receive(
        "order",
        order(
            r.fleet.layout,
            ["r4c1", "r4c2", "r4c3"],
            node_actions={"r4c3": [action("ch", "startCharging")]},
        ),
    )
    r.until(lambda: r.v().battery.charging, 20, "charging")
    start = r.v().battery.charge_pct
    r.step(40)  # 2 s at 0.5 %/s
    s = r.states()[-1]
    assert s["batteryState"]["charging"]
    assert r.v().battery.charge_pct == pytest.approx(start + 1.0, abs=1e-9)
    assert s["batteryState"]["batteryCharge"] == pytest.approx(start + 1.0, abs=1e-3)
    r.v().receive("instantActions", instant(("c1", "stopCharging")))
    r.until(lambda: not r.v().battery.charging, 2, "stop")


def test_battery_drains_with_distance_and_time(tmp_path: Path) -> None:
    r = make(tmp_path)
    b = r.v().battery
    c0 = b.charge_pct
    r.step(21)  # idle: controlled at t = 0 .. 1.0 s
    assert b.charge_pct == pytest.approx(c0 - b.idle_pct_s * 1.0, abs=1e-9)
    c1, t1 = b.charge_pct, r.sim.state.t_s
    r.v().receive("order", order(r.fleet.layout, ROW4))
    r.until(lambda: r.v().last_node.node_id == "r4c5", 20, "the end")
    driven = float(r.sim.state.distance_m[0])
    used = c1 - b.charge_pct
    dt = r.sim.state.t_s - t1
    assert driven == pytest.approx(4.0, abs=0.1)
    assert used == pytest.approx(b.idle_pct_s * dt + b.drive_pct_m * driven, rel=0.02)
    assert r.last_state()["batteryState"]["reach"] == pytest.approx(b.charge_pct / 0.05, rel=1e-3)


def test_safety_field_stops_for_a_box_and_resumes(tmp_path: Path) -> None:
    r = make(tmp_path)
    r.v().receive("order", order(r.fleet.layout, ROW4))
    r.step(10)
    box = np.array([[1.0, 0.0, 0.0, 0.15, 0.15]])  # on the path, at r4c5 - 1 m
    r.sim.set_boxes(box)
    r.until(lambda: r.v().field_violation, 10, "field violation")
    s = r.last_state()
    assert s["safetyState"]["fieldViolation"] and not s["driving"]
    stop = r.pose()
    assert 0.15 + 0.25 < 1.0 - stop[0] < 1.6  # stopped short of the box, not far before
    r.step(40)
    assert np.allclose(r.pose(), stop)
    assert r.sim.state.collisions.sum() == 0
    r.sim.set_boxes(np.zeros((0, 5)))
    r.until(lambda: r.v().last_node.node_id == "r4c5", 10, "resumed to the end")
    assert not r.last_state()["safetyState"]["fieldViolation"]


def test_two_vehicles_told_to_cross_do_not_collide(tmp_path: Path) -> None:
    # agv1 is 2 m from the crossing, agv2 3 m: agv1 crosses, agv2's field stops it, then it
    # goes on. (Arriving together, both would wait for ever: traffic control is the master's.)
    r = make(tmp_path, [("agv1", "differential", "r4c2", 0.0), ("agv2", "mecanum", "r1c4", -90.0)])
    lay = r.fleet.layout
    r.v("agv1").receive("order", order(lay, ["r4c2", "r4c3", "r4c4", "r4c5", "r4c6"]))
    r.v("agv2").receive(
        "order", order(lay, ["r1c4", "r2c4", "r3c4", "r4c4", "r5c4", "r6c4"], serial="agv2")
    )
    violations = set()
    while {r.v(s).last_node.node_id for s in ("agv1", "agv2")} != {"r4c6", "r6c4"}:
        r.step()
        violations |= {v.cfg.serial for v in r.fleet.vehicles if v.field_violation}
        assert r.sim.state.t_s < 40, "both should get through"
    assert r.sim.state.robot_collisions.sum() == 0
    assert violations == {"agv2"}


def test_same_seed_same_messages(tmp_path: Path) -> None:
    out = []
    for k in range(2):
        d = tmp_path / str(k)
        d.mkdir()
        r = make(d)
        r.v().receive("order", order(r.fleet.layout, ROW4))
        r.step(200)
        out.append(r.sent["agv1"])
    assert out[0] == out[1]


def test_an_empty_battery_stops_the_vehicle_until_charged(tmp_path: Path) -> None:
    grid = parse_text_picture(ROOM, 1.0, None)
    lay = layout_from_grid(grid, ["agvsim.differential"], "room")
    offer = ({"actionType": "startCharging", "blockingType": "HARD"},)
    nodes = dict(lay.nodes)
    nodes["r4c2"] = dataclasses.replace(
        lay.nodes["r4c2"], types={"agvsim.differential": NodeProps(None, offer)}
    )
    save_lif(tmp_path / "room.lif.json", [dataclasses.replace(lay, nodes=nodes)])
    r = make(tmp_path, layout="{file: room.lif.json}")
    b = r.v().battery
    b.charge_pct = 0.06  # about a metre left
    r.v().receive("order", order(r.fleet.layout, ROW4))
    r.until(lambda: b.empty, 10, "an empty battery")
    r.step(20)
    s = r.last_state()
    assert s["errors"][-1]["errorType"] == "batteryEmpty" and not s["driving"]
    assert s["lastNodeId"] == "r4c2"  # it got one edge far (1 m at 0.05 %/m)
    here = r.pose()
    r.step(20)
    assert np.allclose(r.pose(), here)
    r.v().receive("instantActions", instant(("ch", "startCharging")))
    r.until(lambda: b.charge_pct > 1.0, 10, "charge")
    r.v().receive("instantActions", instant(("st", "stopCharging")))
    r.until(lambda: r.v().last_node.node_id == "r4c5", 20, "the rest of the order")
    assert r.last_state()["errors"] == []


def test_turning_on_the_spot_keeps_its_circle_clear(tmp_path: Path) -> None:
    r = make(tmp_path, [("agv1", "differential", "r4c4", 0.0)])
    # a post 0.34 m from the centre, inside the 0.37 m circle the body sweeps (+5 cm)
    r.sim.set_boxes(np.array([[0.34, -0.22, 0.0, 0.05, 0.05]]))
    r.step(3)  # a scan with the post in it
    r.v().receive("order", order(r.fleet.layout, ["r4c4", "r3c4"]))  # north: turn first
    r.step(20)
    s = r.last_state()
    assert s["safetyState"]["fieldViolation"] and not s["driving"]
    assert abs(r.pose()[2]) < 1e-9 and r.sim.state.collisions.sum() == 0
    r.sim.set_boxes(np.zeros((0, 5)))
    r.until(lambda: r.v().last_node.node_id == "r3c4", 10, "the turn and the edge")


def test_state_factsheet_requests_and_init_position(tmp_path: Path) -> None:
    r = make(tmp_path)
    r.step(3)
    n_state = len(r.states())
    n_fact = sum(t == "factsheet" for t, _ in r.sent["agv1"])
    r.v().receive(
        "instantActions",
        instant(
            ("s", "stateRequest"),
            ("f", "factsheetRequest"),
            ("bad", "initPosition"),
            ("good", "initPosition"),
            params={
                "bad": {"x": 2.0, "y": 2.0, "theta": 0.0, "mapId": "map", "lastNodeId": "r2c6"},
                "good": {"x": -3.0, "y": 0.05, "theta": 0.0, "mapId": "map", "lastNodeId": "X"},
            },
        ),
    )
    r.step()  # handled within the step it arrives in
    assert len(r.states()) == n_state + 1
    assert sum(t == "factsheet" for t, _ in r.sent["agv1"]) == n_fact + 1
    s = r.states()[-1]
    assert statuses(s) == {"s": "FINISHED", "f": "FINISHED", "bad": "FAILED", "good": "FINISHED"}
    assert s["lastNodeId"] == "X" and s["errors"][-1]["errorType"] == "actionError"


def test_a_robot_safety_scanner_reports_its_protective_field_violation(tmp_path: Path) -> None:
    # the robot's own safety: block replaces the fleet's path-shaped field: the engine's
    # safety stage brakes, the vehicle reports safetyState.fieldViolation from the same field
    import yaml

    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    data = yaml.safe_load(path.read_text())
    # 1 m/s x (0.1 s response + 0.05 s scan) + 1 / (2 x 1 m/s^2) + 0.25 m body = 1.0 m
    field = [[-0.35, -0.3], [1.1, -0.3], [1.1, 0.3], [-0.35, 0.3]]
    data["robots"][0]["safety"] = {
        "sensor": "lidar",
        "check_lengths": False,  # long enough for the fleet's 1 m/s, not the wheels' 2 m/s
        "field_sets": [{"name": "all", "protective": field}],
    }
    path.write_text(yaml.safe_dump(data))
    r = Run(build_fleet(load_scenario(path), epoch=EPOCH))
    assert r.v()._fields is not None
    r.v().receive("order", order(r.fleet.layout, ROW4))
    r.step(10)
    r.sim.set_boxes(np.array([[1.0, 0.0, 0.0, 0.15, 0.15]]))  # on the path
    r.until(lambda: r.v().field_violation, 10, "field violation")
    assert r.sim.state.safety_status[0] == 2  # the engine sees the same protective violation
    s = r.last_state()
    assert s["safetyState"]["fieldViolation"]
    r.step(40)
    stop = r.pose()
    assert 0.15 < 1.0 - stop[0] - 0.25  # stands short of the box
    assert r.sim.state.collisions.sum() == 0
    r.sim.set_boxes(np.zeros((0, 5)))
    r.until(lambda: r.v().last_node.node_id == "r4c5", 10, "resumed to the end")
    assert not r.last_state()["safetyState"]["fieldViolation"]


def test_a_vehicle_with_dynamics_drains_its_battery_by_motor_energy(tmp_path: Path) -> None:
    """With a dynamics: block the charge falls by the energy the motors deliver (positive
    wheel power over time, per ``battery_wh``), not by distance: checked against the power
    the simulation reports, step by step."""
    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    text = path.read_text().replace(
        "    sensors:\n",
        "    dynamics: {mass_kg: 60, motor: {gear_ratio: 20, torque_max_nm: 1.5}}\n    sensors:\n",
        1,
    )
    text = text.replace("start_node: r4c1}", "start_node: r4c1, battery_wh: 2}")
    path.write_text(text)
    r = Run(build_fleet(load_scenario(path), epoch=EPOCH))
    v = r.v()
    c0, b = v.battery.charge_pct, v.battery
    assert b.drive_pct_m == 0 and b.pct_per_j == pytest.approx(100 / (2 * 3600))
    r.v().receive("order", order(r.fleet.layout, ROW4))
    energy, dt = 0.0, r.sim.dt_s
    for _ in range(200):  # 10 s: it accelerates, drives and stops on r4c5
        energy += float(np.maximum(r.sim.state.wheel_power_w[0], 0).sum()) * dt
        r.step()
    assert v.last_node is not None and v.last_node.node_id == "r4c5"
    left = float(v._b.energy_j[0])  # delivered since the vehicle's last tick
    assert energy > 1.0  # accelerating 60 kg takes joules
    used = c0 - b.charge_pct
    expected = b.idle_pct_s * v.t_s + b.pct_per_j * (energy - left)
    assert used == pytest.approx(expected, rel=1e-9)


def test_a_picked_load_weighs_on_a_vehicle_with_dynamics(tmp_path: Path) -> None:
    """pick with a 'weight' makes the robot that much heavier (mass, and a longer
    friction-and-torque-limited stop); drop takes it off again."""
    path = room_scenario(tmp_path, [("agv1", "differential", "r4c1", 0.0)])
    text = path.read_text().replace(
        "    sensors:\n",
        "    dynamics: {mass_kg: 60, motor: {gear_ratio: 20, torque_max_nm: 1.5}}\n    sensors:\n",
        1,
    )
    path.write_text(text)
    r = Run(build_fleet(load_scenario(path), epoch=EPOCH))
    dyn = r.sim.dynamics
    assert dyn is not None
    m0, stop0 = float(dyn.mass_kg()[0]), dyn.stopping_distance_m(0, 1.0)
    acts = {"r4c2": [action("p", "pick", weight=120)], "r4c3": [action("d", "drop")]}
    r.v().receive("order", order(r.fleet.layout, ROW4[:3], node_actions=acts))
    r.until(lambda: bool(r.v().loads), 20, "the pick")
    r.step()  # the driver hands the load to the dynamics at its next step
    assert r.last_state()["loads"][0]["weight"] == 120.0
    assert float(dyn.mass_kg()[0]) == pytest.approx(m0 + 120.0)
    assert dyn.stopping_distance_m(0, 1.0) > stop0 * 1.5  # torque-limited: 180 kg vs 60 kg
    r.until(lambda: not r.v().loads, 20, "the drop")
    r.step()
    assert float(dyn.mass_kg()[0]) == pytest.approx(m0)


def test_a_pick_weight_that_is_no_mass_falls_back_to_load_kg() -> None:
    from agvsim.fleet.vehicle import _weight

    assert _weight("120", 50.0) == 120.0 and _weight(7, 50.0) == 7.0
    for bad in ("heavy", None, float("nan"), float("inf"), -1.0, 1e9, [3], {"kg": 3}):
        assert _weight(bad, 50.0) == 50.0, bad
