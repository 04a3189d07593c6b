"""Routing and traffic control without the simulation: A* times worked by hand, SIPP routes
that never share a node in planned time, and the action-dependency execution finishing every
route whatever the delays (hypothesis), where a naive node-locking master deadlocks."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.master.graph import Arc, RoadGraph, turn_fits
from agvsim.master.traffic import INF, NoRoute, Reservations, Stop, Visit, plan_route
from agvsim.world.lif import Edge, EdgeProps, Layout, Node, NodeProps

T = "agv"


def layout(nodes: dict[str, tuple[float, float]], pairs: list[tuple[str, str, float]]) -> Layout:
    """Both directions of every pair, with its speed limit (m/s)."""
    ns = {k: Node(k, x, y, {T: NodeProps()}) for k, (x, y) in nodes.items()}
    es = {}
    for a, b, v in pairs:
        for s, e in ((a, b), (b, a)):
            es[f"{s}-{e}"] = Edge(f"{s}-{e}", s, e, {T: EdgeProps(True, v)})
    return Layout("test", ns, es)


def grid(w: int, h: int, holes: frozenset[tuple[int, int]] = frozenset()) -> Layout:
    nodes = {f"{x},{y}": (float(x), float(y)) for x in range(w) for y in range(h)}
    nodes = {k: p for k, p in nodes.items() if (int(p[0]), int(p[1])) not in holes}
    pairs = []
    for k, (x, y) in nodes.items():
        for dx, dy in ((1, 0), (0, 1)):
            o = f"{int(x) + dx},{int(y) + dy}"
            if o in nodes:
                pairs.append((k, o, 1.0))
    return layout(nodes, pairs)


def add_route(table: Reservations, serial: str, steps) -> list[Visit]:
    vs = []
    for k, s in enumerate(steps):
        start = steps[0].arrive_s if k == 0 else steps[k - 1].depart_s
        end = steps[k + 1].arrive_s if k + 1 < len(steps) else INF
        v = Visit(serial, s.node, k, start, end)
        table.add(v)
        vs.append(v)
    return vs


def test_astar_prefers_the_faster_longer_way() -> None:
    # a -> c straight is 2 m at 0.2 m/s (10 s); a -> b -> c is 2 * hypot(1, 1) m at 1 m/s
    lay = layout(
        {"a": (0, 0), "b": (1, 1), "c": (2, 0)}, [("a", "c", 0.2), ("a", "b", 1.0), ("b", "c", 1.0)]
    )
    g = RoadGraph(lay, T, max_speed_m_s=2.0)
    path, t = g.astar("a", "c") or ([], 0.0)
    assert path == ["a", "b", "c"]
    assert t == pytest.approx(2 * math.sqrt(2))
    # the vehicle's own top speed caps the edge limit: at 0.5 m/s the detour takes 5.66 s
    slow = RoadGraph(lay, T, max_speed_m_s=0.5)
    assert slow.astar("a", "c") == (["a", "b", "c"], pytest.approx(4 * math.sqrt(2)))
    assert slow.times_to("c")["a"] == pytest.approx(4 * math.sqrt(2))


def test_astar_unreachable_and_vehicle_types() -> None:
    lay = layout({"a": (0, 0), "b": (1, 0), "z": (5, 5)}, [("a", "b", 1.0)])
    g = RoadGraph(lay, T, 1.0)
    assert g.astar("a", "z") is None
    assert RoadGraph(lay, "other-type", 1.0).astar("a", "b") is None  # no edge for that type


def test_sipp_waits_for_a_crossing_vehicle() -> None:
    # a plus: w - c - e and n - c - s, 1 m arms at 1 m/s; X drives n -> s first
    lay = layout(
        {"w": (-1, 0), "c": (0, 0), "e": (1, 0), "n": (0, 1), "s": (0, -1)},
        [("w", "c", 1.0), ("c", "e", 1.0), ("n", "c", 1.0), ("c", "s", 1.0)],
    )
    g, table = RoadGraph(lay, T, 1.0), Reservations(margin_s=0.0)
    x = plan_route(g, table, "X", "n", 0.0, [Stop("s")])
    assert [s.node for s in x] == ["n", "c", "s"]
    assert [s.arrive_s for s in x] == [0.0, 1.0, 2.0]
    add_route(table, "X", x)
    # X holds c from t=0 (heading there) to t=2 (at s): Y may head for c at t=2 at the earliest
    y = plan_route(g, table, "Y", "w", 0.0, [Stop("e")])
    assert [s.node for s in y] == ["w", "c", "e"]
    assert y[0].depart_s == pytest.approx(2.0)
    assert y[1].arrive_s == pytest.approx(3.0) and y[2].arrive_s == pytest.approx(4.0)


def test_sipp_dwell_and_parked_vehicle() -> None:
    lay = grid(3, 1)  # 0,0 - 1,0 - 2,0
    g, table = RoadGraph(lay, T, 1.0), Reservations(margin_s=0.0)
    r = plan_route(g, table, "A", "0,0", 0.0, [Stop("1,0", 3.0), Stop("0,0")])
    assert [(s.node, s.stop) for s in r] == [("0,0", None), ("1,0", 0), ("0,0", 1)]
    assert r[1].depart_s == pytest.approx(1.0 + 3.0) and r[2].arrive_s == pytest.approx(5.0)
    table.add(Visit("P", "2,0", 0, 0.0, INF))  # parked for good
    with pytest.raises(NoRoute):
        plan_route(g, table, "A", "0,0", 0.0, [Stop("2,0")])


def naive_deadlocks(routes: dict[str, list[str]]) -> bool:
    """A naive master: every vehicle drives its own shortest route, taking the next node as
    soon as it is free. True when it gets stuck with routes unfinished."""
    at = {s: 0 for s in routes}
    held = {r[0]: s for s, r in routes.items()}
    moved = True
    while moved:
        moved = False
        for s, r in sorted(routes.items()):
            if at[s] + 1 < len(r) and r[at[s] + 1] not in held:
                del held[r[at[s]]]
                at[s] += 1
                held[r[at[s]]] = s
                moved = True
    return any(at[s] + 1 < len(r) for s, r in routes.items())


def execute(routes: dict[str, list[Visit]], table: Reservations, order: list[int]) -> None:
    """Action-dependency execution: a vehicle moves on to its next visit only when that visit
    is the first of its node; its previous visit is released as it arrives. ``order`` picks
    which movable vehicle goes next (any delays). Fails on a deadlock."""
    at = dict.fromkeys(routes, 0)
    k = 0
    while any(at[s] + 1 < len(v) for s, v in routes.items()):
        movable = [
            s
            for s, vs in sorted(routes.items())
            if at[s] + 1 < len(vs) and table.first(vs[at[s] + 1].node) is vs[at[s] + 1]
        ]
        assert movable, f"deadlock at {at}"
        s = movable[order[k % len(order)] % len(movable)]
        k += 1
        table.remove(routes[s][at[s]])
        at[s] += 1
        # exclusive: no other vehicle's visit ahead of this one on the node
        assert table.first(routes[s][at[s]].node) is routes[s][at[s]]


def test_corridor_swap_deadlocks_naive_master_not_ours() -> None:
    # a corridor (0..6, 0) with a home spur above each end; A and B each fetch something
    # from the far end and come home: head-on in the corridor, twice
    holes = frozenset((x, 1) for x in range(1, 6))
    lay = grid(7, 2, holes)
    g = RoadGraph(lay, T, 1.0)
    plain = {"A": g.astar("0,1", "6,0"), "B": g.astar("6,1", "0,0")}
    assert naive_deadlocks({s: p[0] for s, p in plain.items() if p})
    table = Reservations(margin_s=0.5)
    homes = {"A": "0,1", "B": "6,1"}
    for s, h in homes.items():
        table.add(Visit(s, h, 0, 0.0, INF))
    routes = {}
    for s, far in (("A", "6,0"), ("B", "0,0")):
        parked = table.first(homes[s])
        assert parked is not None
        table.remove(parked)
        steps = plan_route(g, table, s, homes[s], 0.0, [Stop(far, 2.0), Stop(homes[s])])
        assert [x.node for x in steps if x.stop == 0] == [far]
        routes[s] = add_route(table, s, steps)
    # B's trip was planned around A's: it starts only once A has turned at the far end
    b_leaves = routes["B"][1].start_s
    a_turns = next(v for v in routes["A"] if v.node == "6,0").end_s
    assert b_leaves >= a_turns
    for order in ([0], [1], [0, 1, 1, 0, 1]):
        t2 = Reservations(margin_s=0.5)
        copies = {}
        for s, vs in routes.items():
            copies[s] = [Visit(v.serial, v.node, v.index, v.start_s, v.end_s) for v in vs]
            for v in copies[s]:
                t2.add(v)
        execute(copies, t2, order)


@st.composite
def scenes(draw):
    w, h = draw(st.integers(3, 6)), draw(st.integers(1, 4))
    cells = [(x, y) for x in range(w) for y in range(h)]
    holes = frozenset(draw(st.sets(st.sampled_from(cells), max_size=len(cells) // 3)))
    free = [c for c in cells if c not in holes]
    n = draw(st.integers(1, max(1, min(5, len(free) // 2))))
    starts = draw(st.lists(st.sampled_from(free), min_size=n, max_size=n, unique=True))
    goals = draw(st.lists(st.sampled_from(free), min_size=n, max_size=n, unique=True))
    order = draw(st.lists(st.integers(0, 10), min_size=1, max_size=30))
    return w, h, holes, starts, goals, order


@pytest.mark.parametrize("weight", [1.0, 1.5])
@settings(max_examples=150, deadline=None)
@given(scenes())
def test_planned_routes_never_overlap_and_always_finish(weight, scene) -> None:
    """Whatever the layout, starts, goals and delays: routes planned one after the other never
    hold a node at the same planned time, and executing them in dependency order never
    deadlocks - every vehicle that got a route reaches its goal. Weighted A* (weight > 1)
    finds routes at most ``weight`` times slower than the quickest that fits."""
    w, h, holes, starts, goals, order = scene
    lay = grid(w, h, holes)
    g = RoadGraph(lay, T, 1.0)
    table = Reservations(margin_s=0.25)
    parked = {f"V{k}": f"{x},{y}" for k, (x, y) in enumerate(starts)}
    for s, node in parked.items():  # everyone waits at its start until it has a route
        table.add(Visit(s, node, 0, 0.0, INF))
    routes = {}
    for k, (s, node) in enumerate(parked.items()):
        goal = "{},{}".format(*goals[k])
        old = table.first(node)
        assert old is not None and old.serial == s
        table.remove(old)
        try:
            steps = plan_route(
                g, table, s, node, 0.0, [Stop(goal)], max_expansions=20_000, weight=weight
            )
        except NoRoute:
            table.add(old)
            continue
        quickest = plan_route(g, table, s, node, 0.0, [Stop(goal)], max_expansions=20_000)
        assert quickest[-1].arrive_s <= steps[-1].arrive_s <= weight * quickest[-1].arrive_s + 1e-9
        assert steps[0].node == node and steps[-1].node == goal
        for a, b in zip(steps, steps[1:], strict=False):
            assert b.node in [arc.end for arc in g.out[a.node]]
            assert b.arrive_s == pytest.approx(a.depart_s + g.arc(a.node, b.node).time_s)
        routes[s] = add_route(table, s, steps)
    for node, vs in table.visits.items():
        for a, b in zip(vs, vs[1:], strict=False):
            if a.serial != b.serial:
                assert a.end_s + table.margin_s <= b.start_s + 1e-9, (node, a, b)
    execute(routes, table, order)


def test_wait_cycles_finds_each_deadlock_once() -> None:
    from agvsim.master.master import wait_cycles

    # A waits for B, B for C, C for A: one cycle; D waits for A (stuck behind it, not in it)
    assert wait_cycles({"A": "B", "B": "C", "C": "A", "D": "A"}) == [frozenset("ABC")]
    assert wait_cycles({"A": "B", "B": "C"}) == []  # C moves: no deadlock
    assert wait_cycles({"A": "B", "B": "A", "C": "D", "D": "C"}) == [
        frozenset("AB"),
        frozenset("CD"),
    ]
    # the naive master's corridor swap, as a wait-for graph: head-on, each for the other
    assert wait_cycles({"agvW": "agvE", "agvE": "agvW"}) == [frozenset({"agvW", "agvE"})]


# ------------------------------------------------------------------ car-like vehicles
R_ACKERMANN = 0.5 / math.tan(math.radians(35.0))  # wheelbase 0.5 m, 35 deg lock: 0.714 m


def test_turn_fits_hand_worked() -> None:
    # a 90 deg turn driven as a quarter circle of radius R starts R tan(45 deg) = R before
    # the node: it fits when half of each edge holds it
    east = Arc("e", "a", "b", 2.0, 2.0, 0.0, 0.0)
    north = Arc("n", "b", "c", 2.0, 2.0, math.pi / 2, math.pi / 2)
    short_north = Arc("n", "b", "c", 1.2, 1.2, math.pi / 2, math.pi / 2)
    back = Arc("w", "b", "a", 2.0, 2.0, math.pi, math.pi)
    diagonal = Arc("d", "b", "c", 2.0, 2.0, math.radians(-120), math.radians(-120))
    assert turn_fits(R_ACKERMANN, 0.0, north, 2.0)  # needs 0.714 m of 1.0 m
    assert not turn_fits(R_ACKERMANN, 0.0, short_north, 2.0)  # needs 0.714 m of 0.6 m
    assert turn_fits(R_ACKERMANN, 0.0, east, 2.0)  # straight on: needs nothing
    assert not turn_fits(R_ACKERMANN, 0.0, back, 100.0)  # a U-turn never fits
    # 120 deg: R tan(60 deg) = 1.237 m > 1.0 m; with 3 m edges it fits (1.5 m)
    assert not turn_fits(R_ACKERMANN, 0.0, diagonal, 2.0)
    assert turn_fits(R_ACKERMANN, 0.0, Arc("d", "b", "c", 3.0, 3.0, *[math.radians(-120)] * 2), 3.0)
    assert turn_fits(0.0, 0.0, back, 0.1)  # it turns on the spot: anything goes


def lollipop() -> Layout:
    """A corridor w - a - b (2 m edges, both ways) ending in a square loop b - c - d - e - b
    (2 m sides, both ways), and a dead-end spur s north of a."""
    return layout(
        {
            "w": (-2, 0), "a": (0, 0), "b": (2, 0), "c": (4, 0), "d": (4, 2), "e": (2, 2),
            "s": (0, 2),
        },
        [
            ("w", "a", 1.0), ("a", "b", 1.0), ("b", "c", 1.0), ("c", "d", 1.0),
            ("d", "e", 1.0), ("e", "b", 1.0), ("a", "s", 1.0),
        ],
    )  # fmt: skip


def doubles_back(nodes: list[str]) -> bool:
    """u -> w -> u somewhere on the route."""
    return any(nodes[k] == nodes[k + 2] for k in range(len(nodes) - 2))


def test_car_like_turns_round_only_on_a_loop() -> None:
    lay = lollipop()
    diff = RoadGraph(lay, T, 1.0)
    car = RoadGraph(lay, T, 1.0, turn_radius_m=R_ACKERMANN)
    arrived = car.arc("a", "b")  # it drove east into b: a is behind it
    r = plan_route(diff, Reservations(), "X", "b", 0.0, [Stop("a")], heading_rad=0.0)
    assert [s.node for s in r] == ["b", "a"]  # turns on the spot
    r = plan_route(car, Reservations(), "X", "b", 0.0, [Stop("a")], arrived_by=arrived)
    nodes = [s.node for s in r]
    assert nodes in (["b", "c", "d", "e", "b", "a"], ["b", "e", "d", "c", "b", "a"])
    assert not doubles_back(nodes)
    # each turn on the way is one the lock allows (90 deg at c, d, e and at b)
    arcs = [car.arc(u, v) for u, v in itertools.pairwise(nodes)]
    for a, b in itertools.pairwise([arrived, *arcs]):
        assert turn_fits(R_ACKERMANN, a.heading_end_rad, b, a.length_m)
    assert r[-1].arrive_s == pytest.approx(5 * 2.0)  # 10 m at 1 m/s
    # standing on b facing west (its reported heading): straight there
    r = plan_route(car, Reservations(), "X", "b", 0.0, [Stop("a")], heading_rad=math.pi)
    assert [s.node for s in r] == ["b", "a"]
    # w is a dead end: it may pass it as a stop only to come back, which it cannot
    with pytest.raises(NoRoute):
        plan_route(car, Reservations(), "X", "b", 0.0, [Stop("w")], heading_rad=math.pi)


def test_car_like_never_parks_where_it_cannot_leave() -> None:
    lay = lollipop()
    car = RoadGraph(lay, T, 1.0, turn_radius_m=R_ACKERMANN)
    # the dead-end spur s: it could drive in but never out (a U-turn on s)
    with pytest.raises(NoRoute):
        plan_route(car, Reservations(), "X", "w", 0.0, [Stop("s")], heading_rad=0.0)
    assert [s.node for s in plan_route(RoadGraph(lay, T, 1.0), Reservations(), "X", "w", 0.0,
                                       [Stop("s")])] == ["w", "a", "s"]  # fmt: skip
    # a stop on a dead end is as impossible: pick at s, then park on b
    with pytest.raises(NoRoute):
        plan_route(car, Reservations(), "X", "w", 0.0, [Stop("s", 3.0), Stop("b")])
    # parking on c is fine: it leaves north (to d) whichever way it came
    r = plan_route(car, Reservations(), "X", "w", 0.0, [Stop("c")], heading_rad=0.0)
    assert [s.node for s in r] == ["w", "a", "b", "c"]
