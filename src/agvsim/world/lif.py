"""Track layouts in VDMA's Layout Interchange Format (LIF): read, validate, derive, export.

A LIF file holds one or more layouts; each layout is a directed graph of **nodes** (positions
in the world frame, m) and **edges** (start node -> end node), with per-vehicle-type properties
(max speed m/s, orientation rad, rotation allowed, a NURBS trajectory) and **stations** (the
nodes a vehicle stands on to interact with a rack, a conveyor or a charger). LIF coordinates are
agvsim's world frame.

* ``load_lif(path)`` reads a file, validates it against the official ``LIF.schema`` (shipped in
  ``agvsim/data/lif``) and then checks what the schema cannot (unique ids, edges and stations
  naming nodes that exist, NURBS knot vectors of the right length). Every fault is one line
  naming its JSON path: ``layouts[0].edges[3].startNodeId: 'n9' is not a node of ...``.
* ``layout_from_grid(grid, ...)`` derives a layout from an occupancy grid: a node at the
  centre of every free cell (or only at corridor junctions, corners and dead ends with
  ``simplify=True``) and an edge each way between 4-neighbours.
* ``lif_document(layouts)`` / ``save_lif(path, layouts)`` export any layout as LIF.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import BSpline

from agvsim.world.grid import OccupancyGrid

LIF_VERSION = "1.0.0"


class LifError(ValueError):
    """A LIF file that cannot be used; ``problems`` holds one line per fault (with its path)."""

    def __init__(self, source: str, problems: list[str]):
        self.source, self.problems = source, problems
        super().__init__(f"{source}: " + "; ".join(problems))

    def __str__(self) -> str:
        lines = "\n".join(f"  - {p}" for p in self.problems)
        return f"{self.source} is not a valid LIF layout:\n{lines}"


# ---------------------------------------------------------------------------------- model
@dataclass(frozen=True)
class Nurbs:
    """A NURBS curve as VDA 5050 and LIF give it: ``degree``, a knot vector in [0, 1] of
    ``len(control points) + degree + 1`` values, control points (x m, y m, weight)."""

    degree: int
    knots: tuple[float, ...]
    control_points: tuple[tuple[float, float, float], ...]

    def sample(self, n: int = 64) -> np.ndarray:
        """(n, 2) points along the curve, evenly spaced in the curve parameter."""
        cp = np.asarray(self.control_points, dtype=np.float64)
        t = np.asarray(self.knots, dtype=np.float64)
        k = self.degree
        u = np.linspace(t[k], t[-k - 1], n)
        w = cp[:, 2]
        homog = BSpline(t, np.column_stack([cp[:, 0] * w, cp[:, 1] * w, w]), k)(u)
        return homog[:, :2] / homog[:, 2:3]

    def to_json(self) -> dict:
        return {
            "degree": self.degree,
            "knotVector": list(self.knots),
            "controlPoints": [{"x": x, "y": y, "weight": w} for x, y, w in self.control_points],
        }

    @classmethod
    def from_json(cls, d: dict) -> Nurbs:
        return cls(
            int(d.get("degree", 1)),
            tuple(float(v) for v in d["knotVector"]),
            tuple(
                (float(p["x"]), float(p["y"]), float(p.get("weight", 1.0)))
                for p in d["controlPoints"]
            ),
        )

    def problem(self) -> str | None:
        """Why the curve cannot be evaluated, or None."""
        n, k = len(self.control_points), self.degree
        if k < 1:
            return f"degree must be >= 1, got {k}"
        if n < k + 1:
            return f"a degree-{k} curve needs at least {k + 1} control points, got {n}"
        if len(self.knots) != n + k + 1:
            return (
                f"knotVector has {len(self.knots)} values; {n} control points of degree {k} "
                f"need {n + k + 1}"
            )
        if any(b < a for a, b in zip(self.knots, self.knots[1:], strict=False)):
            return "knotVector must not decrease"
        if any(w <= 0 for _, _, w in self.control_points):
            return "control point weights must be > 0"
        return None


@dataclass(frozen=True)
class NodeProps:
    """What one vehicle type may do on a node."""

    theta_rad: float | None = None
    actions: tuple[dict, ...] = ()


@dataclass(frozen=True)
class EdgeProps:
    """What one vehicle type may do on an edge (None: not limited by the layout)."""

    rotation_allowed: bool = True
    max_speed_m_s: float | None = None
    max_rotation_speed_rad_s: float | None = None
    orientation_rad: float | None = None
    orientation_type: str = "TANGENTIAL"
    trajectory: Nurbs | None = None
    actions: tuple[dict, ...] = ()


@dataclass(frozen=True)
class Node:
    node_id: str
    x_m: float
    y_m: float
    types: dict[str, NodeProps]  # vehicleTypeId -> properties
    name: str = ""
    map_id: str = ""


@dataclass(frozen=True)
class Edge:
    edge_id: str
    start: str  # node id
    end: str  # node id
    types: dict[str, EdgeProps]  # vehicleTypeId -> properties
    name: str = ""


@dataclass(frozen=True)
class Station:
    station_id: str
    interaction_node_ids: tuple[str, ...]
    name: str = ""
    description: str = ""
    pose: tuple[float, float, float] | None = None  # x m, y m, theta rad
    height_m: float | None = None


@dataclass(frozen=True)
class Layout:
    layout_id: str
    nodes: dict[str, Node]
    edges: dict[str, Edge]
    stations: dict[str, Station] = field(default_factory=dict)
    name: str = ""
    version: str = "1"
    level_id: str = ""
    description: str = ""

    def node_xy(self, node_id: str) -> tuple[float, float]:
        n = self.nodes[node_id]
        return n.x_m, n.y_m

    def edge_between(self, start: str, end: str) -> Edge | None:
        for e in self.edges.values():
            if e.start == start and e.end == end:
                return e
        return None

    @property
    def vehicle_types(self) -> list[str]:
        seen: dict[str, None] = {}
        for n in self.nodes.values():
            seen.update(dict.fromkeys(n.types))
        return list(seen)


# ---------------------------------------------------------------------------------- reading
@cache
def lif_schema() -> dict:
    """The official LIF JSON schema (draft-07), shipped with agvsim."""
    text = (resources.files("agvsim") / "data" / "lif" / "LIF.schema").read_text("utf-8")
    return dict(json.loads(text))


def json_path(parts: Any) -> str:
    """``layouts[0].nodes[2].nodePosition`` from a jsonschema error path."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


