"""The guidance infrastructure in the 3D view (docs/guidance.md): tape as flat lines on the
floor with its spots as red dots, floor codes as small black squares, reflectors as bright
posts on the walls. ``guidance_shapes`` is the geometry (tested without a browser);
``draw_guidance`` puts it into a viser scene."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

TAPE_RGB = (30, 70, 200)
SPOT_RGB = (220, 30, 30)
CODE_RGB = (20, 20, 20)
REFLECTOR_RGB = (255, 230, 80)
FLOOR_Z_M = 0.003  # just above the floor grid
REFLECTOR_Z_M = (0.2, 0.6)  # the band of the wall a reflector covers


@dataclass(frozen=True)
class GuidanceShapes:
    tape_segments: np.ndarray  # (M, 2, 3) float32 centre-line pieces
    tape_width_m: float
    spots: np.ndarray  # (P, 3)
    code_vertices: np.ndarray  # (4 K, 3) corners of each code's square
    code_faces: np.ndarray  # (2 K, 3) two triangles a square
    reflectors: np.ndarray  # (R, 2) centres
    reflector_width_m: float


def guidance_shapes(world: Any) -> GuidanceShapes:
    """What to draw of ``world``'s tape, floor codes and reflectors (empty arrays without)."""
    tape = getattr(world, "tape", None)
    segs = np.zeros((0, 2, 3), np.float32)
    spots = np.zeros((0, 3))
    width = 0.0
    if tape is not None and len(tape.segments):
        s = tape.segments
        z = np.full(len(s), FLOOR_Z_M)
        segs = np.stack(
            [np.column_stack([s[:, 0], s[:, 1], z]), np.column_stack([s[:, 2], s[:, 3], z])],
            axis=1,
        ).astype(np.float32)
        width = tape.width_m
    if tape is not None and len(tape.spot_xy):
        spots = np.column_stack([tape.spot_xy, np.full(len(tape.spot_xy), 2 * FLOOR_Z_M)])
    verts, faces = np.zeros((0, 3)), np.zeros((0, 3), np.int32)
    grid = getattr(world, "floor_codes", None)
    if grid is not None:
        centres = np.array([grid.code_xy(k) for k in range(grid.cols * grid.rows)])
        h = grid.size_m / 2.0
        corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        xy = (centres[:, None, :] + corners[None]).reshape(-1, 2)
        verts = np.column_stack([xy, np.full(len(xy), 2 * FLOOR_Z_M)])
        base = 4 * np.arange(len(centres))[:, None]
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).astype(np.int32)
    refl = getattr(world, "reflectors", None)
    rxy = np.zeros((0, 2)) if refl is None else refl.xy
    return GuidanceShapes(
        segs, width, spots, verts, faces, rxy, 0.0 if refl is None else refl.width_m
    )


def draw_guidance(scene: Any, world: Any, nodes: list[Any]) -> list[Any]:
    """Draw the world's guidance into ``scene``, removing ``nodes`` (the last drawing)
    first; returns the new nodes."""
    for node in nodes:
        node.remove()
    out: list[Any] = []
    g = guidance_shapes(world)
    if len(g.tape_segments):
        out.append(
            scene.add_line_segments(
                "/guidance/tape",
                g.tape_segments,
                colors=TAPE_RGB,
                thickness=g.tape_width_m,
                thickness_units="world",
            )
        )
    if len(g.spots):
        out.append(
            scene.add_point_cloud(
                "/guidance/spots",
                g.spots.astype(np.float32),
                colors=SPOT_RGB,
                point_size=0.08,
                point_shape="circle",
            )
        )
    if len(g.code_faces):
        out.append(
            scene.add_mesh_simple(
                "/guidance/codes",
                g.code_vertices.astype(np.float32),
                g.code_faces,
                color=CODE_RGB,
                flat_shading=True,
                cast_shadow=False,
                receive_shadow=False,
            )
        )
    lo, hi = REFLECTOR_Z_M
    for k, (x, y) in enumerate(g.reflectors.tolist()):
        out.append(
            scene.add_box(
                f"/guidance/reflectors/r{k}",
                color=REFLECTOR_RGB,
                dimensions=(g.reflector_width_m, g.reflector_width_m, hi - lo),
                position=(x, y, (lo + hi) / 2),
                cast_shadow=False,
                receive_shadow=False,
            )
        )
    return out
