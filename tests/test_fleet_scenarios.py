"""The shipped fleet scenarios: the warehouse (20 vehicles of five models on a LIF layout) and
the thesis maze C.1 derived as a layout, driven by routes planned on the layout graph."""

from __future__ import annotations

from collections import deque
from datetime import UTC, datetime
from pathlib import Path

import pytest
from fleet_helpers import order
from test_fleet_vehicle import Run

from agvsim.fleet.build import build_fleet
from agvsim.scenario import load_scenario
from agvsim.world.lif import Layout

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def route(layout: Layout, start: str, goal: str, avoid: frozenset = frozenset()) -> list[str]:
    """Fewest-edge route on the layout (breadth-first), not through the nodes in ``avoid``."""
    nxt: dict[str, list[str]] = {}
    for e in layout.edges.values():
        nxt.setdefault(e.start, []).append(e.end)
    prev: dict[str, str | None] = {start: None}
    todo = deque([start])
    while todo:
        n = todo.popleft()
        for m in sorted(nxt.get(n, [])):
            if m not in prev and m not in avoid:
                prev[m] = n
                todo.append(m)
    path, n2 = [], goal
    while n2 is not None:
        path.append(n2)
        n2 = prev[n2]
    return path[::-1]


def test_warehouse_vehicles_park_on_nodes() -> None:
    f = build_fleet(
        load_scenario(SCENARIOS / "fleet_warehouse.yaml"), epoch=datetime(2026, 1, 1, tzinfo=UTC)
    )
    assert len(f.vehicles) == 20
    kinds = {type(v.spec.model).__name__ for v in f.vehicles}
    assert kinds == {"DifferentialDrive", "Tricycle", "Ackermann", "Mecanum", "Omni3"}
    r = Run(f)
    r.step()
    for v in f.vehicles:
        s = r.states(v.cfg.serial)[-1]
        x, y = f.layout.node_xy(s["lastNodeId"])
        assert (s["agvPosition"]["x"], s["agvPosition"]["y"]) == (x, y)
        assert s["orderId"] == "" and not s["driving"]


def test_warehouse_pick_drop_and_back_to_parking() -> None:
    f = build_fleet(
        load_scenario(SCENARIOS / "fleet_warehouse.yaml"), epoch=datetime(2026, 1, 1, tzinfo=UTC)
    )
    r = Run(f)
    # agv01 (parked on P01) picks at rack 1 from road B, drops at rack 6 from road C, parks
    lay, v = f.layout, f.vehicle("agv01")
    nodes = route(lay, "P01", "B03") + route(lay, "B03", "C11")[1:] + route(lay, "C11", "P01")[1:]
    acts = {
        "B03": [{"actionId": "pk", "actionType": "pick", "blockingType": "HARD"}],
        "C11": [{"actionId": "dp", "actionType": "drop", "blockingType": "HARD"}],
    }
    v.receive("order", order(lay, nodes, serial="agv01", node_actions=acts))
    r.step()
    r.until(lambda: v.order_actions["dp"].status == "FINISHED", 120, "the drop")
    r.until(lambda: not v.route_nodes, 120, "back to P01")
    assert v.errors == [] and f.sim.state.collisions.sum() == 0


@pytest.mark.parametrize(
    ("serial", "goal"),
    [("diff", "r17c2"), ("tricycle", "r1c17"), ("ackermann", "r9c1"), ("mecanum", "r12c8")],
)
def test_thesis_maze_models_follow_routes(serial: str, goal: str) -> None:
    f = build_fleet(
        load_scenario(SCENARIOS / "fleet_thesis_maze.yaml"), epoch=datetime(2026, 1, 1, tzinfo=UTC)
    )
    r = Run(f)
    v = f.vehicle(serial)
    parked = frozenset(o.last_node.node_id for o in f.vehicles if o is not v)
    nodes = route(f.layout, v.last_node.node_id, goal, parked)
    assert len(nodes) >= 8
    v.receive("order", order(f.layout, nodes, serial=serial))
    r.step()
    r.until(lambda: v.last_node.node_id == goal and not v.route_nodes, 120, goal)
    assert f.sim.state.wall_collisions.sum() == 0


def test_the_fleet_page_examples_run() -> None:
    """Every ```python block of docs/fleet.md runs as written from the repository root."""
    import os
    import re

    root = SCENARIOS.parent
    text = (root / "docs" / "fleet.md").read_text(encoding="utf-8")
    blocks = re.findall(r"^```python\n(.*?)^```", text, re.S | re.M)
    assert blocks
    here = Path.cwd()
    os.chdir(root)
    try:
        for code in blocks:
            exec(compile(code, "docs/fleet.md", "exec"), {})
    finally:
        os.chdir(here)