@cache
def _validator() -> Any:
    import jsonschema_rs

    return jsonschema_rs.validator_for(lif_schema())


def schema_problems(doc: Any, limit: int = 50) -> list[str]:
    """Every violation of the LIF schema, one line each with its JSON path (jsonschema-rs:
    a layout of thousands of nodes is checked in milliseconds)."""
    out = []
    for e in _validator().iter_errors(doc):
        out.append(f"{json_path(e.instance_path)}: {e.message}")
        if len(out) >= limit:
            break
    return sorted(out)


def load_lif(path: str | Path) -> list[Layout]:
    """The layouts of a LIF file, validated (raises ``LifError`` naming each fault)."""
    path = Path(path)
    if not path.is_file():
        raise LifError(str(path), ["no such file"])
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise LifError(str(path), [f"line {err.lineno}: not valid JSON ({err.msg})"]) from None
    except UnicodeDecodeError as err:
        raise LifError(str(path), [f"not UTF-8 text ({err.reason})"]) from None
    return parse_lif(doc, str(path))


def parse_lif(doc: Any, source: str = "LIF") -> list[Layout]:
    """Layouts from a parsed LIF document; schema first, then the graph's consistency."""
    problems = schema_problems(doc)
    if problems:
        raise LifError(source, problems)
    layouts, problems = [], []
    node_ids: set[str] = set()
    edge_ids: set[str] = set()
    for li, lay in enumerate(doc["layouts"]):
        where = f"layouts[{li}]"
        nodes: dict[str, Node] = {}
        for ni, n in enumerate(lay["nodes"]):
            nid = n["nodeId"]
            if nid in node_ids:
                problems.append(f"{where}.nodes[{ni}].nodeId: {nid!r} is used twice")
            node_ids.add(nid)
            pos = n["nodePosition"]
            if not (math.isfinite(pos["x"]) and math.isfinite(pos["y"])):
                problems.append(f"{where}.nodes[{ni}].nodePosition: not finite numbers")
            for pi, p in enumerate(n["vehicleTypeNodeProperties"]):
                if p.get("theta") is not None and not math.isfinite(p["theta"]):
                    problems.append(
                        f"{where}.nodes[{ni}].vehicleTypeNodeProperties[{pi}].theta: "
                        f"{p['theta']!r} is not a finite angle (rad)"
                    )
            nodes[nid] = Node(
                nid,
                float(pos["x"]),
                float(pos["y"]),
                {
                    p["vehicleTypeId"]: NodeProps(p.get("theta"), tuple(p.get("actions", ())))
                    for p in n["vehicleTypeNodeProperties"]
                },
                n.get("nodeName", ""),
                n.get("mapId", ""),
            )
        edges: dict[str, Edge] = {}
        for ei, e in enumerate(lay["edges"]):
            eid, at = e["edgeId"], f"{where}.edges[{ei}]"
            if eid in edge_ids:
                problems.append(f"{at}.edgeId: {eid!r} is used twice")
            edge_ids.add(eid)
            for key in ("startNodeId", "endNodeId"):
                if e[key] not in nodes:
                    problems.append(
                        f"{at}.{key}: {e[key]!r} is not a node of layout {lay['layoutId']!r}"
                    )
            types = {}
            for pi, p in enumerate(e["vehicleTypeEdgeProperties"]):
                traj = Nurbs.from_json(p["trajectory"]) if "trajectory" in p else None
                why = traj.problem() if traj is not None else None
                if why:
                    problems.append(f"{at}.vehicleTypeEdgeProperties[{pi}].trajectory: {why}")
                for key in ("maxSpeed", "maxRotationSpeed"):  # limits a vehicle can drive at
                    v = p.get(key)
                    if v is not None and not (math.isfinite(v) and v > 0):
                        problems.append(
                            f"{at}.vehicleTypeEdgeProperties[{pi}].{key}: {v!r} is no speed "
                            "limit (a finite number > 0; leave it out for none)"
                        )
                v = p.get("vehicleOrientation")
                if v is not None and not math.isfinite(v):
                    problems.append(
                        f"{at}.vehicleTypeEdgeProperties[{pi}].vehicleOrientation: {v!r} is not "
                        "a finite angle (rad)"
                    )
                types[p["vehicleTypeId"]] = EdgeProps(
                    bool(p["rotationAllowed"]),
                    p.get("maxSpeed"),
                    p.get("maxRotationSpeed"),
                    p.get("vehicleOrientation"),
                    p.get("orientationType", "TANGENTIAL"),
                    traj,
                    tuple(p.get("actions", ())),
                )
            edges[eid] = Edge(eid, e["startNodeId"], e["endNodeId"], types, e.get("edgeName", ""))
        stations: dict[str, Station] = {}
        for si, s in enumerate(lay["stations"]):
            for k, nid in enumerate(s["interactionNodeIds"]):
                if nid not in nodes:
                    problems.append(
                        f"{where}.stations[{si}].interactionNodeIds[{k}]: {nid!r} is not a node "
                        f"of layout {lay['layoutId']!r}"
                    )
            sp = s.get("stationPosition")
            if sp is not None and not all(
                math.isfinite(sp.get(k, 0.0)) for k in ("x", "y", "theta")
            ):
                problems.append(f"{where}.stations[{si}].stationPosition: not finite numbers")
            stations[s["stationId"]] = Station(
                s["stationId"],
                tuple(s["interactionNodeIds"]),
                s.get("stationName", ""),
                s.get("stationDescription", ""),
                None if sp is None else (sp["x"], sp["y"], sp.get("theta", 0.0)),
                s.get("stationHeight"),
            )
        layouts.append(
            Layout(
                lay["layoutId"],
                nodes,
                edges,
                stations,
                lay.get("layoutName", ""),
                lay["layoutVersion"],
                lay.get("layoutLevelId", ""),
                lay.get("layoutDescription", ""),
            )
        )
    if problems:
        raise LifError(source, problems)
    return layouts


