"""VDA 5050 messages: factsheets of every model in both versions, 3.0.0 vehicles, and every
kind of bad incoming message refused with the spec's error while the fleet carries on."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from fleet_helpers import action, instant, order
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fleet_vehicle import ROW4, make, statuses

from agvsim.fleet.messages import kinematic_kind, top_speed_m_s
from agvsim.fleet.schemas import VERSIONS, problems, reference_problems, schema
from agvsim.kinematics import MODELS

MODELS_ALL = list(MODELS)


@pytest.mark.parametrize("version", VERSIONS)
def test_every_schema_loads_and_is_valid(version: str) -> None:
    from jsonschema.validators import validator_for

    for topic in ("order", "instantActions", "state", "visualization", "connection", "factsheet"):
        s = schema(version, topic)
        validator_for(s).check_schema(s)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS_ALL)
def test_factsheet_of_every_model_validates(tmp_path: Path, model: str, version: str) -> None:
    r = make(tmp_path, [("agv1", model, "r4c1", 0.0)], version=version)
    f = r.v().factsheet()
    assert problems(version, "factsheet", f) == []
    wheels = f["mobileRobotGeometry" if version == "3.0.0" else "agvGeometry"]["wheelDefinitions"]
    assert len(wheels) == len(r.v().spec.model.wheel_names)
    kind = {
        "differential": "DIFF",
        "mecanum": "OMNI",
        "omni3": "OMNI",
        "tricycle": "THREEWHEEL",
        "ackermann": "THREEWHEEL",
    }[model]
    assert kinematic_kind(r.v().spec.model) == kind
    spec = f["typeSpecification"]
    assert spec.get("agvKinematic", spec.get("mobileRobotKinematic")) == kind
    phys = f["physicalParameters"]
    assert phys.get("length") == 0.5 and phys.get("width") == 0.4
    top = top_speed_m_s(r.v().spec.model)
    assert phys.get("speedMax", phys.get("maximumSpeed")) == min(1.0, top)
    if model == "differential":  # r = 0.1 m, 20 rad/s at most: 2 m/s
        assert top == pytest.approx(2.0)


def test_v3_vehicle_runs_an_order_with_valid_messages(tmp_path: Path) -> None:
    r = make(tmp_path, version="3.0.0")
    acts = {"r4c3": [action("pk", "pick", "HARD")]}
    r.v().receive("order", order(r.fleet.layout, ROW4[:3], node_actions=acts, version="3.0.0"))
    r.step()
    r.until(lambda: r.v().order_actions["pk"].status == "RUNNING", 20, "pick")
    r.v().receive("instantActions", instant(("p", "startPause"), version="3.0.0"))
    r.step(5)
    s = r.states()[-1]  # Run validated every message against the 3.0.0 schemas
    assert statuses(s) == {"pk": "PAUSED"}
    assert s["instantActionStates"] == [
        {"actionId": "p", "actionType": "startPause", "actionStatus": "FINISHED"}
    ]
    assert "powerSupply" in s and "mobileRobotPosition" in s
    vis = [m for t, m in r.sent["agv1"] if t == "visualization"][-1]
    assert vis["referenceStateHeaderId"] <= s["headerId"]
    assert problems("3.0.0", "connection", r.v().connection("CONNECTION_BROKEN")) == []


def _errors(r, serial: str = "agv1") -> list[str]:
    return [e["errorType"] for e in r.last_state(serial)["errors"]]


def test_every_bad_message_is_an_error_and_the_fleet_goes_on(tmp_path: Path) -> None:
    r = make(
        tmp_path, [("agv1", "differential", "r4c1", 0.0), ("agv2", "differential", "r2c1", 0.0)]
    )
    lay, v = r.fleet.layout, r.v()
    good = order(lay, ROW4)
    r.v("agv2").receive("order", order(lay, ["r2c1", "r2c2", "r2c3"], serial="agv2"))
    cases: list[tuple[str, object, str, str]] = [
        ("malformed JSON", b'{"headerId": 1, "orderId": ', "validationError", "JSON"),
        ("not an object", b"[1, 2, 3]", "validationError", "not a JSON object"),
        ("schema", {"headerId": 1}, "validationError", "is a required property"),
        ("version", good | {"version": "1.1.0"}, "validationError", "1.1.0"),
        ("serial", good | {"serialNumber": "agv9"}, "validationError", "agv9"),
        ("bytes", b" " * 1_000_001, "validationError", "1000001 bytes"),
    ]
    unknown = order(lay, ROW4)
    del unknown["nodes"][2]["nodePosition"]
    unknown["nodes"][2]["nodeId"] = "nowhere"
    unknown["edges"][1]["endNodeId"] = unknown["edges"][2]["startNodeId"] = "nowhere"
    cases.append(("unknown node", unknown, "noRouteError", "nowhere"))
    jump = order(lay, ROW4)
    jump["nodes"][3]["sequenceId"] = 9
    cases.append(("sequence jump", jump, "validationError", "sequenceId 9, expected 6"))
    cases.append(("huge", order(lay, ["r4c1", "r4c2"] * 600), "orderError", "at most 1000"))
    cases.append(
        (
            "action",
            order(lay, ROW4, node_actions={"r4c2": [action("x", "fly", "NONE")]}),
            "orderError",
            "'fly'",
        )
    )
    far = order(lay, ["r1c7", "r1c6"])
    cases.append(("far start", far, "noRouteError", "first node"))
    for name, payload, etype, words in cases:
        data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        v.receive("order", data)
        s = r.last_state()
        assert s["errors"], name
        err = s["errors"][-1]
        assert err["errorType"] == etype, name
        assert err["errorLevel"] == "WARNING"
        assert words in err["errorDescription"], (name, err["errorDescription"])
        assert s["orderId"] == "" and s["nodeStates"] == [], name
    # the errors stay until an order is accepted; then they go, and it drives
    assert len(r.last_state()["errors"]) == len(cases)
    v.receive("order", good)
    r.step()
    assert r.states()[-1]["errors"] == []
    # while busy, another order is refused and the first goes on
    v.receive("order", order(lay, ROW4, order_id="o2"))
    assert _errors(r) == ["orderError"]
    r.until(lambda: v.last_node.node_id == "r4c5", 20, "the first order's end")
    assert r.v("agv2").last_node.node_id == "r2c3"  # the other vehicle did its order
    # instant actions: an order-only action, and a malformed message
    v.receive("instantActions", instant(("i1", "pick")))
    assert _errors(r)[-1] == "instantActionError"
    v.receive("instantActions", b"nope")
    assert _errors(r)[-1] == "validationError"


def test_v3_error_names(tmp_path: Path) -> None:
    r = make(tmp_path, version="3.0.0")
    lay, v = r.fleet.layout, r.v()
    v.receive("order", b"{")
    assert _errors(r) == ["VALIDATION_FAILURE"]
    v.receive("order", order(lay, ["r1c7", "r1c6"], version="3.0.0"))
    assert _errors(r)[-1] == "START_NODE_OUT_OF_RANGE"
    v.receive("instantActions", instant(("c", "cancelOrder"), version="3.0.0"))
    assert _errors(r)[-1] == "NO_ORDER_TO_CANCEL"
    v.receive("order", order(lay, ROW4, version="3.0.0"))
    r.step()
    v.receive("order", order(lay, ROW4, order_id="o2", version="3.0.0"))
    assert _errors(r) == ["OTHER_ORDER_ACTIVE"]


JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-5, 10**12)
    | st.floats(allow_nan=False)
    | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=20,
)


@settings(
    max_examples=int(os.environ.get("AGVSIM_FUZZ_EXAMPLES", "60")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(data=st.data())
def test_mutated_messages_never_crash_a_vehicle(tmp_path_factory, data) -> None:
    r = make(tmp_path_factory.mktemp("fuzz"))
    good = order(r.fleet.layout, ROW4, node_actions={"r4c3": [action("a", "pick", "SOFT")]})
    good["edges"][1]["maxSpeed"] = 0.5
    a, b = good["nodes"][2]["nodePosition"], good["nodes"][3]["nodePosition"]
    good["edges"][2]["trajectory"] = {
        "degree": 1,
        "knotVector": [0, 0, 1, 1],
        "controlPoints": [{"x": a["x"], "y": a["y"]}, {"x": b["x"], "y": b["y"], "weight": 1.0}],
    }
    good["nodes"][2]["nodePosition"] |= {"allowedDeviationXY": 0.2, "theta": 0.0}
    msg = json.loads(json.dumps(good))
    # change one field deep inside the order to any JSON value, or drop it
    path = []
    node: object = msg
    while isinstance(node, dict | list) and node and data.draw(st.booleans()):
        key = data.draw(
            st.sampled_from(sorted(node) if isinstance(node, dict) else list(range(len(node))))
        )
        path.append(key)
        node = node[key]
    if path:
        parent = msg
        for k in path[:-1]:
            parent = parent[k]
        if data.draw(st.booleans()) and isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent[path[-1]] = data.draw(JSON)
    topic = data.draw(st.sampled_from(["order", "instantActions"]))
    r.v().receive(topic, json.dumps(msg).encode())
    r.step(30)  # Run validates every state it publishes
    s = r.states()[-1]
    # refused with an error, or taken as the order it now is (a mutated id is still an id)
    assert s["errors"] or (topic == "order" and s["orderId"] == msg["orderId"] != ""), s
    assert not [e for e in s["errors"] if e["errorType"] == "internalError"], s["errors"]


def test_zero_deviation_still_arrives(tmp_path: Path) -> None:
    r = make(tmp_path)
    o = order(r.fleet.layout, ROW4[:3])
    o["nodes"][-1]["nodePosition"] |= {
        "allowedDeviationXY": 0.0,
        "allowedDeviationTheta": 0.0,
        "theta": 1.0,
    }
    r.v().receive("order", o)
    r.step()
    r.until(lambda: not r.v().route_nodes, 20, "arrival")
    assert abs(r.pose()[2] - 1.0) <= 0.02 + 1e-9


def test_a_fault_in_one_vehicle_stops_only_it(tmp_path: Path, monkeypatch) -> None:
    r = make(
        tmp_path, [("agv1", "differential", "r4c1", 0.0), ("agv2", "differential", "r2c1", 0.0)]
    )
    lay = r.fleet.layout
    monkeypatch.setattr(r.v("agv1"), "_drive", lambda: 1 / 0)
    r.v("agv1").receive("order", order(lay, ROW4))
    r.v("agv2").receive("order", order(lay, ["r2c1", "r2c2", "r2c3"], serial="agv2"))
    r.until(lambda: r.v("agv2").last_node.node_id == "r2c3", 20, "agv2's order")
    s = r.last_state("agv1")
    assert s["errors"][0]["errorType"] == "internalError"
    assert "ZeroDivisionError" in s["errors"][0]["errorDescription"]
    assert np.allclose(r.pose("agv1"), (-3.0, 0.0, 0.0))


@pytest.mark.parametrize("version", VERSIONS)
def test_the_reference_validator_agrees(tmp_path: Path, version: str) -> None:
    """Every kind of message a vehicle sends passes python-jsonschema too, and broken copies
    fail both validators."""
    r = make(tmp_path, version=version)
    acts = {"r4c3": [action("pk", "pick", "HARD")]}
    r.v().receive("order", order(r.fleet.layout, ROW4[:3], node_actions=acts, version=version))
    r.step(120)
    sent = r.sent["agv1"] + [("connection", r.v().connection("ONLINE"))]
    kinds = {t for t, _ in sent}
    assert kinds == {"state", "visualization", "factsheet", "connection"}
    for topic, msg in sent:
        assert reference_problems(version, topic, msg) == [], topic
        broken = dict(msg)
        broken["headerId"] = "one"
        assert problems(version, topic, broken) and reference_problems(version, topic, broken)
