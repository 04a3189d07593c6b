"""What the master knows of one vehicle, and the VDA 5050 messages it sends it."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from agvsim.fleet.messages import Stamper
from agvsim.master.graph import RoadGraph
from agvsim.master.orders import Transport
from agvsim.master.traffic import Step, Stop, Visit
from agvsim.world.lif import Layout

ENDED = ("FINISHED", "FAILED")


@dataclass
class Agv:
    """What the master knows of one vehicle."""

    serial: str
    manufacturer: str
    version: str
    stamp: Stamper
    vehicle_type: str | None = None
    speed_m_s: float = 1.0
    home: str | None = None
    map_id: str = "map"
    state: dict | None = None
    ready: bool = False  # its home, type and a state are known: the master may plan for it
    broken: bool = False
    # the route: steps, their visits (None once released), what is granted and sent
    route: list[Step] = field(default_factory=list)
    visits: list[Visit | None] = field(default_factory=list)
    granted: int = 0
    sent: int = -1  # index of the last node sent as released (-1: nothing sent)
    reached: int = 0
    order_id: str = ""
    update_id: int = 0
    order_done: bool = True
    changed: bool = False  # the horizon changed since the last message
    actions: dict[int, list[dict]] = field(default_factory=dict)  # route index -> actions
    stops: list[tuple[Stop, int]] = field(default_factory=list)  # stop, route index
    job: str = "idle"  # idle | transport | home | charge | charging
    transport: Transport | None = None
    charger: str | None = None
    stop_charging_sent: bool = False
    orders_sent: int = 0
    progress: tuple = ()  # what changes while the vehicle gets on with its order
    progress_s: float = 0.0  # when it last changed
    stalled: bool = False
    replan: bool = False  # its route crosses a broken vehicle: re-plan as soon as one fits
    retimed_s: float = -1e9  # when it was last re-planned for being late
    # (the state, Master._progress_key) when the master last read its progress
    progress_seen: tuple[dict | None, tuple] | None = None
    # (decision node, held since, the node's table version, from when) when others had it
    blocked_at: tuple[str, float, int, float] | None = None
    # when route nodes were granted (by route index), when it was seen at node ``reached``
    grant_t: dict[int, float] = field(default_factory=dict)
    reached_s: float | None = None
    turn_radius_m: float = 0.0  # car-like: its minimum turning radius (0: turns on the spot)
    road: RoadGraph | None = None  # its routing graph (Master.graph), once known
    _battery_of: dict | None = field(default=None, repr=False, compare=False)
    _battery_now: tuple[float, bool] = field(default=(100.0, False), repr=False, compare=False)
    _ended_of: list | None = field(default=None, repr=False, compare=False)
    _ended_n: int = field(default=0, repr=False, compare=False)

    @property
    def battery_pct(self) -> float:
        return self._battery()[0]

    @property
    def charging(self) -> bool:
        return self._battery()[1]

    def _battery(self) -> tuple[float, bool]:
        """(charge %, charging) from the last state, read once per state message."""
        st = self.state or {}
        if self._battery_of is not st:
            bs = st.get("batteryState") or st.get("powerSupply") or {}
            pct = float(bs.get("batteryCharge", bs.get("stateOfCharge", 100.0)))
            self._battery_now = (pct, bool(bs.get("charging", False)))
            self._battery_of = st
        return self._battery_now

    def ended(self) -> int:
        """How many of the last state's actions are FINISHED or FAILED (counted once per
        list of action states: a periodic state shares its predecessor's)."""
        acts = (self.state or {}).get("actionStates", [])
        if self._ended_of is not acts:
            self._ended_n = sum(x.get("actionStatus") in ENDED for x in acts)
            self._ended_of = acts
        return self._ended_n

    @property
    def heading_rad(self) -> float | None:
        """Its reported heading (None before its first state with a position)."""
        pos = (self.state or {}).get("agvPosition") or (self.state or {}).get("mobileRobotPosition")
        return float(pos["theta"]) if pos and "theta" in pos else None

    @property
    def decision_node(self) -> str:
        return self.route[self.granted].node


def action(aid: str, kind: str, blocking: str = "HARD", **params: str) -> dict:
    a: dict[str, Any] = {"actionId": aid, "actionType": kind, "blockingType": blocking}
    if params:
        a["actionParameters"] = [{"key": k, "value": v} for k, v in params.items()]
    return a


def order_message(
    agv: Agv, layout: Layout, g: RoadGraph, t_s: float, horizon_nodes: int | None = None
) -> dict:
    """The order (or order update) that sends what is new: from the node the vehicle last
    got as released (its decision point), released up to what is granted (base), then the
    horizon: the rest of the route, or its next ``horizon_nodes`` nodes (each update moves it
    on with the base; the vehicle drives only the base, so a shorter horizon changes no motion,
    only the size of every order and state message)."""
    first = 0 if agv.sent < 0 else agv.sent
    end = len(agv.route)
    if horizon_nodes is not None:
        end = min(end, agv.granted + 1 + horizon_nodes)
    nodes, edges = [], []
    for i in range(first, end):
        n = agv.route[i].node
        x, y = layout.node_xy(n)
        nodes.append(
            {
                "nodeId": n,
                "sequenceId": 2 * i,
                "released": i <= agv.granted,
                "nodePosition": {"x": x, "y": y, "mapId": agv.map_id},
                "actions": agv.actions.get(i, []),
            }
        )
        if i > first:
            prev = agv.route[i - 1].node
            edges.append(
                {
                    "edgeId": g.arc(prev, n).edge_id,
                    "sequenceId": 2 * i - 1,
                    "released": i <= agv.granted,
                    "startNodeId": prev,
                    "endNodeId": n,
                    "actions": [],
                }
            )
    if agv.sent >= 0:
        agv.update_id += 1
    return agv.stamp.header("order", t_s) | {
        "orderId": agv.order_id,
        "orderUpdateId": agv.update_id,
        "nodes": nodes,
        "edges": edges,
    }
