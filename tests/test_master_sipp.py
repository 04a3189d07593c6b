"""The numba route search (``agvsim.master.sipp`` behind ``plan_route``) finds exactly the
routes of the plain-Python reference search (``sipp_reference``) on random problems: grids
with holes, tables already holding other vehicles' routes (granted and not, parked for
good), the vehicle's own visits, stops with dwell times, parking places to avoid, weights and
car-like vehicles. Bit for bit: the same nodes, times and stops, or NoRoute from both."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sipp_reference import plan_route_reference
from test_master_traffic import grid

from agvsim.master.graph import RoadGraph
from agvsim.master.traffic import INF, NoRoute, Reservations, Stop, Visit, plan_route

T = "agv"


def solve(fn, *args, **kw) -> list[tuple[str, float, float, int | None]] | str:  # noqa: ANN001
    try:
        return [(s.node, s.arrive_s, s.depart_s, s.stop) for s in fn(*args, **kw)]
    except NoRoute:
        return "no route"


@st.composite
def problems(draw):
    w, h = draw(st.integers(2, 6)), draw(st.integers(1, 4))
    cells = [(x, y) for x in range(w) for y in range(h)]
    holes = frozenset(draw(st.sets(st.sampled_from(cells), max_size=len(cells) // 4)))
    free = [f"{x},{y}" for x, y in cells if (x, y) not in holes]
    others = draw(st.integers(0, min(6, len(free) - 1)))
    n = others + 1
    starts = draw(st.lists(st.sampled_from(free), min_size=n, max_size=n, unique=True))
    goals = draw(st.lists(st.sampled_from(free), min_size=n, max_size=n, unique=True))
    # mostly where nobody parks for good (others' goals), sometimes anywhere
    open_ = [c for c in free if c not in goals[1:]] or free
    stops = draw(
        st.lists(
            st.tuples(st.sampled_from(open_), st.sampled_from([0.0, 0.5, 3.0])),
            min_size=1,
            max_size=3,
        )
    )
    return {
        "w": w,
        "h": h,
        "holes": holes,
        "starts": starts,
        "goals": goals,
        "granted": draw(st.lists(st.booleans(), min_size=others, max_size=others)),
        "broken": draw(st.integers(0, 6)),
        "t0": draw(st.sampled_from([0.0, 0.7, 2.0, 5.5])),
        "stops": stops,
        "weight": draw(st.sampled_from([1.0, 1.3, 2.0])),
        "margin": draw(st.sampled_from([0.0, 0.25, 0.5])),
        "avoid": frozenset(draw(st.sets(st.sampled_from(free), max_size=2))),
        "car": draw(st.booleans()),
        "heading": draw(st.sampled_from([None, 0.0, math.pi / 2, math.pi])),
        "own": draw(st.sets(st.sampled_from(open_), max_size=2)),
        "stop_at_start": draw(st.booleans()),
    }


def table_of(g: RoadGraph, p: dict) -> Reservations:
    """Other vehicles' routes planned one after another (some on their way: the first node
    released, the next granted, one of them broken down there; the ones with no route parked
    for good where they start), and a few visits of the planning vehicle "X" itself."""
    table = Reservations(margin_s=p["margin"])
    for k, (s, goal) in enumerate(zip(p["starts"][1:], p["goals"][1:], strict=True)):
        try:
            steps = plan_route(g, table, f"O{k}", s, 0.5 * k, [Stop(goal)])
        except NoRoute:
            table.add(Visit(f"O{k}", s, 0, 0.0, INF, granted=True))
            continue
        vs = []
        for i, step in enumerate(steps):
            begin = 0.5 * k if i == 0 else steps[i - 1].depart_s
            end = steps[i + 1].arrive_s if i + 1 < len(steps) else INF
            vs.append(Visit(f"O{k}", step.node, i, begin, end, granted=i == 0))
            table.add(vs[-1])
        if p["granted"][k] and len(vs) > 1:  # it went on: the next node granted, the first left
            table.grant(vs[1])
            table.remove(vs[0])
            if k == p["broken"]:  # and broke down there
                table.hold_forever(vs[1])
    for i, node in enumerate(sorted(p["own"])):
        table.add(Visit("X", node, i, 0.0, 1.0 + i, granted=i == 0))
    return table


@settings(max_examples=300, deadline=None)
@given(problems())
def test_numba_search_finds_the_reference_routes(p) -> None:
    lay = grid(p["w"], p["h"], p["holes"])
    radius = 0.4 if p["car"] else 0.0  # on 1 m edges: 90 deg turns fit, U-turns never
    g = RoadGraph(lay, T, 1.0, turn_radius_m=radius)
    table = table_of(RoadGraph(lay, T, 1.0), p)
    start = p["starts"][0]
    arrived_by = None
    if p["car"] and g.out[start] and p["heading"] is None:
        back = g.out[start][0]  # it came in against the first arc out (a U-turn away)
        arrived_by = g.arc(back.end, start)
    kw = {
        "held_since_s": 0.0,
        "stop_at_start": p["stop_at_start"],
        "avoid": p["avoid"],
        "arrived_by": arrived_by,
        "heading_rad": p["heading"],
        "weight": p["weight"],
        "max_expansions": 5_000,
    }
    stops = [Stop(n, d) for n, d in p["stops"]]
    want = solve(plan_route_reference, g, table, "X", start, p["t0"], stops, **kw)
    got = solve(plan_route, g, table, "X", start, p["t0"], stops, **kw)
    assert got == want
    # the table's array copy is left as it was found (the vehicle's own rows swapped back)
    again = solve(plan_route, g, table, "X", start, p["t0"], stops, **kw)
    assert again == want


def test_reference_and_kernel_on_a_hand_worked_crossing() -> None:
    """The plus of test_sipp_waits_for_a_crossing_vehicle, both searches: Y waits 2 s."""
    lay = grid(3, 3)
    g, table = RoadGraph(lay, T, 1.0), Reservations(margin_s=0.0)
    x = plan_route(g, table, "X", "1,2", 0.0, [Stop("1,0")])
    assert [(s.node, s.arrive_s) for s in x] == [("1,2", 0.0), ("1,1", 1.0), ("1,0", 2.0)]
    for k, s in enumerate(x):
        end = x[k + 1].arrive_s if k + 1 < len(x) else INF
        table.add(Visit("X", s.node, k, 0.0 if k == 0 else x[k - 1].depart_s, end))
    for fn in (plan_route, plan_route_reference):
        y = fn(g, table, "Y", "0,1", 0.0, [Stop("2,1")], avoid=frozenset({"0,0", "0,2"}))
        # straight through the middle once X has left it (t=2), or round a corner: the
        # corner way (0,1 -> 0,0 ...) is closed by ``avoid``, the other by 2,2 / 2,0 times
        assert [s.node for s in y] == ["0,1", "1,1", "2,1"]
        assert y[0].depart_s == pytest.approx(2.0) and y[-1].arrive_s == pytest.approx(4.0)