# ---------------------------------------------------------------------------------- export
def _drop_none(d: dict) -> dict:
    return {k: v for k, v in d.items() if v is not None and v != ""}


def layout_json(layout: Layout) -> dict:
    """One layout as a LIF ``layouts[]`` entry."""
    nodes = [
        _drop_none(
            {
                "nodeId": n.node_id,
                "nodeName": n.name,
                "mapId": n.map_id,
                "nodePosition": {"x": n.x_m, "y": n.y_m},
                "vehicleTypeNodeProperties": [
                    _drop_none(
                        {
                            "vehicleTypeId": t,
                            "theta": p.theta_rad,
                            "actions": list(p.actions) or None,
                        }
                    )
                    for t, p in n.types.items()
                ],
            }
        )
        for n in layout.nodes.values()
    ]
    edges = [
        _drop_none(
            {
                "edgeId": e.edge_id,
                "edgeName": e.name,
                "startNodeId": e.start,
                "endNodeId": e.end,
                "vehicleTypeEdgeProperties": [
                    _drop_none(
                        {
                            "vehicleTypeId": t,
                            "rotationAllowed": p.rotation_allowed,
                            "maxSpeed": p.max_speed_m_s,
                            "maxRotationSpeed": p.max_rotation_speed_rad_s,
                            "vehicleOrientation": p.orientation_rad,
                            "orientationType": p.orientation_type,
                            "trajectory": None if p.trajectory is None else p.trajectory.to_json(),
                            "actions": list(p.actions) or None,
                        }
                    )
                    for t, p in e.types.items()
                ],
            }
        )
        for e in layout.edges.values()
    ]
    stations = [
        _drop_none(
            {
                "stationId": s.station_id,
                "interactionNodeIds": list(s.interaction_node_ids),
                "stationName": s.name,
                "stationDescription": s.description,
                "stationHeight": s.height_m,
                "stationPosition": None
                if s.pose is None
                else {"x": s.pose[0], "y": s.pose[1], "theta": s.pose[2]},
            }
        )
        for s in layout.stations.values()
    ]
    return _drop_none(
        {
            "layoutId": layout.layout_id,
            "layoutName": layout.name,
            "layoutVersion": layout.version,
            "layoutLevelId": layout.level_id,
            "layoutDescription": layout.description,
            "nodes": nodes,
            "edges": edges,
            "stations": stations,
        }
    )


