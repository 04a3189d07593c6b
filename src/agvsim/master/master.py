"""The master control's logic: no I/O, no clock of its own.

It learns the vehicles from what they publish (``factsheet``: vehicle type and top speed;
``state``: where they stand, battery, errors, actions) and answers with ``order`` and
``instantActions`` messages, as dicts in the vehicle's VDA 5050 version. ``receive(serial,
topic, message)`` takes what a vehicle published; ``tick(t_s)`` decides and returns the
messages to send as ``(serial, topic, message)``. The in-process runner and the MQTT client
(``agvsim.master.run``, ``agvsim.master.mqtt``) feed the same object, so both paths share
every decision.

Each vehicle has one route at a time: node visits planned by SIPP in the reservation table
(``agvsim.master.traffic``), sent as a base (the visits granted so far) plus a horizon (the
rest, ``released: false``) and extended by order updates as the next visits are granted.
A transport is one route: pick-up, drop-off, then back to the vehicle's home node (where it
started). A vehicle on its way home can take the next transport: the route is re-planned
from its decision point (the end of its base) and sent as an order update.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime

import numpy as np

from agvsim.fleet.dialect import DIALECTS
from agvsim.fleet.messages import Stamper
from agvsim.master.agv import ENDED, Agv, action, order_message
from agvsim.master.config import MasterConfig
from agvsim.master.dispatch import POLICIES
from agvsim.master.graph import RoadGraph
from agvsim.master.metrics import Metrics
from agvsim.master.orders import Transport
from agvsim.master.pace import GRANT_LEAD_S, Pace
from agvsim.master.traffic import (
    INF,
    NoRoute,
    Reservations,
    StartTaken,
    Step,
    Stop,
    Visit,
    plan_route,
)
from agvsim.world.lif import Layout

Message = tuple[str, str, dict]  # serial, topic, message
PLANNED_DWELL_S = 3.0  # what a pick or a drop is planned to take (an estimate: order only)


def wait_cycles(waits: dict[str, str]) -> list[frozenset[str]]:
    """The cycles of a wait-for graph in which each vehicle waits for at most one other."""
    found: list[frozenset[str]] = []
    for s in sorted(waits):
        seen, cur = [s], waits.get(s)
        while cur is not None and cur not in seen:
            seen.append(cur)
            cur = waits.get(cur)
        if cur is not None:
            cycle = frozenset(seen[seen.index(cur) :])
            if cycle not in found:
                found.append(cycle)
    return found


def _same_events(old: dict | None, new: dict | None) -> bool:
    """``new`` tells the master's progress nothing that ``old`` did not: the same message,
    or one whose event fields (what ``Master._progress_once`` reads) are the same objects, as
    in a vehicle's periodic state (``agvsim.fleet.messages.periodic_state``). A state
    received over MQTT is decoded afresh: it compares unequal here and is read whole."""
    if old is new:
        return True
    if old is None or new is None:
        return False
    get, was = new.get, old.get  # written out: this runs for every vehicle at every tick
    return (
        was("actionStates") is get("actionStates")
        and was("lastNodeSequenceId") is get("lastNodeSequenceId")
        and was("lastNodeId") is get("lastNodeId")
        and was("nodeStates") is get("nodeStates")
        and was("orderId") is get("orderId")
        and was("errors") is get("errors")
    )


class Master:
    def __init__(
        self,
        layout: Layout,
        cfg: MasterConfig,
        transports: list[Transport] | None = None,
        epoch: datetime | None = None,
        turn_radius_m: dict[str, float] | None = None,
    ):
        """``turn_radius_m``: the minimum turning radius of each car-like vehicle by serial
        (a vehicle not named turns on the spot); the VDA 5050 factsheet has no field for it,
        so the runners read it from the vehicles' kinematic models."""
        self.layout, self.cfg = layout, cfg
        self.turn_radius_m = dict(turn_radius_m or {})
        self.epoch = epoch or datetime(2026, 1, 1, tzinfo=UTC)
        self.table = Reservations(cfg.margin_s)
        self.policy = POLICIES[cfg.dispatch]
        self.agvs: dict[str, Agv] = {}
        self._graphs: dict[tuple[str | None, float, float], RoadGraph] = {}
        self.upcoming = sorted(transports or [], key=lambda x: (x.created_s, x.transport_id))
        self.pending: list[Transport] = []
        self.transports: list[Transport] = list(self.upcoming)
        self.metrics = Metrics()
        self.t_s = 0.0
        self.plan_times_s: list[float] = []
        self.replan_failures = 0
        self._deadlocks_seen: set[frozenset[str]] = set()
        self._homes: frozenset[str] = frozenset()  # parking places: no route passes them
        # vehicles that reported, or that the master changed, since the last tick: only their
        # utilisation is looked at again (metrics are O(changes) a tick)
        self._touched: set[str] = set()
        self._chargers: dict[str | None, list[str]] = {}  # by vehicle type
        self.pace: dict[RoadGraph, Pace] = {}  # learnt, by routing graph (agvsim.master.pace)

    # ------------------------------------------------------------------ input
    def receive(self, serial: str, topic: str, msg: dict) -> None:
        agv = self.agvs.get(serial)
        if agv is None:
            if topic not in ("state", "factsheet"):
                return
            version = str(msg.get("version", "2.1.0"))
            dialect = DIALECTS.get(version) or DIALECTS["2.1.0"]
            agv = Agv(
                serial,
                str(msg.get("manufacturer", "")),
                dialect.version,
                Stamper(dialect, str(msg.get("manufacturer", "")), serial, self.epoch),
                turn_radius_m=self.turn_radius_m.get(serial, 0.0),
            )
            self.agvs = dict(sorted({**self.agvs, serial: agv}.items()))
        if topic == "factsheet":
            ts = msg.get("typeSpecification", {})
            agv.vehicle_type = ts.get("seriesName")
            agv.speed_m_s = float(msg.get("physicalParameters", {}).get("speedMax", 1.0))
            agv.road = None  # its routing graph, for that type and speed
            self.graph(agv)  # built now (with its tables to the goals), not in a tick
        elif topic == "state":
            agv.state = msg
            self._touched.add(serial)
            self.metrics.battery(serial, agv.battery_pct)
            pos = msg.get("agvPosition") or msg.get("mobileRobotPosition") or {}
            agv.map_id = str(pos.get("mapId", agv.map_id))
            node = msg.get("lastNodeId", "")
            if agv.home is None and node in self.layout.nodes:
                agv.home = node
                self._homes = self._homes | {node}
                for g in self._graphs.values():
                    g.prepare([node])
                agv.route = [Step(node, self.t_s, INF)]
                v = Visit(serial, node, 0, self.t_s, INF, granted=True)
                agv.visits = [v]
                self.table.add(v)
        agv.ready = agv.home is not None and agv.vehicle_type is not None and agv.state is not None

    # ------------------------------------------------------------------ helpers
    def graph(self, agv: Agv) -> RoadGraph:
        if agv.road is not None:
            return agv.road
        key = (agv.vehicle_type, agv.speed_m_s, agv.turn_radius_m)
        if key not in self._graphs:
            types = self.layout.vehicle_types
            vt = agv.vehicle_type if agv.vehicle_type in types else None
            g = self._graphs[key] = RoadGraph(self.layout, vt, agv.speed_m_s, agv.turn_radius_m)
            # the goals of every route: stations, chargers and homes (one batch now)
            stations = [n for st in self.layout.stations.values() for n in st.interaction_node_ids]
            g.prepare([*stations, *self.chargers(agv), *sorted(self._homes)])
        agv.road = self._graphs[key]
        return agv.road

    def static_time(self, agv: Agv, a: str, b: str) -> float:
        return self.graph(agv).times_to(b).get(a, INF)

    def chargers(self, agv: Agv) -> list[str]:
        """The nodes where ``agv`` can charge (a node offering ``startCharging``)."""
        got = self._chargers.get(agv.vehicle_type)
        if got is not None:
            return got
        out = []
        for nid, n in sorted(self.layout.nodes.items()):
            props = n.types.get(agv.vehicle_type or "") or next(iter(n.types.values()), None)
            if props and any(a.get("actionType") == "startCharging" for a in props.actions):
                out.append(nid)
        self._chargers[agv.vehicle_type] = out
        return out

    # ------------------------------------------------------------------ routes
    def assign(self, agv: Agv, stops: list[tuple[Stop, list[dict]]], t_s: float) -> bool:
        """Plan a new route through ``stops`` from the vehicle's decision point: a new order
        when it has none running, else an update of the running one. False: no route now."""
        fresh = agv.order_done
        g = 0 if fresh else agv.granted
        start = agv.route[-1] if fresh else agv.route[g]
        old = [v for v in (agv.visits[-1:] if fresh else agv.visits[g:]) if v is not None]
        held = old[0].start_s if old else t_s
        t0 = max(t_s, start.arrive_s)
        # its decision point was taken by others when last tried, no visit of that node has
        # changed since, and it must hold it as long or longer: taken still
        blocked = (start.node, held, self.table.version(start.node))
        if agv.blocked_at is not None and agv.blocked_at[:3] == blocked:
            if t0 >= agv.blocked_at[3]:
                return False
        graph = self.graph(agv)
        # how the vehicle reaches its decision point: by the route's arc into it, or it
        # stands there facing its reported heading (what a car-like can turn to depends on it)
        arrived_by = graph.arc(agv.route[g - 1].node, start.node) if g > 0 else None
        w0 = time.perf_counter()
        try:  # (the search leaves the vehicle's own visits out: its old ones stay till it fits)
            steps = plan_route(
                graph,
                self.table,
                agv.serial,
                start.node,
                t0,
                [s for s, _ in stops],
                held_since_s=held,
                stop_at_start=fresh,
                avoid=self._homes,
                arrived_by=arrived_by,
                heading_rad=agv.heading_rad,
                weight=self.cfg.plan_weight,
                time_scale=self.pace_of(agv).scale,
            )
        except StartTaken:
            agv.blocked_at = (*blocked, t0)
            return False
        except NoRoute:
            return False
        finally:
            self.plan_times_s.append(time.perf_counter() - w0)
        for v in old:
            self.table.remove(v)
        keep = [] if fresh else agv.route[:g]
        visits: list[Visit | None] = [] if fresh else agv.visits[:g]
        for k, s in enumerate(steps):
            begin = held if k == 0 else steps[k - 1].depart_s
            end = steps[k + 1].arrive_s if k + 1 < len(steps) else INF
            v = Visit(agv.serial, s.node, g + k, begin, end, granted=k == 0)
            visits.append(v)
            self.table.add(v)
        if not fresh:
            steps[0].arrive_s = start.arrive_s
        agv.route, agv.visits = keep + steps, visits
        agv.actions = {i: a for i, a in agv.actions.items() if i <= g} if not fresh else {}
        agv.stops = [(st, i) for st, i in agv.stops if i <= g] if not fresh else []
        for k, s in enumerate(steps):
            if s.stop is not None:
                stop, acts = stops[s.stop]
                agv.actions.setdefault(g + k, []).extend(acts)
                agv.stops.append((stop, g + k))
        if fresh:
            agv.orders_sent += 1
            agv.order_id = f"{agv.serial}-{agv.orders_sent:05d}"
            agv.update_id, agv.granted, agv.sent, agv.reached = 0, 0, -1, 0
            agv.grant_t, agv.reached_s = {0: t_s}, None
            agv.order_done = False
        else:  # the steps after the decision point are new: so are their grants
            agv.grant_t = {i: t for i, t in agv.grant_t.items() if i <= g}
        agv.changed = True
        self._touched.add(agv.serial)
        return True

    def _remaining_stops(self, agv: Agv) -> list[tuple[Stop, list[dict]]]:
        return [(st, agv.actions.get(i, [])) for st, i in agv.stops if i > agv.granted]

    def _grant(self, agv: Agv) -> None:
        while agv.granted + 1 < len(agv.route):
            v = agv.visits[agv.granted + 1]
            if v is None or self.table.first(v.node) is not v:
                break
            self.table.grant(v)
            agv.granted += 1
            agv.grant_t[agv.granted] = self.t_s
            self._touched.add(agv.serial)

    # ------------------------------------------------------------------ per vehicle
    def _progress(self, agv: Agv, t_s: float, out: list[Message]) -> None:
        """What the vehicle's last state tells: passed nodes (their visits released),
        finished actions, a drop, an order done, a breakdown. Idempotent: when neither the
        state nor the master's record of the vehicle changed since the last call, it is
        skipped (most vehicles at most ticks: a periodic state, which only moved the
        vehicle on, tells nothing new)."""
        seen = agv.progress_seen
        if seen is not None and _same_events(seen[0], agv.state):
            if seen[1] == self._progress_key(agv):
                return
        self._progress_once(agv, t_s, out)
        agv.progress_seen = (agv.state, self._progress_key(agv))

    @staticmethod
    def _progress_key(agv: Agv) -> tuple:
        tr = agv.transport
        return (
            agv.order_id,
            agv.update_id,
            len(agv.route),
            agv.granted,
            agv.reached,
            agv.sent,
            agv.order_done,
            agv.broken,
            agv.job,
            id(tr),
            None if tr is None else tr.picked_s,
        )

    def _progress_once(self, agv: Agv, t_s: float, out: list[Message]) -> None:
        st = agv.state
        if st is None:
            return
        fatal = [e for e in st.get("errors", []) if e.get("errorLevel") == "FATAL"]
        if fatal and not agv.broken:
            self.breakdown(agv, t_s)
            return
        if agv.broken or st.get("orderId") != agv.order_id or agv.order_done:
            return
        if agv.sent < 0:
            return
        reached = int(st.get("lastNodeSequenceId", 0)) // 2
        if st.get("lastNodeId") != agv.route[min(reached, len(agv.route) - 1)].node:
            return
        if reached > agv.reached:
            self._paced(agv, agv.reached, reached, t_s)
            agv.reached = reached
            self._touched.add(agv.serial)
        for i in range(agv.reached):
            v = agv.visits[i]
            if v is not None:
                self.table.remove(v)
                agv.visits[i] = None
        status = {a["actionId"]: a["actionStatus"] for a in st.get("actionStates", [])}
        tr = agv.transport
        if tr is not None:
            if tr.picked_s is None and status.get(f"{tr.transport_id}-pick-{tr.attempts}") in ENDED:
                tr.picked_s = t_s
            drop = status.get(f"{tr.transport_id}-drop-{tr.attempts}")
            if tr.picked_s is not None and drop in ENDED:
                tr.delivered_s = t_s
                self.metrics.delivered(tr)
                agv.transport, agv.job = None, "home"
                if agv.battery_pct < self.cfg.charging.low_pct:
                    self._send_to_charger(agv, t_s)
        all_ended = all(s in ENDED for s in status.values())
        if (
            agv.reached == len(agv.route) - 1
            and agv.granted == agv.reached
            and not st.get("nodeStates")
            and all_ended
        ):
            agv.order_done = True
            self._touched.add(agv.serial)
            if agv.job == "charge":
                agv.job = "charging"
            elif agv.job == "home":
                agv.job = "idle"

    def pace_of(self, agv: Agv) -> Pace:
        """How much slower than its routing graph says ``agv``'s kind drives (learnt)."""
        g = self.graph(agv)
        got = self.pace.get(g)
        if got is None:
            got = self.pace[g] = Pace()
        return got

    def pace_summary(self) -> dict[str, dict[str, float]]:
        """The learnt pace by routing graph: the scale routes are planned with, the samples."""
        out = {}
        for (vt, speed, radius), g in sorted(self._graphs.items(), key=lambda kv: str(kv[0])):
            p = self.pace.get(g)
            if p is not None:
                name = f"{vt or 'any type'}, {speed:g} m/s"
                name += f", R {radius:g} m" if radius else ""
                out[name] = {"scale": round(p.scale, 4), "samples": p.samples}
        return out

    def _paced(self, agv: Agv, before: int, now: int, t_s: float) -> None:
        """The vehicle reported route node ``now`` (the last one was ``before``) at ``t_s``:
        an edge it drove through without stopping is a sample of its pace (agvsim.master.
        pace: its end granted ``GRANT_LEAD_S`` before it reached the start, no action and no
        planned wait at the start)."""
        since = agv.reached_s  # when it was seen at ``before``
        agv.reached_s = t_s
        if since is None or now != before + 1:
            return
        granted = agv.grant_t.get(now)
        prev, step = agv.route[before], agv.route[now]
        if granted is None or granted > since - GRANT_LEAD_S or agv.actions.get(before):
            return
        if prev.depart_s - prev.arrive_s > 1e-6:  # a planned wait there
            return
        arc = self.graph(agv).arc(prev.node, step.node)
        self.pace_of(agv).add(t_s - since, arc.time_s)

    def _send_to_charger(self, agv: Agv, t_s: float) -> bool:
        taken = {a.charger for a in self.agvs.values() if a is not agv and a.charger}
        free = [c for c in self.chargers(agv) if c not in taken]
        if not free:
            return False
        here = agv.route[-1 if agv.order_done else agv.granted].node
        free.sort(key=lambda c: (self.static_time(agv, here, c), c))
        for c in free:
            acts = [action(f"{agv.serial}-charge-{agv.orders_sent}-{c}", "startCharging")]
            if self.assign(agv, [(Stop(c), acts)], t_s):
                agv.job, agv.charger, agv.stop_charging_sent = "charge", c, False
                return True
        return False

    def breakdown(self, agv: Agv, t_s: float) -> None:
        """A vehicle reports FATAL: it keeps the node it stands on (and the one it was driving
        to) for good, its transport goes back to the queue, and every vehicle that was to
        pass those nodes later is re-planned around them."""
        agv.broken = True
        self._touched.add(agv.serial)
        self.metrics.breakdowns += 1
        hold = {agv.reached} | ({agv.reached + 1} if agv.granted > agv.reached else set())
        blocked = set()
        for i, v in enumerate(agv.visits):
            if v is None:
                continue
            if i in hold:
                self.table.hold_forever(v)
                blocked.add(v.node)
            else:
                self.table.remove(v)
                agv.visits[i] = None
        if agv.order_done and agv.visits and agv.visits[-1] is not None:
            blocked.add(agv.visits[-1].node)
        tr = agv.transport
        if tr is not None:
            tr.vehicle, tr.picked_s, tr.assigned_s = None, None, None
            tr.attempts += 1
            self.pending.insert(0, tr)
            agv.transport = None
        agv.job, agv.charger = "broken", None
        for other in self.agvs.values():
            if other is agv or other.broken or other.order_done:
                continue
            ahead = [v for v in other.visits[other.granted + 1 :] if v is not None]
            if any(v.node in blocked for v in ahead):
                if not self.assign(other, self._remaining_stops(other), t_s):
                    self.replan_failures += 1
                    other.replan = True

    # ------------------------------------------------------------------ the tick
    def tick(self, t_s: float) -> list[Message]:
        self.t_s = t_s
        out: list[Message] = []
        while self.upcoming and self.upcoming[0].created_s <= t_s:
            self.pending.append(self.upcoming.pop(0))
        for agv in self.agvs.values():
            if (not agv.order_done or agv.serial in self._touched) and agv.ready:
                self._progress(agv, t_s, out)
        self._charging(t_s, out)
        blocking = self._blocking()
        for agv in self.agvs.values():
            if agv.replan and not agv.broken and not agv.order_done:
                agv.replan = not self.assign(agv, self._remaining_stops(agv), t_s)
            elif agv.serial in blocking and self._late(agv, t_s):
                agv.retimed_s = t_s
                if self.assign(agv, self._remaining_stops(agv), t_s):
                    self.metrics.retimed += 1
        self._dispatch(t_s)
        for agv in self.agvs.values():
            if agv.order_done and not agv.changed or agv.broken or not agv.ready:
                continue
            self._grant(agv)
            if agv.granted > agv.sent or agv.changed:
                out.append(
                    (
                        agv.serial,
                        "order",
                        order_message(
                            agv, self.layout, self.graph(agv), t_s, self.cfg.horizon_nodes
                        ),
                    )
                )
                agv.sent, agv.changed = agv.granted, False
        self.metrics.step(self, t_s, sorted(self._touched))
        self._touched.clear()
        self._detect_deadlocks()
        self._detect_stalls(t_s)
        return out

    def _blocking(self) -> set[str]:
        """Vehicles that hold others up: a visit of theirs not yet granted stands before
        another vehicle's next visit in a node's queue. Only those are worth re-planning
        when late (re-planning one that blocks nobody frees nobody, and at a thousand
        vehicles most run somewhat late)."""
        out: set[str] = set()
        queues = self.table.visits
        for a in self.agvs.values():
            if a.order_done or a.broken or a.granted + 1 >= len(a.visits):
                continue
            w = a.visits[a.granted + 1]
            if w is None or w.granted:
                continue
            for v in queues.get(w.node, ()):
                if v is w:
                    break
                if not v.granted:
                    out.add(v.serial)
        return out

    def _late(self, agv: Agv, t_s: float) -> bool:
        """Behind its plan by ``late_s`` (at the next node), with a part not yet granted, and
        not re-planned for that in the last ``late_s``. Re-planning it moves its pending
        visits after everyone else's: vehicles queued behind them go first (the planned
        order stays consistent, so the dependency graph stays acyclic)."""
        if agv.order_done or agv.broken or agv.state is None or not agv.ready:
            return False
        if agv.granted + 1 >= len(agv.route) or t_s - agv.retimed_s < self.cfg.late_s:
            return False
        nxt = agv.route[min(agv.reached + 1, len(agv.route) - 1)]
        return t_s - nxt.arrive_s > self.cfg.late_s

    def _detect_stalls(self, t_s: float) -> None:
        """A vehicle with an order that has neither passed a node, nor finished an action,
        nor been sent anything for ``stall_s``: counted once (it must never happen)."""
        for a in self.agvs.values():
            if a.order_done or a.broken or a.job == "charging":
                if a.progress:
                    a.progress, a.progress_s, a.stalled = (), t_s, False
                continue
            st = a.state or {}
            key = (st.get("lastNodeSequenceId"), a.order_id, a.update_id, a.ended(), a.job)
            if key != a.progress:
                a.progress, a.progress_s, a.stalled = key, t_s, False
            elif t_s - a.progress_s > self.cfg.stall_s and not a.stalled:
                a.stalled = True
                self.metrics.stalls += 1

    def _charging(self, t_s: float, out: list[Message]) -> None:
        low, full = self.cfg.charging.low_pct, self.cfg.charging.full_pct
        for agv in self.agvs.values():
            if agv.job not in ("charging", "idle") or agv.broken or not agv.ready:
                continue
            if agv.job == "charging" and agv.charging and agv.battery_pct >= full:
                if not agv.stop_charging_sent:
                    msg = agv.stamp.header("instantActions", t_s) | {
                        "actions": [
                            action(
                                f"{agv.serial}-stopcharge-{agv.orders_sent}", "stopCharging", "NONE"
                            )
                        ]
                    }
                    out.append((agv.serial, "instantActions", msg))
                    agv.stop_charging_sent = True
            elif agv.job == "charging" and agv.stop_charging_sent and not agv.charging:
                if self.assign(agv, [(Stop(agv.home or ""), [])], t_s):
                    agv.job, agv.charger = "home", None
            elif agv.job == "idle" and agv.battery_pct < low:
                self._send_to_charger(agv, t_s)

    def available(self) -> list[str]:
        low = self.cfg.charging.low_pct
        return [
            a.serial
            for a in self.agvs.values()
            if a.job in ("idle", "home")
            and not a.broken
            and a.ready
            and a.battery_pct >= low
            and not a.charging
        ]

    def _dispatch(self, t_s: float) -> None:
        if not self.pending:
            return
        free = self.available()
        # where each candidate decides next, by node index, grouped by routing graph: the
        # cost of a pick-up for all of them is one table look-up per group (numpy)
        by_graph: dict[RoadGraph, tuple[list[int], list[int]]] = {}
        for pos, sn in enumerate(free):
            a = self.agvs[sn]
            g = self.graph(a)
            here = a.route[-1 if a.order_done else a.granted].node
            rows, nodes = by_graph.setdefault(g, ([], []))
            rows.append(pos)
            nodes.append(g.index[here])
        groups = {g: (np.array(r), np.array(n)) for g, (r, n) in by_graph.items()}

        def costs(node: str) -> np.ndarray:
            out = np.full(len(free), INF)
            for g, (rows, nodes) in groups.items():
                out[rows] = g.times_to(node).array[nodes]
            return out

        def take(pos: int) -> None:  # candidate ``pos`` got an order: drop its row
            del free[pos]
            for g, (rows, nodes) in groups.items():
                keep = rows != pos
                groups[g] = (rows[keep] - (rows[keep] > pos), nodes[keep])

        # each order to the best candidate whose route fits; a candidate whose route does
        # not fit is out for the rest of the tick (the next best is tried), and at most
        # ``dispatch_plans`` routes are searched a tick: the rest wait, in order, for the next
        left: list[Transport] = []
        budget = self.cfg.dispatch_plans
        for tr in self.pending:
            placed = False
            while free and budget > 0 and not placed:
                serial = self.policy(tr, free, costs)
                agv = self.agvs.get(serial) if serial else None
                if agv is None:
                    break
                n = tr.attempts
                stops = [
                    (
                        Stop(tr.source, PLANNED_DWELL_S),
                        [action(f"{tr.transport_id}-pick-{n}", "pick", loadId=tr.transport_id)],
                    ),
                    (
                        Stop(tr.destination, PLANNED_DWELL_S),
                        [action(f"{tr.transport_id}-drop-{n}", "drop")],
                    ),
                    (Stop(agv.home or ""), []),
                ]
                planned = len(self.plan_times_s)
                if self.assign(agv, stops, t_s):
                    tr.vehicle, tr.assigned_s = agv.serial, t_s
                    agv.transport, agv.job = tr, "transport"
                    placed = True
                budget -= len(self.plan_times_s) - planned  # (a known-blocked one is free)
                take(free.index(agv.serial))
            if not placed:
                left.append(tr)
        self.pending = left

    def _detect_deadlocks(self) -> None:
        """Vehicles stopped at the end of their base, each waiting for a node whose first
        visit belongs to another: a cycle among them is a deadlock, counted once."""
        waits: dict[str, str] = {}
        for a in self.agvs.values():
            if a.order_done or a.broken or a.granted + 1 >= len(a.route):
                continue
            if a.reached != a.granted:
                continue
            v = a.visits[a.granted + 1]
            head = self.table.first(v.node) if v is not None else None
            if head is not None and head.serial != a.serial:
                waits[a.serial] = head.serial
        for cycle in wait_cycles(waits):
            if cycle not in self._deadlocks_seen:
                self._deadlocks_seen.add(cycle)
                self.metrics.deadlocks += 1

    @property
    def all_delivered(self) -> bool:
        return (
            not self.upcoming
            and not self.pending
            and all(t.delivered_s is not None for t in self.transports)
        )

    def waiting(self, agv: Agv) -> bool:
        return (
            not agv.order_done
            and not agv.broken
            and agv.reached == agv.granted
            and agv.granted + 1 < len(agv.route)
            and not bool((agv.state or {}).get("driving"))
        )
