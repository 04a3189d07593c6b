"""Draw the multi-wing building of ``scenarios/slam_wings.yaml`` and write its waypoints.

    python scripts/make_slam_wings.py

Writes ``scenarios/slam_wings.png`` (5 cm a pixel, dark = wall) and rewrites the waypoint list
at the end of ``scenarios/slam_wings.yaml``. The building: a 40 m corridor, a wing at 30 deg,
one at 100 deg, a long one slanted 10 deg off east-west, a 17 m x 16 m lobby with twelve
round pillars and benches, and a corridor at 245 deg back to the start; twelve rooms behind
1.2 m doors. Every corridor is 2.2 m wide. Only the lobby's and the rooms' walls run along
the map's axes, so most walls are drawn as staircases of 5 cm cells, as a real building's
slanted walls are in any grid map.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenario_route import write_route  # noqa: E402

RES_M = 0.05
WIDTH_M, HEIGHT_M = 72.0, 51.0
CORRIDOR_M = 2.2
ROOT = Path(__file__).resolve().parents[1] / "scenarios"

Point = tuple[float, float]

A0, A1 = (5.0, 8.0), (45.0, 8.0)
B1 = (A1[0] + 20 * math.cos(math.radians(30)), A1[1] + 20 * math.sin(math.radians(30)))
C1 = (B1[0] - 17 * math.sin(math.radians(10)), B1[1] + 17 * math.cos(math.radians(10)))
D1 = (26.0, 41.0)
E0 = (16.0, 32.0)  # the lobby end of the corridor back to A0
LOBBY = (9.0, 31.0, 26.0, 47.0)
PILLARS = [  # a 4 m grid with one left out
    (x, y) for x in (12.0, 16.0, 20.0, 24.0) for y in (34.5, 38.5, 42.5) if (x, y) != (16.0, 38.5)
]
# rooms: (corridor from, corridor to, fraction along, depth, width, side: +1 left, -1 right)
ROOMS = [
    *[(A0, A1, t, 4.5, 3.6, -1) for t in (0.2, 0.45, 0.7, 0.9)],
    *[(A0, A1, t, 4.0, 3.6, +1) for t in (0.3, 0.6)],
    *[(A1, B1, t, 4.5, 3.6, -1) for t in (0.35, 0.75)],
    *[(C1, D1, t, 4.0, 3.8, -1) for t in (0.25, 0.55, 0.85)],
    (E0, A0, 0.4, 4.0, 3.4, +1),
]
DOOR_M = 1.2


class Drawing:
    def __init__(self) -> None:
        self.img = Image.new("L", (round(WIDTH_M / RES_M), round(HEIGHT_M / RES_M)), 0)
        self.draw = ImageDraw.Draw(self.img)

    @staticmethod
    def px(p: Point) -> tuple[float, float]:
        return p[0] / RES_M, (HEIGHT_M - p[1]) / RES_M

    def corridor(self, pts: list[Point]) -> None:
        self.draw.line([self.px(p) for p in pts], fill=255, width=round(CORRIDOR_M / RES_M))
        for p in pts:  # round joints
            self.disc(p, CORRIDOR_M / 2, 255)

    def polygon(self, pts: list[Point], fill: int = 255) -> None:
        self.draw.polygon([self.px(p) for p in pts], fill=fill)

    def rect(self, x0: float, y0: float, x1: float, y1: float, fill: int = 255) -> None:
        self.polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)], fill)

    def disc(self, c: Point, r: float, fill: int = 0) -> None:
        x, y = self.px(c)
        k = r / RES_M
        self.draw.ellipse([x - k, y - k, x + k, y + k], fill=fill)


def room(d: Drawing, a: Point, b: Point, t: float, depth: float, width: float, side: int):
    """Carve a room beside corridor a->b at fraction t and its door; returns the corridor
    point in front of the door and a point inside the room."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    ux, uy = (b[0] - a[0]) / length, (b[1] - a[1]) / length
    nx, ny = -uy * side, ux * side
    cx, cy = a[0] + ux * length * t, a[1] + uy * length * t
    wall = CORRIDOR_M / 2 + 0.15

    def at(s: float, n: float) -> Point:
        return cx + ux * s + nx * n, cy + uy * s + ny * n

    w = width / 2
    d.polygon([at(-w, wall), at(w, wall), at(w, wall + depth), at(-w, wall + depth)])
    h = DOOR_M / 2
    d.polygon([at(-h, wall - 0.25), at(h, wall - 0.25), at(h, wall + 0.05), at(-h, wall + 0.05)])
    return at(0, 0), at(0, wall + 0.6 * depth)


def visit(front: Point, inside: Point) -> list[Point]:
    """Into a room and round: front of the door, either side of a point inside, back out."""
    f, r = np.array(front), np.array(inside)
    n = (r - f) / np.linalg.norm(r - f)
    u = np.array([n[1], -n[0]])
    return [front, tuple(r - 0.7 * u), tuple(r + 0.7 * u), front]


def main(root: Path = ROOT) -> None:
    d = Drawing()
    d.corridor([A0, A1, B1, C1, D1])
    d.corridor([E0, A0])
    d.rect(*LOBBY)
    d.rect(26.0, 39.9, 27.0, 42.1)  # where the slanted corridor opens into the lobby
    doors = [room(d, *r) for r in ROOMS]
    for p in PILLARS:
        d.disc(p, 0.3)
    rng = np.random.default_rng(7)
    for _ in range(14):  # benches along the lobby's north and south walls
        x = rng.uniform(9.6, 25.4)
        y = rng.choice([rng.uniform(45.6, 46.4), rng.uniform(31.4, 31.9)])
        if abs(x - 16.0) >= 2.5:  # not in the corridor's mouth
            d.rect(x, y, x + 0.45, y + 0.45, 0)
    d.img.save(root / "slam_wings.png")

    lobby = [(22.0, 40.5), (14.0, 40.5), (14.0, 36.5), (18.0, 36.5), E0]
    first = [(8.0, 8.0)]
    for i in sorted([0, 4, 2], key=lambda i: doors[i][0][0]):  # rooms on corridor A, west to east
        first += visit(*doors[i])
    first += [A1, *visit(*doors[6]), B1, C1, *visit(*doors[9]), D1, *lobby, *visit(*doors[11]), A0]
    second = [(8.0, 8.0), A1, B1, C1, D1, (22.0, 40.5), (18.0, 40.5), (18.0, 36.5), E0, A0]
    third = [(8.0, 8.0), A1, B1, C1, D1, *lobby, A0, (10.0, 8.0)]
    write_route(
        root,
        "slam_wings",
        [(float(x), float(y)) for x, y in first + second + third],
        "make_slam_wings.py",
    )


if __name__ == "__main__":
    main()
