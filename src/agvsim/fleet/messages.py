"""The messages a vehicle publishes, as plain dicts shaped by the official schemas.

``Stamper`` adds the protocol header (headerId counted per topic, timestamp, version,
manufacturer, serialNumber); timestamps are the run's epoch plus simulated time, so a run
with a fixed epoch publishes identical messages every time. ``factsheet`` describes a robot
from its kinematic model and body (VDA 5050 6.15). The tests validate every kind of message
built here against the schema of each supported version.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np

from agvsim.control.mobility import Mobility
from agvsim.fleet.actions import ACTION_TYPES
from agvsim.fleet.dialect import Dialect
from agvsim.fleet.order import Limits
from agvsim.sim.spec import RobotSpec

if TYPE_CHECKING:
    from agvsim.fleet.vehicle import Vehicle

TOPICS_OUT = ("state", "visualization", "connection", "factsheet")


@lru_cache(maxsize=16)  # a fleet's vehicles share the epoch and stamp many messages a step
def iso_time(epoch: datetime, t_s: float) -> str:
    """ISO 8601 UTC with milliseconds, e.g. 2026-11-25T07:40:03.120Z."""
    t = epoch + timedelta(seconds=round(t_s, 3))
    return t.replace(tzinfo=None).isoformat(timespec="milliseconds") + "Z"


@dataclass
class Stamper:
    dialect: Dialect
    manufacturer: str
    serial: str
    epoch: datetime = field(default_factory=lambda: datetime.now(UTC))
    counters: dict[str, int] = field(default_factory=dict)

    def header(self, topic: str, t_s: float) -> dict[str, Any]:
        n = self.counters.get(topic, -1) + 1
        self.counters[topic] = n
        return {
            "headerId": n,
            "timestamp": iso_time(self.epoch, t_s),
            "version": self.dialect.version,
            "manufacturer": self.manufacturer,
            "serialNumber": self.serial,
        }


def connection(stamp: Stamper, t_s: float, state: str) -> dict:
    return stamp.header("connection", t_s) | {"connectionState": state}


def position_json(pose: np.ndarray, map_id: str, v3: bool) -> dict:
    p = {
        "x": round(float(pose[0]), 6),
        "y": round(float(pose[1]), 6),
        "theta": round(float(pose[2]), 6),
        "mapId": map_id,
    }
    return p | ({"localized": True} if v3 else {"positionInitialized": True})


def velocity_json(twist: tuple[float, float, float]) -> dict:
    return {"vx": round(twist[0], 6), "vy": round(twist[1], 6), "omega": round(twist[2], 6)}


def action_state(a: Any, v3: bool, paused_ok: bool) -> dict:
    status = a.status
    if status == "PAUSED" and not paused_ok:
        status = "RUNNING"
    out = {"actionId": a.action_id, "actionType": a.action_type, "actionStatus": status}
    if a.description:
        out["actionDescriptor" if v3 else "actionDescription"] = a.description
    if a.result:
        out["actionResult" if v3 else "resultDescription"] = a.result
    return out


def state(v: Vehicle) -> dict:
    """The vehicle's ``state`` message (VDA 5050 6.10, in its dialect's field names)."""
    v3 = v.v3
    ok = v.dialect.has_paused_status
    order_states = [action_state(a, v3, ok) for a in v.order_actions.values()]
    instant_states = [action_state(a, v3, ok) for a in v.instant_actions]
    node_states, released_left = v.node_states()
    last = v.last_node
    out: dict[str, Any] = v.stamp.header("state", v.t_s) | {
        "orderId": v.order_id,
        "orderUpdateId": v.update_id,
        "lastNodeId": "" if last is None else last.node_id,
        "lastNodeSequenceId": 0 if last is None else last.seq,
        "nodeStates": node_states,
        "edgeStates": v.edge_states(),
        "driving": v.driving,
        "paused": v.paused,
        "newBaseRequest": released_left <= 1 and len(v.route_nodes) > released_left,
        "distanceSinceLastNode": round(v.distance_since_node_m, 4),
        "operatingMode": "AUTOMATIC",
        "loads": list(v.loads),
        "errors": [e for _, e in v.errors],
        "information": [],
        "velocity": velocity_json(v.twist),
    }
    pos = position_json(v.pose, v.cfg.map_id, v3)
    if v3:
        return out | {
            "actionStates": order_states,
            "instantActionStates": instant_states,
            "powerSupply": v.battery.state_json(True),
            "safetyState": {"activeEmergencyStop": "NONE", "fieldViolation": v.field_violation},
            "mobileRobotPosition": pos,
        }
    return out | {
        "actionStates": order_states + instant_states,
        "batteryState": v.battery.state_json(False),
        "safetyState": {"eStop": "NONE", "fieldViolation": v.field_violation},
        "agvPosition": pos,
    }


def periodic_state(v: Vehicle, last: dict) -> dict:
    """The vehicle's ``state`` when nothing but its motion and charge changed since ``last``
    (its previous state message: no event in between, see ``Vehicle._publish_due``): that
    message with a new header, position, velocity, battery and distance since the node.
    The same dict ``state`` would build, for a fraction of the work."""
    out = dict(last)
    stamp = v.stamp  # the header's other fields are the last state's
    out["headerId"] = n = stamp.counters.get("state", -1) + 1
    stamp.counters["state"] = n
    out["timestamp"] = iso_time(stamp.epoch, v.t_s)
    out["distanceSinceLastNode"] = round(v.distance_since_node_m, 4)
    out["velocity"] = velocity_json(v.twist)
    pos = position_json(v.pose, v.cfg.map_id, v.v3)
    if v.v3:
        out["powerSupply"] = v.battery.state_json(True)
        out["mobileRobotPosition"] = pos
    else:
        out["batteryState"] = v.battery.state_json(False)
        out["agvPosition"] = pos
    return out


def visualization(
    stamp: Stamper, t_s: float, pose: np.ndarray, twist: tuple, map_id: str, state_header_id: int
) -> dict:
    v3 = stamp.dialect.version.startswith("3")
    key = "mobileRobotPosition" if v3 else "agvPosition"
    out = stamp.header("visualization", t_s) | {
        key: position_json(pose, map_id, v3),
        "velocity": velocity_json(twist),
    }
    if v3:
        out["referenceStateHeaderId"] = max(state_header_id, 0)
    return out


# ------------------------------------------------------------------------------ factsheet
def top_speed_m_s(model: Any) -> float:
    """The fastest straight-ahead speed the model's wheel speed limit allows (m/s)."""
    wheels = np.abs(np.asarray(model.inverse(np.array([[1.0, 0.0, 0.0]])).speeds)).max()
    limit = float(np.min(np.asarray(model.max_wheel_speed_rad_s)))
    return limit / float(wheels) if wheels > 0 else float("inf")


