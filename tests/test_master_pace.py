"""The master's learnt pace (agvsim.master.pace): the weighted ratio worked by hand, routes
planned with scaled times, and a fleet whose plans it keeps closer to what the vehicles do."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from test_master_fleet import warehouse
from test_master_traffic import grid, layout

from agvsim.master.config import GenerateConfig, MasterConfig
from agvsim.master.graph import RoadGraph
from agvsim.master.pace import SAMPLE_CAP, Pace
from agvsim.master.run import InProcessRun
from agvsim.master.traffic import Reservations, Stop, plan_route
from agvsim.scenario import parse_scenario
from agvsim.world.lif import save_lif

T = "agv"
ROOT = Path(__file__).resolve().parents[1]


def test_no_scale_before_enough_samples() -> None:
    p = Pace(min_samples=3)
    p.add(4.0, 2.0)
    p.add(4.0, 2.0)
    assert p.scale == 1.0  # two samples: not yet
    p.add(4.0, 2.0)
    assert p.scale == pytest.approx(2.0)


def test_recent_samples_weigh_more() -> None:
    # memory 2: each sum is halved before a sample is added
    p = Pace(min_samples=1, memory=2.0)
    p.add(3.0, 2.0)  # taken 3, graph 2
    p.add(2.0, 2.0)  # taken 1.5 + 2 = 3.5, graph 1 + 2 = 3
    assert p.taken_s == pytest.approx(3.5) and p.graph_s == pytest.approx(3.0)
    assert p.scale == pytest.approx(3.5 / 3.0)


def test_a_stop_mid_edge_counts_at_most_the_cap_and_scale_is_bounded() -> None:
    p = Pace(min_samples=1, memory=1e9, max_scale=2.5)
    p.add(100.0, 1.0)  # a vehicle that stood on the edge: counted as SAMPLE_CAP x
    assert p.taken_s == pytest.approx(SAMPLE_CAP)
    assert p.scale == 2.5  # never above max_scale
    q = Pace(min_samples=1)
    q.add(1.0, 2.0)  # faster than the graph: never planned faster than the graph
    assert q.scale == 1.0
    q.add(float("nan"), 1.0)
    q.add(1.0, 0.0)
    assert q.samples == 1  # nonsense is not a sample


def test_routes_are_planned_with_scaled_travel_times() -> None:
    g = RoadGraph(grid(4, 1), T, 1.0)  # 0,0 - 1,0 - 2,0 - 3,0, 1 m at 1 m/s
    base = plan_route(g, Reservations(margin_s=0.0), "A", "0,0", 10.0, [Stop("3,0", 2.0)])
    slow = plan_route(
        g, Reservations(margin_s=0.0), "A", "0,0", 10.0, [Stop("3,0", 2.0)], time_scale=1.5
    )
    assert [s.node for s in slow] == [s.node for s in base]
    assert [s.arrive_s for s in base] == pytest.approx([10.0, 11.0, 12.0, 13.0])
    assert [s.arrive_s for s in slow] == pytest.approx([10.0, 11.5, 13.0, 14.5])


def test_scaled_times_can_change_the_route() -> None:
    # a -> c direct at 0.5 m/s (2 m: 4 s), or a -> b -> c at 1 m/s (2 x 1.41 m: 2.83 s):
    # scaling every time keeps the detour the quicker one
    lay = layout(
        {"a": (0, 0), "b": (1, 1), "c": (2, 0)}, [("a", "c", 0.5), ("a", "b", 1.0), ("b", "c", 1.0)]
    )
    g = RoadGraph(lay, T, 1.0)
    r = plan_route(g, Reservations(margin_s=0.0), "A", "a", 0.0, [Stop("c")], time_scale=2.0)
    assert [s.node for s in r] == ["a", "b", "c"]
    assert r[-1].arrive_s == pytest.approx(2.0 * 2.0 * np.sqrt(2.0))


def lateness(run: InProcessRun) -> list[float]:
    """For every vehicle with an order: how far behind its plan (s) at its next node."""
    out = []
    for a in run.master.agvs.values():
        if not a.order_done and not a.broken:
            nxt = a.route[min(a.reached + 1, len(a.route) - 1)]
            out.append(run.t_s - nxt.arrive_s)
    return out


def grid_fleet(n: int, seconds: float, rate_per_vehicle_h: float, tmp: Path) -> InProcessRun:
    """``n`` vehicles on a 16 x 10 road grid, nodes 2 m apart (benchmarks/bench_master.py's
    generated warehouse, small): many turns, so the vehicles take longer than the graph."""
    spec = importlib.util.spec_from_file_location(
        "bench_master", ROOT / "benchmarks" / "bench_master.py"
    )
    bm = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(bm)  # type: ignore[union-attr]
    lay = bm.big_warehouse(16, 10)
    save_lif(tmp / "big.lif.json", [lay])
    sc = parse_scenario(bm.scenario(tmp, lay, n, seconds, rate_per_vehicle_h), "grid")
    sc._base_dir = tmp
    return InProcessRun(sc, master_period_s=0.5)


def test_the_fleet_learns_its_pace_and_runs_closer_to_plan(monkeypatch, tmp_path) -> None:
    runs = {}
    for learn in (True, False):
        if not learn:  # the graph's own times, as before the pace was learnt
            monkeypatch.setattr(Pace, "scale", property(lambda self: 1.0))
        r = grid_fleet(30, 300.0, 20.0, tmp_path)
        late: list[float] = []
        while r.t_s < 300 - 1e-9:
            r.step()
            if round(r.t_s / r.fleet.sim.dt_s) % 50 == 0:  # every 5 s
                late += lateness(r)
        runs[learn] = (r.summary(), np.array(late))
    learnt, plain = runs[True][0], runs[False][0]
    (pace,) = learnt["plan_pace"].values()
    assert pace["samples"] > 200
    # on a grid of 2 m edges the vehicles take longer than length / top speed (turns)
    assert 1.05 < pace["scale"] < 1.6
    assert (learnt["collisions"], learnt["deadlocks"]) == (0, 0)
    assert learnt["orders_completed"] >= plain["orders_completed"]
    # planned with the learnt pace, vehicles are closer to their plans and seldom so late
    # that they must be re-planned
    assert np.median(runs[True][1]) < np.median(runs[False][1])
    assert learnt["late_replans"] < plain["late_replans"] / 2


def test_where_vehicles_keep_to_the_graph_times_nothing_changes() -> None:
    """On the example warehouse the vehicles are as quick as the graph says (long straight
    edges): the learnt scale stays 1 and the routes are the ones planned without it."""
    cfg = MasterConfig(generate=GenerateConfig(rate_per_h=500))
    r = InProcessRun(warehouse(6, cfg), seed=4, duration_s=200, master_period_s=0.25)
    r.run()
    (pace,) = r.summary()["plan_pace"].values()
    assert pace["samples"] > 100 and pace["scale"] == 1.0
