"""Write scenarios/fleet_warehouse.lif.json and scenarios/fleet_warehouse.yaml: a 32 x 22 m
hall with six racks, three roads joined by four aisles, rack stations on the roads, a charging
lane with four chargers, parking spurs off the outer roads, and 20 vehicles of the five models
parked there (off the roads, facing them). The car-like vehicles (Ackermann: they cannot turn on
the spot) park on drive-through bays (P09, P11, P13: entered from the road node on one side and
left to the one on the other), since a dead-end spur is one they could enter but never leave.

    python examples/fleet/make_warehouse.py
"""

from __future__ import annotations

from pathlib import Path

from agvsim.world.lif import Edge, EdgeProps, Layout, Node, NodeProps, Station, save_lif

OUT = Path(__file__).resolve().parents[2] / "scenarios"
MODELS = (
    ["differential"] * 6 + ["tricycle"] * 4 + ["ackermann"] * 3 + ["mecanum"] * 4 + ["omni3"] * 3
)
TYPES = [f"agvsim.{m}" for m in ("differential", "tricycle", "ackermann", "mecanum", "omni3")]
XS = list(range(-13, 14, 2))  # road node x positions (m)
ROADS = {"A": 6.5, "B": 0.0, "C": -6.5}
AISLES = {"V1": -13, "V2": -5, "V3": 5, "V4": 13}
PARK_SOUTH = [1, 3, 5, 7, 9, 11, 13]
DRIVE_THROUGH = [9, 11, 13]  # P09, P11, P13: bays that car-likes enter and leave going forward
CAR_LIKE = ("agvsim.tricycle", "agvsim.ackermann")
RACKS = [(x, y) for y in (3.25, -3.25) for x in (-9.0, 0.0, 9.0)]  # centres; 5 m x 1.2 m


def build() -> Layout:
    charge = (
        {"actionType": "startCharging", "blockingType": "HARD", "requirementType": "OPTIONAL"},
    )
    load = tuple(
        {"actionType": k, "blockingType": "HARD", "requirementType": "OPTIONAL"}
        for k in ("pick", "drop")
    )
    nodes: dict[str, Node] = {}

    def node(nid: str, x: float, y: float, actions: tuple = ()) -> None:
        nodes[nid] = Node(nid, x, y, {t: NodeProps(None, actions) for t in TYPES})

    for road, y in ROADS.items():
        for k, x in enumerate(XS):
            node(f"{road}{k + 1:02d}", x, y, load if x in (-9, -1, 1, 9) else ())
    for a, x in AISLES.items():
        node(f"{a}n", x, 3.25)
        node(f"{a}s", x, -3.25)
    for k, x in enumerate(XS):  # parking above road A
        node(f"P{k + 1:02d}", x, 8.75)
    for k, x in enumerate(PARK_SOUTH):  # parking below road C
        node(f"Q{k + 1}", x, -8.75)
    node("L0", -13, -8.5)
    for k, x in enumerate((-11, -9, -7, -5)):
        node(f"CH{k + 1}", x, -8.5, charge)
    edges: dict[str, Edge] = {}

    def both(a: str, b: str, speed: float) -> None:
        for s, e in ((a, b), (b, a)):
            edges[f"{s}-{e}"] = Edge(f"{s}-{e}", s, e, {t: EdgeProps(True, speed) for t in TYPES})

    for road in ROADS:
        for k in range(len(XS) - 1):
            both(f"{road}{k + 1:02d}", f"{road}{k + 2:02d}", 1.0)
    for a, x in AISLES.items():
        k = XS.index(x) + 1
        both(f"A{k:02d}", f"{a}n", 0.6)
        both(f"{a}n", f"B{k:02d}", 0.6)
        both(f"B{k:02d}", f"{a}s", 0.6)
        both(f"{a}s", f"C{k:02d}", 0.6)
    for k in range(len(XS)):
        both(f"A{k + 1:02d}", f"P{k + 1:02d}", 0.5)
    for k in DRIVE_THROUGH:  # diagonals A(k-1) - Pk - A(k+1), for the steered types
        for a, b in ((f"A{k - 1:02d}", f"P{k:02d}"), (f"P{k:02d}", f"A{k + 1:02d}")):
            for s, e in ((a, b), (b, a)):
                props = {t: EdgeProps(True, 0.5) for t in CAR_LIKE}
                edges[f"{s}-{e}"] = Edge(f"{s}-{e}", s, e, props)
    for k, x in enumerate(PARK_SOUTH):
        both(f"C{XS.index(x) + 1:02d}", f"Q{k + 1}", 0.5)
    both("C01", "L0", 0.3)
    both("L0", "CH1", 0.3)
    for k in range(1, 4):
        both(f"CH{k}", f"CH{k + 1}", 0.3)
    both("CH4", f"C{XS.index(-5) + 1:02d}", 0.3)
    stations: dict[str, Station] = {}
    for k, (x, y) in enumerate(RACKS):
        road_near = ("A", "B") if y > 0 else ("B", "C")
        for road in road_near:
            nid = f"{road}{XS.index(int(x) if x != 0 else -1) + 1:02d}"
            sid = f"rack{k + 1}-{road}"
            stations[sid] = Station(
                sid, (nid,), f"rack {k + 1} from road {road}", pose=(x, y, 0.0), height_m=0.0
            )
    for k in range(4):
        stations[f"charger{k + 1}"] = Station(
            f"charger{k + 1}", (f"CH{k + 1}",), f"charger {k + 1}"
        )
    return Layout(
        "warehouse",
        nodes,
        edges,
        stations,
        "Warehouse hall",
        "1",
        description="three roads, four aisles, six racks, four chargers",
    )


