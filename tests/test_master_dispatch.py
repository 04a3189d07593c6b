"""Dispatching under load: a bounded number of route searches a tick for waiting orders, the
next best vehicle when the best one's route does not fit, and a vehicle whose decision point
others hold is not searched for again until that node changes."""

from __future__ import annotations

import pytest
from test_master_fleet import Checked, warehouse
from test_master_traffic import grid

from agvsim.master.config import MasterConfig
from agvsim.master.graph import RoadGraph
from agvsim.master.traffic import INF, Reservations, StartTaken, Stop, Visit, plan_route

STATIONS = ["rack1-A", "rack2-A", "rack3-A", "rack1-B", "rack2-B", "rack3-B"]


def orders_at_once(n: int) -> list[dict]:
    return [
        {"source": STATIONS[k % 6], "destination": STATIONS[(k + 2) % 6], "at_s": 0}
        for k in range(n)
    ]


def test_at_most_dispatch_plans_route_searches_a_tick() -> None:
    cfg = MasterConfig.model_validate({"transports": orders_at_once(5), "dispatch_plans": 1})
    r = Checked(warehouse(5, cfg), duration_s=600)
    m = r.master
    per_tick: list[int] = []
    dispatch = m._dispatch

    def counted(t_s: float) -> None:
        before = len(m.plan_times_s)
        dispatch(t_s)
        per_tick.append(len(m.plan_times_s) - before)

    m._dispatch = counted  # type: ignore[method-assign]
    r.run(until_s=1.0)
    # five orders and five idle vehicles from the start: one search (one order) a tick
    assert per_tick and max(per_tick) == 1
    assigned = [t.assigned_s for t in m.transports]
    assert sorted(a for a in assigned if a is not None) == sorted(set(assigned) - {None})
    r.run(stop_when_done=True)
    s = r.summary()
    assert s["orders_completed"] == 5
    assert (s["collisions"], s["deadlocks"], s["stalls"]) == (0, 0, 0)


def test_the_next_best_vehicle_takes_an_order_the_best_cannot_plan() -> None:
    orders = [{"source": "rack2-A", "destination": "rack3-B", "at_s": 1.0}]
    r = Checked(warehouse(5, MasterConfig.model_validate({"transports": orders})), duration_s=60)
    m = r.master
    r.run(until_s=0.5)  # every vehicle known and idle, the order not placed yet
    free = m.available()
    assert len(free) == 5

    def cost(serial: str) -> float:
        agv = m.agvs[serial]
        return m.static_time(agv, agv.route[-1].node, m.transports[0].source)

    ranked = sorted(free, key=lambda s: (cost(s), free.index(s)))  # nearest_idle's order
    best = ranked[0]
    assign = m.assign
    tried: list[str] = []

    def fails_for_best(agv, stops, t_s):  # noqa: ANN001, ANN202
        tried.append(agv.serial)
        return False if agv.serial == best else assign(agv, stops, t_s)

    m.assign = fails_for_best  # type: ignore[method-assign]
    r.run(until_s=1.5)
    t = m.transports[0]
    # the best is tried once, then the next best gets the order in that same tick
    assert tried[:2] == ranked[:2] and t.vehicle == ranked[1]
    assert tried.count(best) == 1 and t.assigned_s == pytest.approx(1.0)


def test_a_start_held_by_others_is_its_own_failure() -> None:
    """StartTaken (a NoRoute) says the vehicle cannot stay on its start long enough: what the
    master remembers, with the node's version, to skip the same search until it changes."""
    g, table = RoadGraph(grid(3, 1), "agv", 1.0), Reservations(margin_s=0.0)
    table.add(Visit("B", "1,0", 0, 2.0, 3.0))  # B comes through at t = 2..3
    v0 = table.version("1,0")
    # A has stood on 1,0 since t=0 and it is t=2.5 now: B's visit is in the way
    with pytest.raises(StartTaken):
        plan_route(g, table, "A", "1,0", 2.5, [Stop("0,0")], held_since_s=0.0)
    # at t=0.5 it is off the node (at 0,0, t=1.5) before B's visit begins
    steps = plan_route(g, table, "A", "1,0", 0.5, [Stop("0,0")], held_since_s=0.0)
    assert [s.node for s in steps] == ["1,0", "0,0"]
    b = table.first("1,0")
    assert b is not None
    table.remove(b)  # B re-planned elsewhere: the node changed, and now A fits
    assert table.version("1,0") > v0
    steps = plan_route(g, table, "A", "1,0", 2.5, [Stop("0,0")], held_since_s=0.0)
    assert steps[-1].arrive_s == pytest.approx(3.5) and steps[-1].depart_s == INF
