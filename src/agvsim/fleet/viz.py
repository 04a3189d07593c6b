"""Drawing a layout in the browser app's 3D scene: edges as line segments on the floor
(NURBS trajectories sampled), nodes as points, stations as labelled points. The app calls
``draw_layout(server.scene, layout)`` once the world is built; ``layout_geometry`` is the
plain-array part (tested without a browser)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agvsim.world.lif import Layout

FLOOR_Z_M = 0.01  # just above the floor, below the robots
EDGE_RGB = (40, 120, 220)
NODE_RGB = (20, 60, 160)
STATION_RGB = (230, 140, 20)


@dataclass(frozen=True)
class LayoutGeometry:
    segments: np.ndarray  # (S, 2, 3) float32 edge pieces, world frame
    nodes: np.ndarray  # (N, 3) float32
    stations: np.ndarray  # (K, 3) float32
    station_names: tuple[str, ...]


def layout_geometry(layout: Layout, samples: int = 16) -> LayoutGeometry:
    """Edges as floor segments (a NURBS of any vehicle type is drawn as ``samples`` pieces; an
    edge and its reverse share their segments), nodes and stations as points."""
    segs: list[np.ndarray] = []
    seen: set[tuple[str, str]] = set()
    for e in layout.edges.values():
        key = (min(e.start, e.end), max(e.start, e.end))
        traj = next((p.trajectory for p in e.types.values() if p.trajectory is not None), None)
        if traj is None and key in seen:
            continue
        seen.add(key)
        if traj is not None:
            xy = traj.sample(samples + 1)
        else:
            xy = np.array([layout.node_xy(e.start), layout.node_xy(e.end)])
        p = np.column_stack([xy, np.full(len(xy), FLOOR_Z_M)])
        segs.append(np.stack([p[:-1], p[1:]], axis=1))
    nodes = np.array([(n.x_m, n.y_m, FLOOR_Z_M) for n in layout.nodes.values()]).reshape(-1, 3)
    st_xy, names = [], []
    for s in layout.stations.values():
        x, y = s.pose[:2] if s.pose is not None else layout.node_xy(s.interaction_node_ids[0])
        st_xy.append((x, y, FLOOR_Z_M))
        names.append(s.name or s.station_id)
    return LayoutGeometry(
        np.concatenate(segs).astype(np.float32) if segs else np.zeros((0, 2, 3), np.float32),
        nodes.astype(np.float32),
        np.array(st_xy, dtype=np.float32).reshape(-1, 3),
        tuple(names),
    )


def draw_layout(scene: Any, layout: Layout, prefix: str = "/layout") -> list[Any]:
    """Add the layout to a viser scene (names under ``prefix``; drawing again replaces it).
    Returns the scene handles added (remove them to take the layout away)."""
    g = layout_geometry(layout)
    handles: list[Any] = []
    if len(g.segments):
        handles.append(
            scene.add_line_segments(
                f"{prefix}/edges",
                g.segments,
                colors=EDGE_RGB,
                thickness=2.0,
                thickness_units="screen",
            )
        )
    if len(g.nodes):
        handles.append(
            scene.add_point_cloud(f"{prefix}/nodes", g.nodes, colors=NODE_RGB, point_size=0.08)
        )
    for k, (p, name) in enumerate(zip(g.stations, g.station_names, strict=True)):
        handles.append(
            scene.add_point_cloud(
                f"{prefix}/stations/{k}", p[None, :], colors=STATION_RGB, point_size=0.2
            )
        )
        handles.append(
            scene.add_label(f"{prefix}/stations/{k}/label", name, position=tuple(p + (0, 0, 0.3)))
        )
    return handles
