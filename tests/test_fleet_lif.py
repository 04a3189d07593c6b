"""LIF layouts: reading with clear errors, NURBS geometry, deriving from grids, exporting."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.world.lif import (
    LifError,
    Nurbs,
    layout_from_grid,
    lif_document,
    load_lif,
    parse_lif,
    save_lif,
    schema_problems,
)
from agvsim.world.mazes import random_maze, thesis_maze

from helpers import walled_room

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def small_doc() -> dict:
    def node(nid, x, y, actions=()):
        props = (
            {"vehicleTypeId": "t1", "actions": list(actions)}
            if actions
            else {"vehicleTypeId": "t1"}
        )
        return {
            "nodeId": nid,
            "nodePosition": {"x": x, "y": y},
            "vehicleTypeNodeProperties": [props],
        }

    def edge(eid, a, b, **props):
        return {
            "edgeId": eid,
            "startNodeId": a,
            "endNodeId": b,
            "vehicleTypeEdgeProperties": [{"vehicleTypeId": "t1", "rotationAllowed": True} | props],
        }

    return {
        "metaInformation": {
            "projectIdentification": "p",
            "creator": "c",
            "exportTimestamp": "2026-01-01T00:00:00.00Z",
            "lifVersion": "1.0.0",
        },
        "layouts": [
            {
                "layoutId": "hall",
                "layoutVersion": "3",
                "nodes": [
                    node("a", 0, 0),
                    node("b", 2, 0),
                    node("c", 2, 2, [{"actionType": "startCharging", "blockingType": "HARD"}]),
                ],
                "edges": [edge("a-b", "a", "b", maxSpeed=0.8), edge("b-c", "b", "c")],
                "stations": [
                    {
                        "stationId": "charger",
                        "interactionNodeIds": ["c"],
                        "stationPosition": {"x": 2.5, "y": 2, "theta": 0.0},
                    }
                ],
            }
        ],
    }


def test_reads_nodes_edges_stations(tmp_path: Path) -> None:
    p = tmp_path / "l.json"
    p.write_text(json.dumps(small_doc()))
    (lay,) = load_lif(p)
    assert lay.layout_id == "hall" and lay.version == "3"
    assert lay.node_xy("b") == (2.0, 0.0)
    assert lay.edges["a-b"].types["t1"].max_speed_m_s == 0.8
    assert lay.edges["b-c"].types["t1"].max_speed_m_s is None
    assert lay.stations["charger"].interaction_node_ids == ("c",)
    assert lay.nodes["c"].types["t1"].actions[0]["actionType"] == "startCharging"
    assert lay.edge_between("b", "c").edge_id == "b-c" and lay.edge_between("c", "b") is None


def test_schema_errors_name_the_json_path() -> None:
    doc = small_doc()
    del doc["layouts"][0]["nodes"][1]["nodePosition"]
    doc["layouts"][0]["edges"][0]["vehicleTypeEdgeProperties"][0]["rotationAllowed"] = "yes"
    with pytest.raises(LifError) as e:
        parse_lif(doc, "hall.json")
    text = str(e.value)
    assert "hall.json" in text
    assert 'layouts[0].nodes[1]: "nodePosition" is a required property' in text
    assert 'layouts[0].edges[0].vehicleTypeEdgeProperties[0].rotationAllowed: "yes"' in text


def test_graph_errors_beyond_the_schema() -> None:
    doc = small_doc()
    lay = doc["layouts"][0]
    lay["edges"][1]["endNodeId"] = "zz"
    lay["nodes"][2]["nodeId"] = "a"  # duplicate
    lay["stations"][0]["interactionNodeIds"] = ["nowhere"]
    with pytest.raises(LifError) as e:
        parse_lif(doc)
    probs = e.value.problems
    assert "layouts[0].nodes[2].nodeId: 'a' is used twice" in probs
    assert "layouts[0].edges[1].endNodeId: 'zz' is not a node of layout 'hall'" in probs
    assert any(
        p.startswith("layouts[0].stations[0].interactionNodeIds[0]: 'nowhere'") for p in probs
    )


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_a_speed_limit_no_vehicle_can_drive_at_is_refused(bad: float) -> None:
    # the schema only asks for a number; a master dividing an edge's length by it (found by
    # the fleet fuzz test: maxSpeed 0 crashed the route tables) must never see one
    doc = small_doc()
    lay = doc["layouts"][0]
    lay["edges"][0]["vehicleTypeEdgeProperties"][0]["maxSpeed"] = bad
    lay["edges"][1]["vehicleTypeEdgeProperties"][0]["maxRotationSpeed"] = bad
    with pytest.raises(LifError) as e:
        parse_lif(doc)
    probs = e.value.problems
    assert any(
        p.startswith("layouts[0].edges[0].vehicleTypeEdgeProperties[0].maxSpeed: ") for p in probs
    )
    assert any(
        p.startswith("layouts[0].edges[1].vehicleTypeEdgeProperties[0].maxRotationSpeed: ")
        for p in probs
    )
    assert len(probs) == 2


def test_bad_json_gives_the_line(tmp_path: Path) -> None:
    p = tmp_path / "bad.json"
    p.write_text('{\n  "metaInformation": {,\n}')
    with pytest.raises(LifError, match="line 2: not valid JSON"):
        load_lif(p)
    with pytest.raises(LifError, match="no such file"):
        load_lif(tmp_path / "missing.json")


def test_nurbs_quarter_circle_is_exact() -> None:
    # a rational quadratic with weights 1, sqrt(2)/2, 1 is exactly a 90 degree arc
    w = math.sqrt(0.5)
    arc = Nurbs(2, (0, 0, 0, 1, 1, 1), ((1, 0, 1), (1, 1, w), (0, 1, 1)))
    pts = arc.sample(50)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 1.0, atol=1e-12)
    np.testing.assert_allclose(pts[0], (1, 0), atol=1e-12)
    np.testing.assert_allclose(pts[-1], (0, 1), atol=1e-12)
    line = Nurbs(1, (0, 0, 1, 1), ((0, 0, 1), (3, 4, 1))).sample(5)
    np.testing.assert_allclose(line, [[0, 0], [0.75, 1], [1.5, 2], [2.25, 3], [3, 4]])


def test_nurbs_knot_vector_checked() -> None:
    doc = small_doc()
    doc["layouts"][0]["edges"][0]["vehicleTypeEdgeProperties"][0]["trajectory"] = {
        "degree": 2,
        "knotVector": [0, 0, 1, 1],
        "controlPoints": [{"x": 0, "y": 0}, {"x": 1, "y": 1}, {"x": 2, "y": 0}],
    }
    with pytest.raises(
        LifError,
        match=r"edges\[0\].vehicleTypeEdgeProperties\[0\].trajectory: "
        r"knotVector has 4 values; 3 control points of degree 2 "
        r"need 6",
    ):
        parse_lif(doc)


def test_derive_from_grid_counts() -> None:
    # walled 5 x 8 room: 3 x 6 free cells; 3*5 + 2*6 = 27 neighbour pairs, an edge each way
    lay = layout_from_grid(walled_room(5, 8), ["t"])
    assert len(lay.nodes) == 18 and len(lay.edges) == 54
    assert lay.node_xy("r1c1") == (1.5, 3.5)  # row 1 is the top free row (y = 3.5)
    assert lay.edges["r1c1-r1c2"].start == "r1c1" and "r1c2-r1c1" in lay.edges


def test_derive_simplify_keeps_turns_and_junctions() -> None:
    # the thesis maze's corridors are two cells wide or more: no cell runs straight
    c1 = thesis_maze("thesis_c1")
    assert len(layout_from_grid(c1, ["t"], simplify=True).nodes) == int((~c1.occupied).sum())
    grid = random_maze(5, 5, 3, corridor_cells=1)
    full = layout_from_grid(grid, ["t"])
    simple = layout_from_grid(grid, ["t"], simplify=True)
    assert len(full.nodes) == int((~grid.occupied).sum())
    assert 0 < len(simple.nodes) < len(full.nodes)
    for e in simple.edges.values():  # every edge is axis-aligned
        (x0, y0), (x1, y1) = simple.node_xy(e.start), simple.node_xy(e.end)
        assert x0 == x1 or y0 == y1


def _components(lay) -> int:
    parent = {n: n for n in lay.nodes}

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    for e in lay.edges.values():
        parent[find(e.start)] = find(e.end)
    return len({find(n) for n in lay.nodes})


@settings(max_examples=25, deadline=None)
@given(st.integers(2, 6), st.integers(2, 6), st.integers(0, 10_000), st.floats(0, 0.5))
def test_derived_edges_run_on_free_floor(rows: int, cols: int, seed: int, loops: float) -> None:
    grid = random_maze(rows, cols, seed, corridor_cells=1 + seed % 2, loop_fraction=loops)
    full = layout_from_grid(grid, ["t"])
    simple = layout_from_grid(grid, ["t"], simplify=True)
    assert _components(simple) == _components(full) == 1
    for e in simple.edges.values():
        a, b = np.array(simple.node_xy(e.start)), np.array(simple.node_xy(e.end))
        pts = a + np.linspace(0, 1, 41)[:, None] * (b - a)
        assert not grid.is_occupied_at(pts[:, 0], pts[:, 1]).any()


def test_export_round_trip(tmp_path: Path) -> None:
    (lay,) = parse_lif(small_doc())
    doc = lif_document([lay], project="round trip")
    assert schema_problems(doc) == []
    (back,) = load_lif(save_lif(tmp_path / "out.json", [lay]))
    assert back == lay
    derived = layout_from_grid(walled_room(4, 4), ["a", "b"], "room", simplify=False)
    (back2,) = load_lif(save_lif(tmp_path / "d.json", [derived]))
    assert back2.nodes == derived.nodes and back2.edges == derived.edges


def test_the_warehouse_layout_loads() -> None:
    (lay,) = load_lif(SCENARIOS / "fleet_warehouse.lif.json")
    assert len(lay.stations) >= 6
    chargers = [
        n
        for n in lay.nodes.values()
        if any(a["actionType"] == "startCharging" for p in n.types.values() for a in p.actions)
    ]
    assert len(chargers) >= 2


def test_layout_geometry_for_the_app() -> None:
    from agvsim.fleet.viz import draw_layout, layout_geometry

    (lay,) = parse_lif(small_doc())
    g = layout_geometry(lay)
    # a-b and b-c are straight, one segment each, on the floor
    np.testing.assert_allclose(g.segments[:, :, :2], [[[0, 0], [2, 0]], [[2, 0], [2, 2]]])
    assert g.nodes.shape == (3, 3) and g.station_names == ("charger",)
    np.testing.assert_allclose(g.stations[0, :2], (2.5, 2.0))
    w = math.sqrt(2.0)  # (1, sqrt(1/2), 1) scaled by sqrt(2): LIF wants weights >= 1
    doc = small_doc()
    doc["layouts"][0]["edges"][1]["vehicleTypeEdgeProperties"][0]["trajectory"] = {
        "degree": 2,
        "knotVector": [0, 0, 0, 1, 1, 1],
        "controlPoints": [
            {"x": 2, "y": 0, "weight": w},
            {"x": 4, "y": 0},
            {"x": 4, "y": 2, "weight": w},
        ],
    }
    (curved,) = parse_lif(doc)
    g2 = layout_geometry(curved, samples=16)
    assert len(g2.segments) == 1 + 16
    arc = g2.segments[1:, 0, :2]  # a quarter circle of radius 2 about (2, 2)
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 2, arc[:, 1] - 2), 2.0, atol=1e-5)
    calls = []

    class Scene:
        def __getattr__(self, name):
            return lambda *a, **k: calls.append((name, a[0]))

    draw_layout(Scene(), curved)
    assert [c[0] for c in calls] == [
        "add_line_segments",
        "add_point_cloud",
        "add_point_cloud",
        "add_label",
    ]