def kinematic_kind(model: Any) -> str:
    """VDA 5050's agvKinematic: DIFF, OMNI or THREEWHEEL. Ackermann (no such value in the
    spec) is reported as THREEWHEEL, the nearest: a steered front axle on a bicycle model."""
    if getattr(model, "holonomic", False):
        return "OMNI"
    return "THREEWHEEL" if getattr(model, "has_steering", False) else "DIFF"


def _wheels(spec: RobotSpec) -> list[dict]:
    m = spec.model
    pos = np.asarray(m.wheel_positions_m(), dtype=np.float64).reshape(-1, 2)
    r = float(np.asarray(m.wheel_radius_m).reshape(-1)[0])
    kind = type(m).__name__
    out = []
    for k, name in enumerate(m.wheel_names):
        driven, steered = k in m.driven_wheels, k in m.steered_wheels
        wtype = "MECANUM" if kind == "Mecanum" else ("DRIVE" if driven else "FIXED")
        w = {
            "type": wtype,
            "isActiveDriven": bool(driven),
            "isActiveSteered": bool(steered),
            "position": {"x": round(float(pos[k, 0]), 6), "y": round(float(pos[k, 1]), 6)},
            "diameter": 2 * r,
            "width": round(0.4 * r, 6),
        }
        if kind == "Omni3":
            w["constraints"] = f"{name}: omni wheel, free rollers at 90 deg"
        out.append(w)
    return out


