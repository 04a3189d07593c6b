"""Orders: the nodes and edges a master control sends, checked and put in one internal form.

``parse_order`` takes an order that already passed the official schema and checks what the
schema cannot: one edge fewer than nodes, sequence ids counting up by one from node to edge to
node, each edge joining its neighbours, no released element after an unreleased one, node
positions the vehicle can find (in the order or in its layout), action types it can perform,
sizes within its factsheet limits. A refusal is an ``OrderRefused`` carrying the spec's problem
kind and the references (``orderId``, ``nodeId``, ``actionId`` ...) the error will name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from agvsim.fleet.dialect import Problem
from agvsim.world.lif import Layout, Nurbs

DEFAULT_DEVIATION_XY_M = 0.1  # a stop node without allowedDeviationXY: reach it within this
DEFAULT_DEVIATION_THETA_RAD = 0.1


class OrderRefused(Exception):
    def __init__(self, kind: Problem, description: str, refs: dict[str, str] | None = None):
        super().__init__(description)
        self.kind, self.description, self.refs = kind, description, dict(refs or {})


@dataclass
class Action:
    """One action of an order or an instant action, and its progress."""

    action_id: str
    action_type: str
    blocking: str  # NONE | SOFT | HARD (3.0.0 also SINGLE, treated as HARD)
    params: dict[str, Any]
    description: str = ""
    status: str = "WAITING"
    result: str = ""
    remaining_s: float = 0.0  # work left once running

    @classmethod
    def from_json(cls, a: dict) -> Action:
        params = {p["key"]: p["value"] for p in a.get("actionParameters", ())}
        desc = a.get("actionDescription", a.get("actionDescriptor", ""))
        return cls(a["actionId"], a["actionType"], a["blockingType"], params, desc)


@dataclass
class OrderNode:
    node_id: str
    seq: int
    released: bool
    xy: tuple[float, float]
    theta: float | None
    dev_xy_m: float
    dev_theta_rad: float
    map_id: str
    actions: list[Action] = field(default_factory=list)
    _json: dict | None = field(default=None, init=False, repr=False, compare=False)

    def state_json(self) -> dict:
        """Its entry in ``state.nodeStates``: built once (a node of an order never changes;
        an update brings new node objects), shared by every state message - read only."""
        if self._json is None:
            pos = {"x": self.xy[0], "y": self.xy[1], "mapId": self.map_id}
            if self.theta is not None:
                pos["theta"] = self.theta
            self._json = {
                "nodeId": self.node_id,
                "sequenceId": self.seq,
                "released": self.released,
                "nodePosition": pos,
            }
        return self._json


@dataclass
class OrderEdge:
    edge_id: str
    seq: int
    released: bool
    start: str
    end: str
    max_speed_m_s: float | None
    trajectory: Nurbs | None
    actions: list[Action] = field(default_factory=list)
    _json: dict | None = field(default=None, init=False, repr=False, compare=False)

    def state_json(self) -> dict:
        """Its entry in ``state.edgeStates`` (built once, shared, read only)."""
        if self._json is None:
            self._json = {"edgeId": self.edge_id, "sequenceId": self.seq, "released": self.released}
        return self._json


@dataclass(frozen=True)
class Limits:
    """What the vehicle takes (its factsheet's protocolLimits)."""

    max_nodes: int = 1000
    max_actions_per_element: int = 50
    max_message_bytes: int = 1_000_000
    max_instant_actions: int = 50


def _deviation(pos: dict, key: str, default: float) -> float:
    v = pos.get(key)
    if v is None:
        return default
    if isinstance(v, dict):  # 3.0.0: an ellipse (a, b, theta): the inscribed circle
        return float(min(v["a"], v["b"]))
    return abs(float(v))


def parse_order(
    order: dict,
    layout: Layout | None,
    supported: dict[str, frozenset[str]],
    limits: Limits,
    vehicle_type: str,
) -> tuple[list[OrderNode], list[OrderEdge]]:
    """The order's nodes and edges, or ``OrderRefused`` (see the module docstring).
    ``supported`` maps action type -> scopes ("NODE", "EDGE") the vehicle runs it in."""
    oid = {"orderId": order["orderId"], "orderUpdateId": str(order["orderUpdateId"])}
    nodes_in, edges_in = order["nodes"], order["edges"]
    if len(nodes_in) > limits.max_nodes or len(edges_in) >= limits.max_nodes:
        raise OrderRefused(
            Problem.TOO_LARGE,
            f"the order has {len(nodes_in)} nodes and {len(edges_in)} edges; this vehicle "
            f"takes at most {limits.max_nodes} nodes (factsheet protocolLimits)",
            oid,
        )
    if not nodes_in:
        raise OrderRefused(Problem.VALIDATION, "an order needs at least one node", oid)
    if len(edges_in) != len(nodes_in) - 1:
        raise OrderRefused(
            Problem.VALIDATION,
            f"{len(nodes_in)} nodes need {len(nodes_in) - 1} edges, got {len(edges_in)}",
            oid,
        )
    seq0 = nodes_in[0]["sequenceId"]
    for i, n in enumerate(nodes_in):
        if n["sequenceId"] != seq0 + 2 * i:
            raise OrderRefused(
                Problem.VALIDATION,
                f"nodes[{i}] ({n['nodeId']}) has sequenceId {n['sequenceId']}, expected "
                f"{seq0 + 2 * i} (ids run node, edge, node, ... one apart)",
                oid | {"nodeId": n["nodeId"]},
            )
    for i, e in enumerate(edges_in):
        if e["sequenceId"] != seq0 + 2 * i + 1:
            raise OrderRefused(
                Problem.VALIDATION,
                f"edges[{i}] ({e['edgeId']}) has sequenceId {e['sequenceId']}, expected "
                f"{seq0 + 2 * i + 1}",
                oid | {"edgeId": e["edgeId"]},
            )
        a, b = nodes_in[i]["nodeId"], nodes_in[i + 1]["nodeId"]
        if e["startNodeId"] != a or e["endNodeId"] != b:
            raise OrderRefused(
                Problem.VALIDATION,
                f"edges[{i}] ({e['edgeId']}) runs {e['startNodeId']} -> {e['endNodeId']} but "
                f"lies between nodes {a} and {b}",
                oid | {"edgeId": e["edgeId"]},
            )
        if e["released"] and not (nodes_in[i]["released"] and nodes_in[i + 1]["released"]):
            raise OrderRefused(
                Problem.VALIDATION,
                f"edges[{i}] ({e['edgeId']}) is released but one of its nodes is not",
                oid | {"edgeId": e["edgeId"]},
            )
    flags = [
        x["released"]
        for pair in zip(nodes_in, [*edges_in, None], strict=True)
        for x in pair
        if x is not None
    ]
    if not nodes_in[0]["released"]:
        raise OrderRefused(Problem.VALIDATION, "the first node must be released", oid)
    if any(b and not a for a, b in zip(flags, flags[1:], strict=False)):
        raise OrderRefused(
            Problem.VALIDATION, "a released node or edge follows an unreleased one", oid
        )
    nodes = [_node(n, i, layout, supported, limits, oid) for i, n in enumerate(nodes_in)]
    edges = [
        _edge(e, i, layout, supported, limits, oid, vehicle_type) for i, e in enumerate(edges_in)
    ]
    return nodes, edges


def _actions(
    raw: list, where: str, scope: str, supported: dict, limits: Limits, oid: dict
) -> list[Action]:
    if not raw:
        return []
    if len(raw) > limits.max_actions_per_element:
        raise OrderRefused(
            Problem.TOO_LARGE,
            f"{where} has {len(raw)} actions; at most {limits.max_actions_per_element}",
            oid,
        )
    out = []
    for a in raw:
        if scope not in supported.get(a["actionType"], frozenset()):
            can = sorted(t for t, s in supported.items() if scope in s)
            raise OrderRefused(
                Problem.UNSUPPORTED_ACTION,
                f"{where}: action {a['actionType']!r} cannot run on a {scope.lower()}; "
                f"this vehicle runs {can}",
                oid | {"actionId": a["actionId"], "actionType": a["actionType"]},
            )
        out.append(Action.from_json(a))
    return out


def _node(
    n: dict, i: int, layout: Layout | None, supported: dict, limits: Limits, oid: dict
) -> OrderNode:
    pos = n.get("nodePosition")
    nid = n["nodeId"]
    if pos is not None:
        xy = (float(pos["x"]), float(pos["y"]))
        if not (math.isfinite(xy[0]) and math.isfinite(xy[1])):
            raise OrderRefused(Problem.VALIDATION, f"nodes[{i}] ({nid}): position not finite", oid)
        theta, map_id = pos.get("theta"), str(pos.get("mapId", ""))
    elif layout is not None and nid in layout.nodes:
        ln = layout.nodes[nid]
        xy, theta, map_id = (ln.x_m, ln.y_m), None, ln.map_id
    else:
        raise OrderRefused(
            Problem.NO_ROUTE,
            f"nodes[{i}]: node {nid!r} has no nodePosition and is not in the vehicle's layout",
            oid | {"nodeId": nid},
        )
    return OrderNode(
        nid,
        n["sequenceId"],
        n["released"],
        xy,
        None if theta is None else float(theta),
        _deviation(pos or {}, "allowedDeviationXY", DEFAULT_DEVIATION_XY_M),
        _deviation(pos or {}, "allowedDeviationTheta", DEFAULT_DEVIATION_THETA_RAD),
        map_id,
        _actions(n["actions"], f"nodes[{i}] ({nid})", "NODE", supported, limits, oid)
        if n["actions"]
        else [],
    )


def _edge(
    e: dict,
    i: int,
    layout: Layout | None,
    supported: dict,
    limits: Limits,
    oid: dict,
    vehicle_type: str,
) -> OrderEdge:
    traj = None
    if "trajectory" in e:
        t = e["trajectory"]
        if "knotVector" not in t:  # 3.0.0 may leave it out: a clamped uniform vector
            k, n = int(t.get("degree", 1)), len(t["controlPoints"])
            inner = [j / (n - k) for j in range(1, n - k)] if n > k else []
            t = t | {"knotVector": [0.0] * (k + 1) + inner + [1.0] * (k + 1)}
        traj = Nurbs.from_json(t)
        why = traj.problem()
        if why:
            raise OrderRefused(
                Problem.VALIDATION,
                f"edges[{i}] ({e['edgeId']}).trajectory: {why}",
                oid | {"edgeId": e["edgeId"]},
            )
    elif layout is not None and e["edgeId"] in layout.edges:
        props = layout.edges[e["edgeId"]].types.get(vehicle_type)
        traj = None if props is None else props.trajectory
    speed = e.get("maxSpeed", e.get("maximumSpeed"))
    if speed is not None and not (isinstance(speed, int | float) and 0 < speed < math.inf):
        raise OrderRefused(
            Problem.VALIDATION,
            f"edges[{i}] ({e['edgeId']}).maxSpeed: {speed!r} is not a speed > 0 (m/s)",
            oid | {"edgeId": e["edgeId"]},
        )
    return OrderEdge(
        e["edgeId"],
        e["sequenceId"],
        e["released"],
        e["startNodeId"],
        e["endNodeId"],
        None if speed is None else float(speed),
        traj,
        _actions(e["actions"], f"edges[{i}] ({e['edgeId']})", "EDGE", supported, limits, oid)
        if e["actions"]
        else [],
    )