def lif_document(layouts: list[Layout], project: str = "agvsim", creator: str = "agvsim") -> dict:
    """A complete LIF document (validated against the schema before it is returned)."""
    stamp = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-4] + "Z"
    doc = {
        "metaInformation": {
            "projectIdentification": project,
            "creator": creator,
            "exportTimestamp": stamp,
            "lifVersion": LIF_VERSION,
        },
        "layouts": [layout_json(lay) for lay in layouts],
    }
    problems = schema_problems(doc)
    if problems:  # pragma: no cover - our own output; a failure here is a bug
        raise LifError("exported layout", problems)
    return doc


def save_lif(path: str | Path, layouts: list[Layout], project: str = "agvsim") -> Path:
    path = Path(path)
    path.write_text(json.dumps(lif_document(layouts, project), indent=2) + "\n", "utf-8")
    return path


# ---------------------------------------------------------------------------------- deriving
def _runs_straight(free: np.ndarray, r: int, c: int) -> bool:
    """A free cell with exactly two free 4-neighbours on opposite sides."""
    rows, cols = free.shape

    def f(rr: int, cc: int) -> bool:
        return 0 <= rr < rows and 0 <= cc < cols and bool(free[rr, cc])

    n, s, w, e = f(r - 1, c), f(r + 1, c), f(r, c - 1), f(r, c + 1)
    return (n and s and not w and not e) or (w and e and not n and not s)


def layout_from_grid(
    grid: OccupancyGrid,
    vehicle_types: list[str],
    layout_id: str = "grid",
    simplify: bool = False,
    max_speed_m_s: float | None = None,
) -> Layout:
    """A layout on the free cells of ``grid``: a node at every free cell centre (ids
    ``r{row}c{col}``) and an edge each way between 4-neighbouring free cells (ids
    ``{a}-{b}``). With ``simplify`` the nodes in the middle of straight corridor runs are
    dropped, so nodes remain at junctions, corners and dead ends and one edge spans each run.
    Every node and edge is open to every type in ``vehicle_types``."""
    if not vehicle_types:
        raise ValueError("vehicle_types: give at least one vehicle type id")
    free = ~grid.occupied
    keep = free.copy()
    if simplify:
        for r, c in zip(*np.nonzero(free), strict=True):
            if _runs_straight(free, int(r), int(c)):
                keep[r, c] = False
    node_props = {t: NodeProps() for t in vehicle_types}
    edge_props = {t: EdgeProps(True, max_speed_m_s) for t in vehicle_types}
    nodes: dict[str, Node] = {}
    for r, c in zip(*np.nonzero(keep), strict=True):
        x, y = grid.cell_center(int(r), int(c))
        nid = f"r{r}c{c}"
        nodes[nid] = Node(nid, round(float(x), 9), round(float(y), 9), node_props)
    edges: dict[str, Edge] = {}
    rows, cols = free.shape
    for r, c in zip(*np.nonzero(keep), strict=True):
        for dr, dc in ((0, 1), (1, 0)):  # walk east and south to the next kept cell
            rr, cc = int(r) + dr, int(c) + dc
            while 0 <= rr < rows and 0 <= cc < cols and free[rr, cc] and not keep[rr, cc]:
                rr, cc = rr + dr, cc + dc
            if not (0 <= rr < rows and 0 <= cc < cols and keep[rr, cc]):
                continue
            a, b = f"r{r}c{c}", f"r{rr}c{cc}"
            edges[f"{a}-{b}"] = Edge(f"{a}-{b}", a, b, edge_props)
            edges[f"{b}-{a}"] = Edge(f"{b}-{a}", b, a, edge_props)
    return Layout(layout_id, nodes, edges, {}, name=layout_id)
