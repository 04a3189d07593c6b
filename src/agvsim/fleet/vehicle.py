"""A VDA 5050 vehicle: the protocol state machine on top of one simulated robot.

The vehicle knows nothing of MQTT. A master (or the MQTT transport) hands it messages with
``receive(topic, payload)``; each simulation step ``control(t_s, pose, ranges)`` handles them,
runs actions, drives, checks the protective field and returns the body twist to command; the
messages it wants published wait in ``outbox`` as ``(topic, message, retained)``. The same
object so serves an in-process master (no broker) and the MQTT fleet.

Order handling follows VDA 5050 6.6: base and horizon, sequence ids, updates stitched at the
decision point, rejections as errors in ``state.errors`` (kept until a new order is accepted).
Nodes count as traversed when the path progress passes them; the node where the vehicle must
stop (end of the base, or SOFT/HARD actions) must be reached within its allowedDeviationXY
and, for models that can turn there, allowedDeviationTheta.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np

from agvsim.control.mobility import Mobility, wrap
from agvsim.fleet import messages, safety
from agvsim.fleet.actions import ACTION_TYPES, ENDED, drive_blocked, schedule, supported_scopes
from agvsim.fleet.bank import VehicleBank
from agvsim.fleet.battery import Battery
from agvsim.fleet.dialect import V2, Dialect, Problem
from agvsim.fleet.intake import decode
from agvsim.fleet.motion import Leg
from agvsim.fleet.order import Action, Limits, OrderEdge, OrderNode, OrderRefused, parse_order
from agvsim.sensors.safety_fields import PROTECTIVE, PackedFields, field_status
from agvsim.sim.spec import RobotSpec
from agvsim.world.lif import Layout

MAX_ERRORS = 20
MIN_TOLERANCE_M = 0.05  # a stop node is reached within max(this, allowedDeviationXY)
MIN_TOLERANCE_RAD = 0.02
MAX_INSTANT_STATES = 50
# a vehicle's own values in a VehicleBank row (copied by ``Vehicle.bind``)
ROW = (
    "t_s pose twist dist_node_m pct_per_j energy_j next_control_s period_s next_wake_s quiet "
    "mail driving "
    "look_m tol_m next_node_s holonomic can_spin kmax min_r_m use_field front_m reaction_s "
    "decel_m_s2 margin_m half_width_m mount_m"
).split()


def _weight(value: Any, default_kg: float) -> float:
    """A pick action's ``weight`` parameter (kg) when it is a number >= 0, else the default."""
    try:
        w = float(value)
    except (TypeError, ValueError):
        return default_kg
    return w if math.isfinite(w) and 0 <= w <= 1e5 else default_kg


def _reach(node: OrderNode) -> float:
    """How close to a stop node counts as there (m)."""
    return max(MIN_TOLERANCE_M, node.dev_xy_m)


@dataclass(frozen=True)
class VehicleConfig:
    serial: str
    manufacturer: str = "agvsim"
    vehicle_type: str = "agvsim"  # the LIF vehicleTypeId (also the factsheet's seriesName)
    dialect: Dialect = V2
    map_id: str = "map"
    max_speed_m_s: float = 1.0
    lookahead_m: float = 0.6
    control_period_s: float = 0.1  # the vehicle controller's tick (commands held between)
    state_period_s: float = 1.0  # a state at least this often, besides events
    vis_period_s: float = 1.0
    start_tolerance_m: float = 0.5  # an order's first node is reachable within this
    reaction_s: float = 0.2  # protective field: reaction time,
    decel_m_s2: float = 1.0  # braking deceleration,
    field_margin_m: float = 0.15  # length margin
    field_side_margin_m: float = 0.05  # and width margin beside the body
    limits: Limits = field(default_factory=Limits)
    load_kg: float = 50.0  # a picked load's mass when its pick action gives no 'weight'
    action_durations: dict[str, float] = field(default_factory=dict)


@dataclass
class Lidar:
    """The safety scanner: beam directions (B, 2) in the robot frame and its mount (m)."""

    dirs: np.ndarray
    mount_xy: tuple[float, float]
    range_max_m: float


