"""The 3D scene of the browser app, drawn with viser (three.js in the browser).

One ``SceneView`` keeps the viewer in step with a ``Session``: the floor and the walls (one
merged mesh, rebuilt only when the maze changes), each robot as its model (body, wheels at
their real positions turning with their rotation and steering angles, Mecanum rollers), the
sensor beams in the thesis's colours (green rangers, blue lidar) with their hit points, trails,
the world's vision markers (ArUco, AprilTag, QR codes, colour patches) on their wall faces, the
scenario's ``layout:`` (nodes, edges, stations; app.fleet_view) and an optional map overlay.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from agvsim.app import fleet_view, shapes
from agvsim.app.guidance_view import draw_guidance
from agvsim.app.safety_view import FieldsView
from agvsim.app.session import Session
from agvsim.sim.spec import BODY_HEIGHT_M, WALL_HEIGHT_M
from agvsim.world.grid import OccupancyGrid
from agvsim.world.markers import Marker

RANGER_RGB = (40, 200, 60)
LIDAR_RGB = (40, 110, 235)
HIT_RGB = (230, 40, 40)
WALL_RGB = (150, 150, 160)
BOX_RGB = (196, 140, 72)  # racks and pallets: wood / orange steel


def hex_rgb(color: str) -> tuple[int, int, int]:
    c = color.lstrip("#")
    try:
        return (int(c[0:2], 16), int(c[2:4], 16), int(c[4:6], 16))
    except (ValueError, IndexError):
        return (214, 39, 40)


@dataclass
class _RobotNodes:
    frame: Any
    wheels: list[Any]
    parts: shapes.RobotParts
    label: Any


def overlay_rgb(free: np.ndarray) -> np.ndarray:
    """Colours of a map overlay: ``free`` 0 (occupied) .. 1 (free) from near-black through
    grey-blue (0.5, unknown) to light blue, as uint8 RGB."""
    f = np.clip(np.asarray(free, np.float64), 0.0, 1.0)[..., None]
    return np.rint(30.0 + f * np.array([120.0, 200.0, 225.0])).astype(np.uint8)


class SceneView:
    """Draws ``session`` into ``server``'s scene; call ``update()`` every frame."""

    def __init__(self, server: viser.ViserServer, session: Session):
        self.server, self.session = server, session
        self.show_beams = True
        self.show_trails = True
        self.show_overlay = False
        self.overlay: tuple[np.ndarray, float, tuple[float, float]] | None = None
        self._layout = -1
        self._world = -1
        self._robots: list[_RobotNodes] = []
        self._beams: Any = None
        self._hits: Any = None
        self._trails: Any = None
        self._trails_key: tuple | None = None  # what the trails sent last showed
        self._overlay_node: Any = None
        self._markers: list[Any] = []
        self._layout_nodes: list[Any] = []  # the scenario's layout: nodes, edges, stations
        self._boxes: list[Any] = []  # the world's static boxes (racks, pallets)
        self._guidance: list[Any] = []  # tape, spots, floor codes, reflectors
        self._fields = FieldsView()  # safety scanners' field sets (app.safety_view)
        self._frame = 0
        self.frames_sent = 0
        server.scene.set_up_direction("+z")
        server.scene.add_light_hemisphere("/light/sky", intensity=1.2)
        server.scene.add_light_directional("/light/sun", intensity=1.5, wxyz=(0.92, 0.2, -0.3, 0.1))

    # ------------------------------------------------------------------ building
    def _build_world(self, grid: OccupancyGrid, markers: tuple[Marker, ...] = ()) -> None:
        sc = self.server.scene
        xmin, xmax, ymin, ymax = grid.extent_m
        w, h = xmax - xmin, ymax - ymin
        sc.add_grid(
            "/floor",
            width=w,
            height=h,
            cell_size=grid.resolution_m if max(grid.rows, grid.cols) <= 200 else 1.0,
            section_size=max(1.0, 5 * grid.resolution_m),
            plane_color=(235, 235, 228),
            plane_opacity=1.0,
            position=((xmin + xmax) / 2, (ymin + ymax) / 2, -0.002),
        )
        verts, faces = shapes.wall_mesh(grid, min(WALL_HEIGHT_M, 1.0))
        if len(faces):
            sc.add_mesh_simple(
                "/walls",
                verts,
                faces,
                color=WALL_RGB,
                flat_shading=True,
                side="double",
                cast_shadow=False,
                receive_shadow=False,
            )
        else:
            sc.add_frame("/walls", show_axes=False)  # replaces an old mesh
        self._draw_markers(markers)
        self._draw_boxes()
        self._guidance = draw_guidance(sc, self.session.sim.world, self._guidance)
        self._draw_overlay()
        self._layout_nodes = fleet_view.draw_session_layout(sc, self.session, self._layout_nodes)

    def _draw_boxes(self) -> None:
        """The world's static boxes (``world.boxes``: racks, pallets) as solid blocks, as tall
        as the walls; they are obstacles to the robots and their lidars."""
        for node in self._boxes:
            node.remove()
        self._boxes = []
        boxes = np.asarray(self.session.sim.world.boxes, dtype=float).reshape(-1, 5)
        height = min(WALL_HEIGHT_M, 1.0)
        for k, (cx, cy, th, hl, hw) in enumerate(boxes.tolist()):
            self._boxes.append(
                self.server.scene.add_box(
                    f"/boxes/b{k}",
                    color=BOX_RGB,
                    dimensions=(2 * hl, 2 * hw, height),
                    wxyz=(float(np.cos(th / 2)), 0.0, 0.0, float(np.sin(th / 2))),
                    position=(cx, cy, height / 2),
                    cast_shadow=False,
                    receive_shadow=False,
                )
            )

    def _draw_markers(self, markers: tuple[Marker, ...]) -> None:
        """Each marker as an image (its texture, quiet zone included) just in front of its
        wall face, unlit, so it shows its printed colours."""
        for node in self._markers:
            node.remove()
        self._markers = []
        for k, mk in enumerate(markers):
            position, wxyz = shapes.marker_pose(mk)
            self._markers.append(
                self.server.scene.add_image(
                    f"/markers/m{k}",
                    shapes.marker_image(mk),
                    render_width=mk.extent_m,
                    render_height=mk.extent_m,
                    format="png",
                    position=tuple(position),
                    wxyz=tuple(wxyz),
                    cast_shadow=False,
                    receive_shadow=False,
                )
            )

    def _build_robots(self) -> None:
        sc = self.server.scene
        for old in self._robots:
            old.frame.remove()
        self._robots = []
        self._fields.clear()
        sim = self.session.sim
        cfg_by_name = {r["name"]: r for r in self.session.config["robots"]}
        for i, spec in enumerate(sim.robots):
            parts = shapes.robot_parts(spec)
            root = f"/robots/r{i}"
            frame = sc.add_frame(root, show_axes=False)
            color = hex_rgb(cfg_by_name.get(spec.name, {}).get("color", spec.color))
            sc.add_box(
                f"{root}/body",
                color=color,
                dimensions=parts.body_size_m,
                position=parts.body_center_m,
                cast_shadow=False,
                receive_shadow=False,
            )
            # a nose marks the front
            bx, _, bz = parts.body_center_m
            sc.add_box(
                f"{root}/nose",
                color=(250, 250, 250),
                dimensions=(0.06, parts.body_size_m[1] * 0.5, 0.02),
                position=(bx + parts.body_size_m[0] / 2 - 0.05, 0.0, bz + BODY_HEIGHT_M / 2),
                cast_shadow=False,
                receive_shadow=False,
            )
            wheels = []
            for k, wp in enumerate(parts.wheels):
                node = sc.add_frame(
                    f"{root}/w{k}", show_axes=False, position=(wp.x_m, wp.y_m, wp.radius_m)
                )
                sc.add_cylinder(
                    f"{root}/w{k}/tyre",
                    radius=wp.radius_m,
                    height=wp.width_m,
                    color=(40, 40, 40),
                    radial_segments=20,
                    cast_shadow=False,
                    receive_shadow=False,
                )
                # a spoke shows the rotation
                sc.add_box(
                    f"{root}/w{k}/spoke",
                    color=(235, 200, 40),
                    dimensions=(wp.radius_m * 1.6, wp.radius_m * 0.25, wp.width_m * 1.05),
                    cast_shadow=False,
                    receive_shadow=False,
                )
                if wp.rollers:
                    for j in range(8):
                        a = 2 * np.pi * j / 8
                        q = shapes.quat_mul(
                            shapes.quat_z(a),
                            np.array([np.cos(np.pi / 8), np.sin(np.pi / 8) * wp.rollers, 0, 0]),
                        )
                        sc.add_box(
                            f"{root}/w{k}/roller{j}",
                            color=(120, 120, 130),
                            dimensions=(wp.radius_m * 0.25, wp.radius_m * 0.18, wp.width_m * 1.2),
                            position=(wp.radius_m * np.cos(a), wp.radius_m * np.sin(a), 0.0),
                            wxyz=q,
                            cast_shadow=False,
                            receive_shadow=False,
                        )
                wheels.append(node)
            label = sc.add_label(
                f"{root}/label", spec.name, position=(0.0, 0.0, 0.8), font_screen_scale=0.8
            )
            self._robots.append(_RobotNodes(frame, wheels, parts, label))
        self._beams = None
        self._hits = None

    def _draw_overlay(self) -> None:
        if self._overlay_node is not None:
            self._overlay_node.remove()
            self._overlay_node = None
        if not self.show_overlay:
            return
        if self.overlay is not None:
            img, res, origin = self.overlay
        else:
            g = self.session.sim.world.grid
            img = np.where(g.occupied, 0.0, 1.0)
            res, origin = g.resolution_m, g.origin_xy_m
        rgb = overlay_rgb(img)
        h, w = img.shape
        self._overlay_node = self.server.scene.add_image(
            "/overlay",
            rgb,
            render_width=w * res,
            render_height=h * res,
            position=(origin[0] + w * res / 2, origin[1] + h * res / 2, 0.01),
            format="png",
        )

    def set_overlay(self, occupancy: np.ndarray | None, res: float = 1.0, origin=(0.0, 0.0)):
        """Show a map on the floor (e.g. the SLAM map: 0 occupied .. 1 free, row 0 north);
        ``None`` shows the world's own grid."""
        self.overlay = None if occupancy is None else (np.asarray(occupancy), res, tuple(origin))
        self._draw_overlay()

    # ------------------------------------------------------------------ every frame
    def update(self) -> None:
        s = self.session
        with s.lock:
            sim = s.sim
            layout, world = s.layout, s.world_version
            st = sim.state
            poses = st.poses.copy()
            wheel_angles = st.wheel_angles.copy()
            steer = st.steer_angles.copy()
            scans = st.scans.copy()
            table = sim.sensors
            grid = sim.world.grid
            markers = sim.world.appearance.markers
            trails = None  # copied only on the frames that send them (every tenth)
            if self._frame % 10 == 0:
                trails = [np.array(h.trail) for h in s.history.values()] if self.show_trails else []
            kinds = _sensor_kinds(s.config, table)
            specs, safety = sim.robots, (st.safety_set.copy(), st.safety_status.copy())
        with self.server.atomic():
            if world != self._world or layout != self._layout:
                if world != self._world:
                    self._build_world(grid, markers)
                    self._world = world
                if layout != self._layout:
                    self._build_robots()
                    self._layout = layout
            for i, nodes in enumerate(self._robots):
                x, y, th = poses[i]
                nodes.frame.position = (x, y, 0.0)
                nodes.frame.wxyz = shapes.quat_z(th)
                q = shapes.wheel_quaternions(nodes.parts, wheel_angles[i], steer[i])
                for k, node in enumerate(nodes.wheels):
                    node.wxyz = q[k]
            self._update_beams(table, poses, scans, kinds)
            self._fields.update(self.server, specs, *safety)
            if trails is not None:
                self._update_trails(trails)
        self._frame += 1
        self.frames_sent += 1

    def _update_beams(self, table, poses, scans, kinds) -> None:
        sc = self.server.scene
        if not self.show_beams or table.count == 0:
            if self._beams is not None:
                self._beams.visible = False
                self._hits.visible = False
            return
        seg, slot, hit = shapes.beam_segments(table, poses, scans)
        colors = np.where(kinds[slot][:, None], LIDAR_RGB, RANGER_RGB).astype(np.uint8)
        colors = np.repeat(colors[:, None, :], 2, axis=1)
        pts = seg.astype(np.float32)
        hits = pts[hit, 1] if hit.any() else np.zeros((1, 3), np.float32) - 100
        if self._beams is None or len(self._beams.points) != len(pts):
            self._beams = sc.add_line_segments(
                "/beams", pts, colors, thickness=1.0, thickness_units="screen"
            )
            self._hits = sc.add_point_cloud(
                "/hits", hits, colors=HIT_RGB, point_size=0.035, point_shape="circle"
            )
        else:
            self._beams.points = pts
            self._beams.colors = colors
            self._hits.points = hits
        self._beams.visible = True
        self._hits.visible = True

    def _update_trails(self, trails: list[np.ndarray]) -> None:
        # unchanged trails (a paused run) are not sent again: each re-add rebuilds the
        # browser's line geometry, and four a second kept a software-rendered page busy
        key = tuple((len(t), *map(float, t[-1])) if len(t) else (0,) for t in trails)
        if key == self._trails_key:
            return
        self._trails_key = key
        segs = []
        for t in trails:
            if len(t) >= 2:
                t = t[:: max(1, len(t) // 1500)]
                p = np.column_stack([t, np.full(len(t), 0.02)])
                segs.append(np.stack([p[:-1], p[1:]], axis=1))
        if not segs:
            if self._trails is not None:
                self._trails.visible = False
            return
        pts = np.concatenate(segs).astype(np.float32)
        # re-added (same name replaces): the number of segments changes
        self._trails = self.server.scene.add_line_segments(
            "/trails", pts, colors=(90, 90, 90), thickness=2.0, thickness_units="screen"
        )


def _sensor_kinds(config: dict, table) -> np.ndarray:
    """(S,) True for a lidar slot, False for the rangers (they draw green)."""
    kinds = []
    for r in config["robots"]:
        for s in r.get("sensors", []):
            if s.get("type") in ("lidar", "rangers"):  # the range sensors' slots only
                kinds.append(s.get("type") == "lidar")
    out = np.array(kinds, dtype=bool)
    if len(out) != table.count:  # config and sim out of step for a moment: colour by beams
        out = np.array([sp.num_beams > 8 for sp in table.specs], dtype=bool)
    return out
