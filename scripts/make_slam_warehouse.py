"""Draw the rack warehouse of ``scenarios/slam_warehouse.yaml`` and write its waypoints.

    python scripts/make_slam_warehouse.py

Writes ``scenarios/slam_warehouse.png`` (5 cm a pixel, dark = wall) and rewrites the waypoint
list at the end of ``scenarios/slam_warehouse.yaml``. The hall: 60 m x 40 m, eight
double-sided racks about 22 m long running north-south with 3.3 m aisles between them, as a scanner
at wheel height sees them: 10 cm uprights every 2.7 m on both faces and the back, and a
1.2 m x 0.9 m pallet on the floor in about half the bays (drawn from a fixed seed); six
building columns, a small office in a corner and a few boxes by the east wall. The aisles
look alike, and between the uprights a scan sees through the racks.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenario_route import write_route  # noqa: E402

RES_M = 0.05
WIDTH_M, HEIGHT_M = 60.0, 40.0
ROOT = Path(__file__).resolve().parents[1] / "scenarios"
RACKS_X = [8.0 + 5.4 * k for k in range(8)]  # rack centre lines
RACK_Y = (8.0, 32.0)
UPRIGHT_PITCH_M = 2.7
FACE_M = 1.05  # from the centre line to a face's uprights

Point = tuple[float, float]


class Drawing:
    def __init__(self) -> None:
        size = (round(WIDTH_M / RES_M), round(HEIGHT_M / RES_M))
        self.img = Image.new("L", size, 255)
        self.draw = ImageDraw.Draw(self.img)

    def rect(self, x0: float, y0: float, x1: float, y1: float, fill: int = 0) -> None:
        top_left = (x0 / RES_M, (HEIGHT_M - y1) / RES_M)
        bottom_right = (x1 / RES_M, (HEIGHT_M - y0) / RES_M)
        self.draw.rectangle([top_left, bottom_right], fill=fill)

    def post(self, x: float, y: float, half: float) -> None:
        self.rect(x - half, y - half, x + half, y + half)


def main(root: Path = ROOT) -> None:
    d = Drawing()
    for x0, y0, x1, y1 in [
        (0.0, 0.0, WIDTH_M, 0.3),
        (0.0, HEIGHT_M - 0.3, WIDTH_M, HEIGHT_M),
        (0.0, 0.0, 0.3, HEIGHT_M),
        (WIDTH_M - 0.3, 0.0, WIDTH_M, HEIGHT_M),
    ]:
        d.rect(x0, y0, x1, y1)
    rng = np.random.default_rng(3)
    for xc in RACKS_X:
        bays = np.arange(RACK_Y[0], RACK_Y[1] + 1e-6, UPRIGHT_PITCH_M)
        for face in (-1, 1):
            for y in bays:
                d.post(xc + face * FACE_M, y, 0.05)
                d.post(xc, y, 0.05)
            for y in np.arange(RACK_Y[0], RACK_Y[1] - 1.0, UPRIGHT_PITCH_M):
                if rng.random() < 0.55:
                    yy = y + 0.15 + rng.uniform(0.0, 1.2)
                    xa = xc + (0.1 if face > 0 else -1.0)
                    d.rect(xa, yy, xa + 0.9, yy + 1.2)
    for x in (15.0, 30.0, 45.0):
        for y in (3.0, 37.5):
            d.post(x, y, 0.2)
    d.rect(0.3, 36.5, 6.0, 36.8)  # the office, its door 1.2 m wide
    d.rect(6.0, 36.5, 6.3, 39.7)
    d.rect(3.0, 36.5, 4.2, 36.8, 255)
    for x, y in [(52.0, 3.0), (54.5, 3.0), (57.0, 3.0), (52.0, 5.5)]:
        d.rect(x, y, x + 1.2, y + 0.8)
    d.img.save(root / "slam_warehouse.png")

    aisle = [x + UPRIGHT_PITCH_M for x in RACKS_X[:-1]]  # aisle centre lines
    south, north, east = 6.0, 34.2, 50.0
    route: list[Point] = [(3.0, south), (east, south), (east, north)]
    route += [(aisle[0], north), (aisle[0], south), (aisle[2], south), (aisle[2], north)]
    route += [(aisle[4], north), (aisle[4], south), (east, south), (east, north)]
    route += [(4.0, north), (4.0, south), (aisle[1], south), (aisle[1], north)]
    route += [(aisle[5], north), (aisle[5], south), (east, south), (east, north)]
    route += [(aisle[3], north), (aisle[3], south), (3.0, south), (3.0, 12.0)]
    write_route(root, "slam_warehouse", route, "make_slam_warehouse.py")


if __name__ == "__main__":
    main()