def scenario(layout: Layout) -> str:
    # tricycles on P07, P08, P10, P12; the Ackermann vehicles on the drive-through bays
    north = [1, 2, 3, 4, 5, 6, 7, 8, 10, 12, *DRIVE_THROUGH, 14]
    starts = [f"P{k:02d}" for k in north] + [f"Q{k}" for k in range(1, 7)]
    params = {
        "differential": "{wheel_radius_m: 0.1, half_track_m: 0.22}",
        "tricycle": "{wheel_radius_m: 0.1, wheelbase_m: 0.5, half_track_m: 0.2}",
        "ackermann": "{wheel_radius_m: 0.1, wheelbase_m: 0.5, half_track_m: 0.2}",
        "mecanum": "{wheel_radius_m: 0.05, half_length_m: 0.2, half_width_m: 0.2}",
        "omni3": "{wheel_radius_m: 0.05, base_radius_m: 0.2}",
    }
    colors = {
        "differential": "#d62728",
        "tricycle": "#1f77b4",
        "ackermann": "#2ca02c",
        "mecanum": "#9467bd",
        "omni3": "#ff7f0e",
    }
    rows = ["#" * 32] + ["#" + "." * 30 + "#" for _ in range(20)] + ["#" * 32]
    lines = [
        "# Generated by examples/fleet/make_warehouse.py: a warehouse hall on a LIF layout with",
        "# 20 VDA 5050 vehicles of the five models, parked on layout nodes, waiting for orders.",
        "name: Warehouse fleet (VDA 5050 on a LIF layout)",
        "seed: 0",
        "duration_s: 600",
        "dt_s: 0.05",
        "world:",
        "  cell_size_m: 1.0",
        "  picture: |",
        *[f"    {r}" for r in rows],
        "  boxes:  # racks",
        *[f"    - {{x_m: {x}, y_m: {y}, length_m: 5.0, width_m: 1.2}}" for x, y in RACKS],
        "layout: {file: fleet_warehouse.lif.json}",
        "robots:",
    ]
    for k, (model, start) in enumerate(zip(MODELS, starts, strict=True)):
        x, y = layout.node_xy(start)
        lines += [
            f"  - name: agv{k + 1:02d}",
            f"    model: {model}",
            f"    params: {params[model]}",
            "    body: {length_m: 0.6, width_m: 0.45}",
            f"    pose: {{x_m: {x}, y_m: {y}, theta_deg: {-90 if y > 0 else 90}}}",
            f'    color: "{colors[model]}"',
            "    sensors:",
            "      - {type: lidar, beams: 91, fov_deg: 270, range_max_m: 5.0, rate_hz: 10}",
        ]
    lines += ["vda5050:", "  version: 2.1.0", "  manufacturer: agvsim", "  vehicles:"]
    for k, start in enumerate(starts):
        lines.append(f"    - {{robot: agv{k + 1:02d}, start_node: {start}}}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    lay = build()
    save_lif(OUT / "fleet_warehouse.lif.json", [lay], project="agvsim warehouse")
    (OUT / "fleet_warehouse.yaml").write_text(scenario(lay), encoding="utf-8")
    print(f"{len(lay.nodes)} nodes, {len(lay.edges)} edges, {len(lay.stations)} stations")