def factsheet(
    stamp: Stamper,
    t_s: float,
    spec: RobotSpec,
    series: str,
    max_speed_m_s: float,
    limits: Limits,
    state_period_s: float,
    vis_period_s: float,
    action_durations: dict[str, float],
) -> dict:
    v3 = stamp.dialect.version.startswith("3")
    hl, hw = spec.footprint_half_m
    off = spec.body_offset_x_m
    poly = [(off + hl, hw), (off - hl, hw), (off - hl, -hw), (off + hl, -hw)]
    mob = Mobility.of(spec.model)
    actions = []
    for name, t in ACTION_TYPES.items():
        a: dict[str, Any] = {
            "actionType": name,
            "actionDescription": t.description
            + (f" ({action_durations.get(name, t.duration_s):g} s)" if t.duration_s else ""),
            "actionScopes": sorted(t.scopes),
        }
        if name in ("pick", "drop"):
            a["actionParameters"] = [
                {"key": k, "valueDataType": "STRING", "isOptional": True}
                for k in ("lhd", "loadId", "loadType", "stationType")
            ]
        if v3:
            a |= {"pauseAllowed": "YES", "cancelAllowed": "YES"}
        actions.append(a)
    kinematic = kinematic_kind(spec.model)
    type_spec: dict[str, Any] = {
        "seriesName": series,
        "seriesDescription": f"agvsim {type(spec.model).__name__} "
        f"({'can' if mob.can_spin else 'cannot'} turn on the spot)",
        "localizationTypes": ["NATURAL"],
        "navigationTypes": ["VIRTUAL_LINE_GUIDED"],
    }
    if v3:  # the 3.0.0 schema requires 'mobileRobotKinematic' but describes '...Kinematics'
        type_spec |= {
            "mobileRobotKinematic": kinematic,
            "mobileRobotKinematics": kinematic,
            "mobileRobotClass": "CARRIER",
            "maximumLoadMass": 100.0,
        }
        physical = {
            "minimumSpeed": 0.0,
            "maximumSpeed": max_speed_m_s,
            "maximumAcceleration": 1.0,
            "maximumDeceleration": 1.0,
            "minimumHeight": 0.0,
            "maximumHeight": round(spec.height_m, 6),
            "width": 2 * hw,
            "length": 2 * hl,
        }
        limits_json: dict[str, Any] = {
            "maximumStringLengths": {"maximumMessageLength": limits.max_message_bytes},
            "maximumArrayLengths": {
                "order.nodes": limits.max_nodes,
                "order.edges": limits.max_nodes - 1,
                "node.actions": limits.max_actions_per_element,
                "edge.actions": limits.max_actions_per_element,
                "instantActions": limits.max_instant_actions,
            },
        }
    else:
        type_spec |= {"agvKinematic": kinematic, "agvClass": "CARRIER", "maxLoadMass": 100.0}
        physical = {
            "speedMin": 0.0,
            "speedMax": max_speed_m_s,
            "accelerationMax": 1.0,
            "decelerationMax": 1.0,
            "heightMax": round(spec.height_m, 6),
            "width": 2 * hw,
            "length": 2 * hl,
        }
        limits_json = {
            "maxStringLens": {"msgLen": limits.max_message_bytes},
            "maxArrayLens": {
                "order.nodes": limits.max_nodes,
                "order.edges": limits.max_nodes - 1,
                "node.actions": limits.max_actions_per_element,
                "edge.actions": limits.max_actions_per_element,
                "instantActions": limits.max_instant_actions,
            },
        }
    timing = "minimum{}Interval" if v3 else "min{}Interval"
    limits_json["timing"] = {
        timing.format("Order"): 0.0,
        timing.format("State"): 0.0,
        "defaultStateInterval": state_period_s,
        "visualizationInterval": vis_period_s,
    }
    outline = [{"x": x, "y": y} for x, y in poly]
    envelope = (
        {"envelope2dId": "body", "vertices": outline}
        if v3
        else {"set": "body", "polygonPoints": outline}
    )
    geometry = {"wheelDefinitions": _wheels(spec), "envelopes2d": [envelope]}
    out = stamp.header("factsheet", t_s) | {
        "typeSpecification": type_spec,
        "physicalParameters": physical,
        "protocolLimits": limits_json,
        "protocolFeatures": {
            "optionalParameters": [
                {"parameter": "order.edges.trajectory", "support": "SUPPORTED"},
                {"parameter": "order.edges.maxSpeed", "support": "SUPPORTED"},
            ],
            ("mobileRobotActions" if v3 else "agvActions"): actions,
        },
        ("mobileRobotGeometry" if v3 else "agvGeometry"): geometry,
        "loadSpecification": {"loadPositions": ["LHD1"]},
    }
    return out