class Vehicle:
    def __init__(
        self,
        cfg: VehicleConfig,
        spec: RobotSpec,
        layout: Layout | None = None,
        lidar: Lidar | None = None,
        start_node: str | None = None,
        epoch: datetime | None = None,
        battery: Battery | None = None,
    ):
        self.cfg, self.spec, self.layout, self.lidar = cfg, spec, layout, lidar
        self.dialect = cfg.dialect
        self.v3 = cfg.dialect.version.startswith("3")
        self.mob = Mobility.of(spec.model)
        self.stamp = messages.Stamper(cfg.dialect, cfg.manufacturer, cfg.serial)
        if epoch is not None:
            self.stamp.epoch = epoch
        self.supported = supported_scopes()
        # as fast as the configuration allows and the wheels can turn (factsheet speedMax)
        self.max_speed_m_s = min(cfg.max_speed_m_s, messages.top_speed_m_s(spec.model))
        self.battery = battery or Battery()
        hl, hw = spec.footprint_half_m
        self._front_m = spec.body_offset_x_m + hl
        self._half_width_m = hw + cfg.field_side_margin_m
        self._mount_m = 0.0 if lidar is None else math.hypot(*lidar.mount_xy)
        # with the robot's own safety scanner (its ``safety:`` block, read on ``lidar``) the
        # protective field is the scanner's; without, a field along the path (fleet.safety)
        self._fields = (
            None if spec.safety is None or lidar is None else PackedFields.of([spec.safety])
        )
        # the hot values live in a bank row: this vehicle's own until a fleet binds it
        self._b, self._k = VehicleBank(1, points=8), 0
        self.battery.bind(
            self._b.charge_pct[0:1], self._b.idle_pct_s[0:1], self._b.drive_pct_m[0:1]
        )
        self._init_row()
        self.inbox: deque[tuple[str, Any]] = deque()
        self.outbox: list[tuple[str, dict, bool]] = []
        # protocol state
        self.order_id, self.update_id, self.cancelled = "", 0, False
        self.route_nodes: list[OrderNode] = []  # not yet traversed (nodeStates)
        self.route_edges: list[OrderEdge] = []  # not yet left (edgeStates)
        # node/edge state entries per route list (``node_states``)
        self._last_state: dict | None = None  # the last state published
        self._ns_src: list[OrderNode] | None = None
        self._ns_json: list[dict] = []
        self._ns_released = 0
        self._es_src: list[OrderEdge] | None = None
        self._es_json: list[dict] = []
        self.last_node: OrderNode | None = None
        self.order_actions: dict[str, Action] = {}
        self.instant_actions: list[Action] = []
        self.here: list[Action] = []  # actions of the node the vehicle stands on
        self.on_edge = False
        self.leg: Leg | None = None
        self.errors: list[tuple[str, dict]] = []  # (scope: order|instant|run, error json)
        self.loads: list[dict] = []
        self.paused = self.driving = self.field_violation = False
        self.broken = False  # a scheduled breakdown (``break_down``): stopped for good
        self.twist = (0.0, 0.0, 0.0)
        self.pose = np.array(spec.initial_pose, dtype=np.float64)
        self.t_s = 0.0
        self.distance_since_node_m = 0.0
        self._dirty, self._next_state_s, self._next_vis_s = True, 0.0, 0.0
        self._next_control_s = 0.0
        self._want_factsheet = True
        self._loads_made = 0
        if start_node is not None:
            xy = self.layout.node_xy(start_node) if self.layout else tuple(self.pose[:2])
            self.last_node = OrderNode(start_node, 0, True, xy, None, 0.1, 0.1, cfg.map_id)

    # ------------------------------------------------------------------ the bank row
    def _init_row(self) -> None:
        b, k, c, m = self._b, self._k, self.cfg, self.mob
        b.period_s[k] = c.control_period_s
        b.pct_per_j[k] = self.battery.pct_per_j
        b.holonomic[k], b.can_spin[k] = m.holonomic, m.can_spin
        b.kmax[k], b.min_r_m[k] = m.max_curvature_1_m, m.min_radius_m
        b.use_field[k] = self.lidar is not None and self._fields is None
        b.front_m[k], b.reaction_s[k], b.decel_m_s2[k] = self._front_m, c.reaction_s, c.decel_m_s2
        b.margin_m[k], b.half_width_m[k] = c.field_margin_m, self._half_width_m
        b.mount_m[k] = self._mount_m

    def bind(self, bank: VehicleBank, k: int) -> None:
        """Move this vehicle's hot values into row ``k`` of ``bank`` (a fleet's shared one)."""
        old, j = self._b, self._k
        for name in ROW:
            getattr(bank, name)[k] = getattr(old, name)[j]
        self._b, self._k = bank, k
        self.battery.bind(
            bank.charge_pct[k : k + 1], bank.idle_pct_s[k : k + 1], bank.drive_pct_m[k : k + 1]
        )
        if self.leg is not None:
            self.leg.attach(bank, k)

    @property
    def t_s(self) -> float:
        """Time of the last control tick (s)."""
        return float(self._b.t_s[self._k])

    @t_s.setter
    def t_s(self, value: float) -> None:
        self._b.t_s[self._k] = value

    @property
    def pose(self) -> np.ndarray:
        """(3,) pose at the last control tick (a copy)."""
        return self._b.pose[self._k].copy()

    @pose.setter
    def pose(self, value: np.ndarray) -> None:
        self._b.pose[self._k] = value

    @property
    def twist(self) -> tuple[float, float, float]:
        """The body twist commanded (vx, vy m/s, omega rad/s), held between ticks."""
        vx, vy, w = self._b.twist[self._k].tolist()
        return vx, vy, w

    @twist.setter
    def twist(self, value: tuple[float, float, float]) -> None:
        self._b.twist[self._k] = value

    @property
    def distance_since_node_m(self) -> float:
        return float(self._b.dist_node_m[self._k])

    @distance_since_node_m.setter
    def distance_since_node_m(self, value: float) -> None:
        self._b.dist_node_m[self._k] = value

    @property
    def _next_control_s(self) -> float:
        return float(self._b.next_control_s[self._k])

    @_next_control_s.setter
    def _next_control_s(self, value: float) -> None:
        self._b.next_control_s[self._k] = value

    def _quiet(self) -> bool:
        """Whether a control tick would only follow the leg (or stand): nothing to handle,
        run, publish or check beyond what ``agvsim.fleet.bank.tick`` does."""
        if (
            self.inbox
            or self.paused
            or self.broken
            or self.battery.charging
            or self.field_violation
            or self._fields is not None
            or self._dirty
            or self._want_factsheet
            or self.errors
            and any(e[0] == "run" for e in self.errors)
            or any(a.status not in ENDED for a in self.here)
            or self._running()
        ):
            return False
        edges = self.route_edges
        if not edges or not edges[0].released or self.last_node is None:
            return True  # standing: nothing to drive
        return (
            self.leg is not None
            and self.on_edge
            and all(a.status in ENDED for a in edges[0].actions)
        )

    def _settle(self) -> None:
        """After Python handled the vehicle: tell the bank what the batch tick may do."""
        b, k, leg = self._b, self._k, self.leg
        if leg is None:
            b.has_leg[k] = False
        elif leg._bank is not b:
            leg.attach(b, k)
        nxt = math.inf
        if leg is not None and self.route_nodes:
            i = leg.index(self.route_nodes[0])
            if i is not None and i < len(leg.nodes) - 1:
                nxt = leg.node_s[i]
        b.next_node_s[k] = nxt
        b.next_wake_s[k] = self._wake_s()
        b.driving[k] = self.driving
        b.quiet[k] = self._quiet()

    def _wake_s(self) -> float:
        """When a periodic message is next due (the batch tick hands the vehicle back then)."""
        return min(self._next_state_s, self._next_vis_s if self.cfg.vis_period_s > 0 else math.inf)

    # ------------------------------------------------------------------ the public surface
    def receive(self, topic: str, payload: Any) -> None:
        """Queue a message (bytes, str or dict) for ``order`` or ``instantActions``; it is
        handled at the next ``control`` call. Safe to call from another thread."""
        self.inbox.append((topic, payload))
        self._b.mail[self._k] = True

    def control(self, t_s: float, pose: np.ndarray, ranges: np.ndarray | None) -> tuple:
        """One simulation step: handle messages, run actions, drive, publish. Returns the
        body twist (vx m/s, vy m/s, omega rad/s)."""
        if not self.inbox and t_s < self._next_control_s - 1e-9:
            return self.twist  # held between control ticks
        self._next_control_s = t_s + self.cfg.control_period_s
        dt = max(0.0, t_s - self.t_s)
        moved = math.hypot(float(pose[0]) - self.pose[0], float(pose[1]) - self.pose[1])
        self.t_s, self.pose = t_s, np.asarray(pose, dtype=np.float64)
        self.distance_since_node_m += moved
        while self.inbox:
            topic, payload = self.inbox.popleft()
            if topic == "order":
                self._on_order(payload)
            elif topic == "instantActions":
                self._on_instant(payload)
        self._advance(dt)
        self.battery.update(dt, moved, float(self._b.energy_j[self._k]))
        self._b.energy_j[self._k] = 0.0
        tw = self._drive()
        violation = False
        if self._fields is not None:  # a safety scanner (safety: block): the engine brakes
            violation = ranges is not None and self._scanner_violated(tw, ranges)
        elif tw != (0.0, 0.0, 0.0) and ranges is not None and self.lidar is not None:
            violation = self._field_violated(tw, ranges)
            if violation:
                tw = (0.0, 0.0, 0.0)
        if violation != self.field_violation:
            self.field_violation, self._dirty = violation, True
        driving = math.hypot(tw[0], tw[1]) > 1e-6 or abs(tw[2]) > 1e-6
        if driving != self.driving:
            self.driving, self._dirty = driving, True
        self.twist = tw
        self._publish_due()
        self._settle()
        return tw

    def publish_periodic(self) -> None:
        """The batch tick did this vehicle's control tick and its periodic state or
        visualization is due: publish it. The tick changed only what the bank holds (motion,
        charge, time) and a quiet vehicle has no event to publish, so of what ``_settle``
        tells the bank only the next wake-up time changes (tests/test_fleet_bank.py)."""
        self._publish_due()
        self._b.next_wake_s[self._k] = self._wake_s()

    def node_states(self) -> tuple[list[dict], int]:
        """``state.nodeStates`` and how many of those nodes are released. The route only
        loses nodes at its front (passed) or is replaced whole (an order or update), and
        released nodes come first: so the entries are built once per route (a new list) and
        each state takes the remaining tail."""
        nodes = self.route_nodes
        if self._ns_src is not nodes:
            self._ns_src = nodes
            self._ns_json = [n.state_json() for n in nodes]
            self._ns_released = sum(n.released for n in nodes)
        gone = len(self._ns_json) - len(nodes)
        return self._ns_json[gone:], max(0, self._ns_released - gone)

    def edge_states(self) -> list[dict]:
        """``state.edgeStates``, as ``node_states`` (edges leave the route at its front)."""
        edges = self.route_edges
        if self._es_src is not edges:
            self._es_src = edges
            self._es_json = [e.state_json() for e in edges]
        return self._es_json[len(self._es_json) - len(edges) :]

    def connection(self, state: str) -> dict:
        return messages.connection(self.stamp, self.t_s, state)

    def factsheet(self) -> dict:
        c = self.cfg
        return messages.factsheet(
            self.stamp,
            self.t_s,
            self.spec,
            c.vehicle_type,
            self.max_speed_m_s,
            c.limits,
            c.state_period_s,
            c.vis_period_s,
            self._durations(),
        )

    def state(self) -> dict:
        return messages.state(self)

    def visualization(self) -> dict:
        sid = self.stamp.counters.get("state", 0)
        return messages.visualization(
            self.stamp, self.t_s, self.pose, self.twist, self.cfg.map_id, sid
        )

    def publish_all(self) -> None:
        """Queue connection ONLINE, factsheet and state (on (re)connecting)."""
        self.outbox.append(("connection", self.connection("ONLINE"), True))
        self._want_factsheet = self._dirty = True
        self._publish_due()
        self._settle()

    @property
    def load_kg(self) -> float:
        """The mass of the loads on board (kg)."""
        return float(sum(ld.get("weight", 0.0) for ld in self.loads))

    @property
    def busy(self) -> bool:
        """Executing an order or waiting for its continuation (VDA 5050 6.6.2 step 3)."""
        return bool(self.route_nodes) or any(
            a.status not in ENDED for a in self.order_actions.values()
        )

    # ------------------------------------------------------------------ errors
    def _error(self, scope: str, kind: Problem, description: str, refs: dict) -> None:
        etype, level = self.dialect.error(kind)
        err: dict[str, Any] = {
            "errorType": etype,
            "errorLevel": level,
            "errorDescription": description[:500],
            "errorReferences": [
                {"referenceKey": k, "referenceValue": str(v)} for k, v in refs.items()
            ],
        }
        self.errors.append((scope, err))
        del self.errors[:-MAX_ERRORS]
        self._dirty = True

    def _clear_errors(self, scope: str) -> None:
        before = len(self.errors)
        self.errors = [e for e in self.errors if e[0] != scope]
        self._dirty |= len(self.errors) != before

    # ------------------------------------------------------------------ incoming
    def _decode(self, payload: Any, topic: str) -> dict | None:
        """The message as a dict, or None with a validation error recorded."""
        c = self.cfg
        try:
            return decode(
                payload,
                topic,
                self.dialect.version,
                c.limits.max_message_bytes,
                c.manufacturer,
                c.serial,
            )
        except OrderRefused as r:
            self._error("order" if topic == "order" else "instant", r.kind, r.description, r.refs)
            return None

    def _on_order(self, payload: Any) -> None:
        msg = self._decode(payload, "order")
        if msg is None:
            return
        oid = {"orderId": msg["orderId"], "orderUpdateId": str(msg["orderUpdateId"])}
        if not msg["orderId"]:  # "" is what the state reports while the vehicle has no order
            self._error(
                "order", Problem.VALIDATION, "orderId is empty: every order needs an id", oid
            )
            return
        try:
            nodes, edges = parse_order(
                msg, self.layout, self.supported, self.cfg.limits, self.cfg.vehicle_type
            )
            if msg["orderId"] != self.order_id:
                self._accept_new(msg, nodes, edges, oid)
            else:
                self._accept_update(msg, nodes, edges, oid)
        except OrderRefused as r:
            self._error("order", r.kind, r.description, r.refs)

    def _accept_new(self, msg: dict, nodes: list, edges: list, oid: dict) -> None:
        if self.busy:
            raise OrderRefused(
                Problem.OTHER_ORDER_ACTIVE,
                f"order {self.order_id!r} is still active; cancel it first (cancelOrder)",
                oid,
            )
        first = nodes[0]
        tol = max(first.dev_xy_m, self.cfg.start_tolerance_m)
        gap = math.hypot(first.xy[0] - self.pose[0], first.xy[1] - self.pose[1])
        if gap > tol:
            raise OrderRefused(
                Problem.START_OUT_OF_RANGE,
                f"the first node {first.node_id!r} is {gap:.2f} m away (allowed {tol:.2f} m)",
                oid | {"nodeId": first.node_id},
            )
        self.order_id, self.update_id, self.cancelled = msg["orderId"], msg["orderUpdateId"], False
        self.order_actions = {a.action_id: a for x in [*nodes, *edges] for a in x.actions}
        self.instant_actions = [a for a in self.instant_actions if a.status not in ENDED]
        self.route_nodes, self.route_edges = nodes[1:], list(edges)
        self.leg, self.on_edge = None, False
        self._clear_errors("order")
        self._traverse(first)

    def _accept_update(self, msg: dict, nodes: list, edges: list, oid: dict) -> None:
        uid = msg["orderUpdateId"]
        if self.cancelled:
            raise OrderRefused(
                Problem.UPDATE_AFTER_CANCEL,
                f"order {self.order_id!r} was cancelled; send a new orderId",
                oid,
            )
        if uid < self.update_id:
            raise OrderRefused(
                Problem.OUTDATED_UPDATE,
                f"orderUpdateId {uid} is older than the current {self.update_id}",
                oid,
            )
        if uid == self.update_id:
            return  # a resend of the order the vehicle holds: ignored (6.6.4.3)
        released = [n for n in self.route_nodes if n.released]
        point = released[-1] if released else self.last_node
        first = nodes[0]
        if point is None or (first.node_id, first.seq) != (point.node_id, point.seq):
            at = "none" if point is None else f"{point.node_id!r} (sequenceId {point.seq})"
            raise OrderRefused(
                Problem.BAD_STITCH,
                f"the update starts at {first.node_id!r} "
                f"(sequenceId {first.seq}); it must start at the decision "
                f"point {at}",
                oid | {"nodeId": first.node_id},
            )
        keep = [n for n in self.route_nodes if n.released]
        self.route_edges = [e for e in self.route_edges if e.released] + list(edges)
        self.route_nodes = keep + nodes[1:]
        for x in [*nodes[1:], *edges]:
            for a in x.actions:
                self.order_actions[a.action_id] = a
        self.update_id = uid
        self._clear_errors("order")
        self._dirty = True
        if self.leg is not None:  # driving towards the old decision point: drive on
            targets, t_edges = self._leg_targets()
            k = next((j for j, n in enumerate(targets) if n is self.leg.nodes[-1]), None)
            if k is not None and len(t_edges) > k:
                self.leg.extend(
                    targets[k:], t_edges[k:], self._speeds(t_edges[k:]), _reach(targets[-1])
                )

    def _on_instant(self, payload: Any) -> None:
        msg = self._decode(payload, "instantActions")
        if msg is None:
            return
        if len(msg["actions"]) > self.cfg.limits.max_instant_actions:
            self._error(
                "instant",
                Problem.TOO_LARGE,
                f"{len(msg['actions'])} instant actions; "
                f"at most {self.cfg.limits.max_instant_actions}",
                {},
            )
            return
        self._clear_errors("instant")
        for raw in msg["actions"]:
            a = Action.from_json(raw)
            self.instant_actions.append(a)
            del self.instant_actions[:-MAX_INSTANT_STATES]
            if "INSTANT" not in ACTION_TYPES.get(a.action_type, ACTION_TYPES["pick"]).scopes:
                a.status = "FAILED"
                self._error(
                    "instant",
                    Problem.INVALID_INSTANT_ACTION,
                    f"{a.action_type!r} is not an instant action of this vehicle",
                    {"actionId": a.action_id, "actionType": a.action_type},
                )
                continue
            self._start(a)
        self._dirty = True

    # ------------------------------------------------------------------ actions
    def _durations(self) -> dict[str, float]:
        return {k: self.cfg.action_durations.get(k, t.duration_s) for k, t in ACTION_TYPES.items()}

    def _fail(self, a: Action, why: str) -> None:
        a.status, a.result = "FAILED", why[:200]
        self._error(
            "order" if a.action_id in self.order_actions else "instant",
            Problem.ACTION_FAILED,
            f"{a.action_type} {a.action_id}: {why}",
            {"actionId": a.action_id},
        )

    def _start(self, a: Action) -> None:
        """WAITING -> RUNNING (or straight to FINISHED / FAILED)."""
        self._dirty = True
        kind = a.action_type
        lhd = str(a.params.get("lhd", "LHD1"))
        if kind == "startPause":
            self.paused, a.status = True, "FINISHED"
        elif kind == "stopPause":
            self.paused, a.status = False, "FINISHED"
        elif kind == "cancelOrder":
            self._cancel(a)
        elif kind == "stateRequest":
            a.status = "FINISHED"
        elif kind == "factsheetRequest":
            self._want_factsheet, a.status = True, "FINISHED"
        elif kind == "initPosition":
            self._init_position(a)
        elif kind == "startCharging" and not self._on_charger():
            self._fail(
                a,
                "not standing on a charging node (a layout node whose properties "
                "offer startCharging)",
            )
        elif kind == "pick" and any(ld.get("loadPosition") == lhd for ld in self.loads):
            self._fail(a, f"the load handling device {lhd} already holds a load")
        elif kind == "drop" and not any(ld.get("loadPosition") == lhd for ld in self.loads):
            self._fail(a, f"no load on {lhd} to drop")
        else:
            a.remaining_s = self._durations().get(kind, 0.0)
            a.status = "RUNNING"
            if a.remaining_s <= 0:
                self._finish(a)

    def _finish(self, a: Action) -> None:
        kind, lhd = a.action_type, str(a.params.get("lhd", "LHD1"))
        if kind == "pick":
            self._loads_made += 1
            load: dict[str, Any] = {
                "loadId": str(a.params.get("loadId", f"{self.cfg.serial}-{self._loads_made}")),
                "loadPosition": lhd,
            }
            if "loadType" in a.params:
                load["loadType"] = str(a.params["loadType"])
            load["weight"] = _weight(a.params.get("weight"), self.cfg.load_kg)
            self.loads.append(load)
        elif kind == "drop":
            self.loads = [ld for ld in self.loads if ld.get("loadPosition") != lhd]
        elif kind == "startCharging":
            self.battery.charging = True
        elif kind == "stopCharging":
            self.battery.charging = False
        a.status, self._dirty = "FINISHED", True

    def _advance(self, dt: float) -> None:
        for a in self._running():
            if self.paused:
                if a.status == "RUNNING":
                    a.status, self._dirty = "PAUSED", True
                continue
            if a.status == "PAUSED":
                a.status, self._dirty = "RUNNING", True
            a.remaining_s -= dt
            if a.remaining_s <= 1e-9:
                self._finish(a)

    def _running(self) -> list[Action]:
        acts = [*self.order_actions.values(), *self.instant_actions]
        return [a for a in acts if a.status in ("RUNNING", "PAUSED")]

    def _cancel(self, a: Action) -> None:
        if not self.busy or self.cancelled:
            a.status = "FAILED"
            self._error(
                "order", Problem.NO_ORDER_TO_CANCEL, "no order to cancel", {"actionId": a.action_id}
            )
            return
        for b in self.order_actions.values():
            if b.status not in ENDED:
                b.status, b.result = "FAILED", "order cancelled"
        self.route_nodes, self.route_edges, self.here = [], [], []
        self.leg, self.on_edge, self.cancelled = None, False, True
        a.status = "FINISHED"  # the vehicle stops within this step

    def _init_position(self, a: Action) -> None:
        p = a.params
        try:
            x, y = float(p["x"]), float(p["y"])
        except (KeyError, TypeError, ValueError):
            self._fail(a, "initPosition needs numbers x and y")
            return
        if math.hypot(x - self.pose[0], y - self.pose[1]) > self.cfg.start_tolerance_m:
            self._fail(
                a,
                f"({x:g}, {y:g}) is not where the vehicle stands "
                f"({self.pose[0]:.2f}, {self.pose[1]:.2f})",
            )
            return
        nid = str(p.get("lastNodeId", ""))
        self.last_node = OrderNode(nid, 0, True, (x, y), None, 0.1, 0.1, self.cfg.map_id)
        a.status = "FINISHED"

    def _on_charger(self) -> bool:
        n = self.last_node
        if n is None or self.layout is None or n.node_id not in self.layout.nodes:
            return False
        if math.hypot(n.xy[0] - self.pose[0], n.xy[1] - self.pose[1]) > 0.3:
            return False
        props = self.layout.nodes[n.node_id].types.get(self.cfg.vehicle_type)
        return props is not None and any(
            a.get("actionType") == "startCharging" for a in props.actions
        )

    # ------------------------------------------------------------------ driving
    def _traverse(self, node: OrderNode) -> None:
        """The vehicle has reached ``node``: report it, leave the edge, trigger its actions."""
        if self.route_edges and self.route_edges[0].end == node.node_id and self.on_edge:
            for a in self.route_edges[0].actions:
                if a.status not in ENDED:
                    a.status = "FINISHED"
            self.route_edges.pop(0)
        if self.route_nodes and self.route_nodes[0] is node:
            self.route_nodes.pop(0)
        self.last_node, self.on_edge = node, False
        self.distance_since_node_m = 0.0
        self.here = list(node.actions)
        schedule(self.here, self._start)
        self._dirty = True

    def _speeds(self, edges: list[OrderEdge]) -> list[float]:
        v = self.max_speed_m_s
        return [v if e.max_speed_m_s is None else min(v, e.max_speed_m_s) for e in edges]

    def _leg_targets(self) -> tuple[list[OrderNode], list[OrderEdge]]:
        """From the last node to the next node the vehicle must stop at."""
        assert self.last_node is not None
        nodes, edges = [self.last_node], []
        for n, e in zip(self.route_nodes, self.route_edges, strict=False):
            if not (n.released and e.released):
                break
            nodes.append(n)
            edges.append(e)
            if any(a.blocking != "NONE" for a in n.actions):
                break
        return nodes, edges

    def _drive(self) -> tuple[float, float, float]:
        stop = (0.0, 0.0, 0.0)
        schedule(self.here, self._start)
        if self.paused or self.broken or self.battery.charging or drive_blocked(self.here):
            return stop
        if self.battery.empty:
            if not any(e[0] == "run" for e in self.errors):
                self._error("run", Problem.BATTERY_EMPTY, "the battery is empty", {})
            return stop
        if any(e[0] == "run" for e in self.errors):
            self._clear_errors("run")  # charged again
        if not self.route_edges or not self.route_edges[0].released or self.last_node is None:
            return stop
        edge = self.route_edges[0]
        if not self.on_edge:
            self.on_edge, self._dirty = True, True
        schedule(edge.actions, self._start)
        if drive_blocked(edge.actions):
            return stop
        if self.leg is None:
            nodes, edges = self._leg_targets()
            self.leg = Leg(
                nodes, edges, self._speeds(edges), self.cfg.lookahead_m, _reach(nodes[-1])
            )
            self.leg.attach(self._b, self._k)
        leg = self.leg
        tw = leg.twist(self.pose, self.mob)
        # pass the nodes the progress has reached
        while self.route_nodes:
            n = self.route_nodes[0]
            k = leg.index(n)
            if k is None:
                break
            if k < len(leg.nodes) - 1:
                if leg.s < leg.node_s[k] - 1e-6:
                    break
                self._traverse(n)
                continue
            if not leg.reached:
                break
            if n.theta is not None and (self.mob.can_spin or self.mob.holonomic):
                err = wrap(n.theta - float(self.pose[2]))
                if abs(err) > max(MIN_TOLERANCE_RAD, n.dev_theta_rad):
                    return 0.0, 0.0, max(-1.0, min(1.0, 2.0 * err))
            self.leg = None
            self._traverse(n)
            return stop
        return tw

    def _scanner_violated(self, tw: tuple, ranges: np.ndarray) -> bool:
        """The robot's safety scanner sees a return in the protective field of the set active
        for the faster of the commanded and the last speed (as the engine's safety stage)."""
        sc, pk, lidar = self.spec.safety, self._fields, self.lidar
        assert sc is not None and pk is not None and lidar is not None
        v = tw[0] if abs(tw[0]) > abs(self.twist[0]) else self.twist[0]
        wheelbase = float(np.asarray(getattr(self.spec.model, "wheelbase_m", 0.0)).flat[0])
        steer = math.atan2(wheelbase * tw[2], v) if wheelbase > 0 and abs(v) > 1e-9 else 0.0
        k = sc.select(v, steer)
        r = np.asarray(ranges, dtype=np.float64)
        valid = ~np.isnan(r) & ~np.isposinf(r)
        rr = np.where(valid, np.maximum(r, 0.0), 0.0)[:, None]
        pts = np.asarray(lidar.mount_xy, dtype=np.float64) + rr * lidar.dirs
        status = field_status(
            pts[None],
            valid[None],
            np.array([k], dtype=np.int64),
            pk.verts,
            pk.start,
            pk.count,
            pk.prot,
            pk.warn,
        )
        return bool(status[0] == PROTECTIVE)

    def _field_violated(self, tw: tuple, ranges: np.ndarray) -> bool:
        assert self.lidar is not None and self.leg is not None
        speed = max(math.hypot(tw[0], tw[1]), math.hypot(self.twist[0], self.twist[1]))
        length = safety.field_length_m(
            speed, self._front_m, self.cfg.reaction_s, self.cfg.decel_m_s2, self.cfg.field_margin_m
        )
        # a return farther than the field's reach (plus the mount offset and a margin for
        # the distance from the path) cannot be in it: most ticks end here
        reach = length + self._half_width_m + self._mount_m + 0.5
        if float(ranges.min()) > reach:
            return False
        pts = safety.scan_points(self.pose, self.lidar.mount_xy, self.lidar.dirs, ranges, reach)
        if len(pts) == 0:
            return False
        path = self.leg.ahead(length)
        if math.hypot(tw[0], tw[1]) < 1e-6 or len(path) < 2:
            # turning on the spot: the circle the body sweeps (around the reference point)
            r = self.spec.bounding_radius_m + self.cfg.field_side_margin_m
            return bool((np.hypot(*(pts - self.pose[:2]).T) < r).any())
        return safety.violated(pts[:, :2], path[1:], self._half_width_m)

    # ------------------------------------------------------------------ outgoing
    def _publish_due(self) -> None:
        t = self.t_s
        if self._want_factsheet:
            self.outbox.append(("factsheet", self.factsheet(), True))
            self._want_factsheet = False
        if self._dirty or t >= self._next_state_s - 1e-9:
            # every change the protocol sees sets _dirty: without one, only motion and
            # charge differ from the last state published
            last = self._last_state
            msg = (
                self.state() if self._dirty or last is None else messages.periodic_state(self, last)
            )
            self._last_state = msg
            self.outbox.append(("state", msg, False))
            self._dirty = False
            self._next_state_s = t + self.cfg.state_period_s
        if self.cfg.vis_period_s > 0 and t >= self._next_vis_s - 1e-9:
            self.outbox.append(("visualization", self.visualization(), False))
            self._next_vis_s = t + self.cfg.vis_period_s

    def fault(self, exc: BaseException) -> None:
        """A failure inside the vehicle's own code: it stops, reports it, and stays up."""
        if not any(e[0] == "fault" for e in self.errors):
            self._error("fault", Problem.INTERNAL, f"{type(exc).__name__}: {exc}", {})
        self.twist, self.driving, self.leg = (0.0, 0.0, 0.0), False, None
        self._publish_due()
        self._settle()

    def break_down(self, description: str = "breakdown") -> None:
        """A failure the scenario schedules: the vehicle stops for good and reports a FATAL
        error (internalError / INTERNAL_ERROR) in its state."""
        self.broken = True
        self._error("fault", Problem.INTERNAL, description, {})
        self._publish_due()
        self._settle()

    def drain(self) -> list[tuple[str, dict, bool]]:
        out, self.outbox = self.outbox, []
        return out
