"""Collision kernels: hand-worked overlaps and near misses (touching is not colliding), and
random scenes against an independent reference: the area of the polygon clipped from one
rectangle by the other (Sutherland-Hodgman), overlap meaning positive area."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agvsim.sim.collide import (
    Collider,
    box_pairs_overlapping,
    boxes_hit_boxes,
    boxes_hit_grid,
    warmup,
)
from agvsim.world.grid import OccupancyGrid


# ---------------------------------------------------------------------------- reference
def corners(b) -> list[tuple[float, float]]:
    cx, cy, th, hl, hw = b
    c, s = math.cos(th), math.sin(th)
    return [
        (cx + sx * hl * c - sy * hw * s, cy + sx * hl * s + sy * hw * c)
        for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))
    ]  # counter-clockwise


def clip_area(poly, clip) -> float:
    """Area of convex ``poly`` clipped by the convex counter-clockwise polygon ``clip``."""
    out = list(poly)
    for (ax, ay), (bx, by) in zip(clip, clip[1:] + clip[:1], strict=True):
        src, out = out, []
        side = [(bx - ax) * (py - ay) - (by - ay) * (px - ax) for px, py in src]
        for k, (p, sp) in enumerate(zip(src, side, strict=True)):
            q, sq = src[k - 1], side[k - 1]
            if sp >= 0:
                if sq < 0:
                    out.append(_cut(q, p, sq, sp))
                out.append(p)
            elif sq >= 0:
                out.append(_cut(q, p, sq, sp))
        if not out:
            return 0.0
    return 0.5 * abs(
        sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(out, out[1:] + out[:1], strict=True))
    )


def _cut(q, p, sq, sp):
    t = sq / (sq - sp)
    return (q[0] + t * (p[0] - q[0]), q[1] + t * (p[1] - q[1]))


def ref_overlap(a, b) -> bool:
    return clip_area(corners(a), corners(b)) > 1e-12


def ref_hit_grid(grid: OccupancyGrid, b) -> bool:
    xmin, xmax, ymin, ymax = grid.extent_m
    pts = np.array(corners(b))
    if (
        pts[:, 0].min() < xmin
        or pts[:, 0].max() > xmax
        or pts[:, 1].min() < ymin
        or (pts[:, 1].max() > ymax)
    ):
        return True
    res = grid.resolution_m
    ox, oy = grid.origin_xy_m
    iy, ix = np.nonzero(grid.cells_bu)
    x_lo, y_lo = ox + ix * res, oy + iy * res
    near = (x_lo <= pts[:, 0].max()) & (x_lo + res >= pts[:, 0].min())
    near &= (y_lo <= pts[:, 1].max()) & (y_lo + res >= pts[:, 1].min())
    for x0, y0 in zip(x_lo[near].tolist(), y_lo[near].tolist(), strict=True):
        cell = [(x0 + res, y0 + res), (x0, y0 + res), (x0, y0), (x0 + res, y0)]
        if clip_area(corners(b), cell) > 1e-12:
            return True
    return False


def random_boxes(rng, n, xmin, xmax, ymin, ymax, size=(0.1, 0.8)) -> np.ndarray:
    return np.column_stack(
        [
            rng.uniform(xmin, xmax, n),
            rng.uniform(ymin, ymax, n),
            rng.uniform(-4, 4, n),
            rng.uniform(*size, n),
            rng.uniform(size[0], size[1] * 0.6, n),
        ]
    )


# ---------------------------------------------------------------------------- walls
@pytest.fixture(scope="module")
def wall_cell() -> Collider:
    """10 x 10 free 1 m cells on [0, 10]^2 with one wall cell [5, 6] x [5, 6]."""
    occ = np.zeros((10, 10), dtype=bool)
    occ[10 - 1 - 5, 5] = True
    return Collider(OccupancyGrid(occ, 1.0, (0.0, 0.0)))


@pytest.mark.parametrize(
    ("box", "hit"),
    [
        ((4.5, 5.5, 0.0, 0.5, 0.4), False),  # west face on the wall's west face: touching
        ((4.5 + 1e-9, 5.5, 0.0, 0.5, 0.4), True),
        ((4.5, 4.5, 0.0, 0.5, 0.5), False),  # only the corners (5, 5) meet
        ((4.5, 4.5, math.pi / 4, 0.5, 0.5), False),  # diamond: its edge x + y = 9.71 < 10
        ((4.65, 4.65, math.pi / 4, 0.5, 0.5), True),  # edge x + y = 10.007: cuts the corner
        ((5.5, 4.6, math.pi / 2, 0.4, 0.3), False),  # turned 90 deg, touching the south face
        ((5.5, 4.6 + 1e-9, math.pi / 2, 0.4, 0.3), True),
        ((5.5, 5.5, 0.3, 0.1, 0.1), True),  # inside the wall
        ((2.0, 2.0, 1.0, 0.8, 0.4), False),
        ((9.75, 2.0, 0.0, 0.25, 0.25), False),  # touches the map's east border from inside
        ((9.76, 2.0, 0.0, 0.25, 0.25), True),  # pokes out of the map
        ((0.45, 2.0, 0.0, 0.4, 0.4), False),
        ((0.45, 2.0, math.pi / 4, 0.4, 0.4), True),  # turned: a corner leaves the map
    ],
)
def test_box_vs_wall_hand_worked(wall_cell, box, hit):
    assert wall_cell.hit_walls(np.array([box]))[0] == hit
    assert ref_hit_grid(wall_cell.grid, box) == hit


@pytest.mark.parametrize("cell_m", [1.0, 0.25])
def test_walls_match_reference_on_random_boxes(cell_m):
    rng = np.random.default_rng(1)
    m = np.zeros((20, 20), dtype=bool)
    m[0, :] = m[-1, :] = m[:, 0] = m[:, -1] = True
    m[4, 2:12] = m[8, 5:13] = m[4:12, 15] = m[12:18, 5] = True
    m |= rng.random((20, 20)) < 0.05
    k = round(1 / cell_m)
    grid = OccupancyGrid.from_matrix(np.kron(m, np.ones((k, k), dtype=bool)), cell_m)
    boxes = random_boxes(rng, 300, -10.5, 10.5, -10.5, 10.5)
    got = Collider(grid).hit_walls(boxes)
    want = [ref_hit_grid(grid, b) for b in boxes]
    np.testing.assert_array_equal(got, want)
    assert 30 < got.sum() < 270  # both outcomes well represented


# ---------------------------------------------------------------------------- boxes
@pytest.mark.parametrize(
    ("other", "hit"),
    [
        ((2.0, 0.0, 0.0, 1.0, 0.5), False),  # faces touch along x = 1
        ((1.999, 0.0, 0.0, 1.0, 0.5), True),
        ((2.0, 1.0, 0.0, 1.0, 0.5), False),  # corners touch at (1, 0.5)
        ((1.8, 0.0, math.pi / 4, 0.5, 0.5), False),  # diamond's vertex at x = 1.09
        ((1.6, 0.0, math.pi / 4, 0.5, 0.5), True),  # ... at x = 0.89
        ((1.71, 0.6, math.pi / 4, 0.5, 0.5), False),  # near the corner, separated on a diagonal
        ((0.0, 1.0, math.pi / 2, 0.7, 0.2), True),  # crossing at right angles
        ((0.0, 1.2, math.pi / 2, 0.7, 0.2), False),  # turned 90 deg, touching y = 0.5
        ((0.0, 1.2 - 1e-9, math.pi / 2, 0.7, 0.2), True),
    ],
)
def test_box_vs_box_hand_worked(other, hit):
    a = np.array([[0.0, 0.0, 0.0, 1.0, 0.5]])
    assert boxes_hit_boxes(a, np.array([other]))[0] == hit
    assert boxes_hit_boxes(np.array([other]), a)[0] == hit
    assert ref_overlap(a[0], other) == hit


def test_hit_static_matches_reference():
    rng = np.random.default_rng(2)
    boxes = random_boxes(rng, 200, 0, 30, 0, 30)
    static = random_boxes(rng, 60, 0, 30, 0, 30, size=(0.3, 2.0))
    got = Collider(OccupancyGrid(np.zeros((3, 3), dtype=bool), 10.0)).hit_static(boxes, static)
    want = [any(ref_overlap(b, o) for o in static) for b in boxes]
    np.testing.assert_array_equal(got, want)
    assert 10 < got.sum() < 190
    assert not boxes_hit_boxes(boxes, np.zeros((0, 5))).any()


def _sat_all_pairs(b: np.ndarray) -> set[tuple[int, int]]:
    """Brute force over all pairs, vectorised SAT on the four box axes."""
    c, s = np.cos(b[:, 2]), np.sin(b[:, 2])
    dx = b[None, :, 0] - b[:, None, 0]
    dy = b[None, :, 1] - b[:, None, 1]
    cc = np.abs(c[:, None] * c[None, :] + s[:, None] * s[None, :])
    ss = np.abs(s[:, None] * c[None, :] - c[:, None] * s[None, :])
    hl, hw = b[:, 3], b[:, 4]
    sep = np.abs(dx * c[:, None] + dy * s[:, None]) >= hl[:, None] + hl * cc + hw * ss
    sep |= np.abs(-dx * s[:, None] + dy * c[:, None]) >= hw[:, None] + hl * ss + hw * cc
    sep |= np.abs(dx * c + dy * s) >= hl + hl[:, None] * cc + hw[:, None] * ss
    sep |= np.abs(-dx * s + dy * c) >= hw + hl[:, None] * ss + hw[:, None] * cc
    i, j = np.nonzero(~sep)
    return {(a, b) for a, b in zip(i.tolist(), j.tolist(), strict=True) if a < b}


def test_pairs_match_brute_force_reference():
    rng = np.random.default_rng(3)
    boxes = random_boxes(rng, 250, 0, 25, 0, 25)
    pairs = Collider(OccupancyGrid(np.zeros((2, 2), dtype=bool))).overlapping_pairs(boxes)
    assert pairs.dtype == np.int64 and pairs.shape[1] == 2
    got = [tuple(p) for p in pairs.tolist()]
    assert got == sorted(got)  # sorted, each pair once with i < j
    dist = np.hypot(*(boxes[:, None, :2] - boxes[None, :, :2]).transpose(2, 0, 1))
    near = zip(*np.nonzero(np.triu(dist < 2.0, 1)), strict=True)
    want = sorted((i, j) for i, j in near if ref_overlap(boxes[i], boxes[j]))
    assert got == want
    assert len(want) > 20


def test_pairs_many_spread_boxes_and_edge_cases():
    rng = np.random.default_rng(4)
    boxes = random_boxes(rng, 1500, 0, 600, 0, 600, size=(0.2, 2.0))
    boxes[:40, :2] = rng.uniform(0, 5, (40, 2))  # a crowded corner
    boxes[40] = [3000.0, -2000.0, 0.0, 5.0, 5.0]  # one far away: the bins must not explode
    got = {tuple(p) for p in box_pairs_overlapping(boxes).tolist()}
    assert got == _sat_all_pairs(boxes)
    assert box_pairs_overlapping(boxes[:1]).shape == (0, 2)
    assert box_pairs_overlapping(np.zeros((0, 5))).shape == (0, 2)
    two = np.array([[0.0, 0.0, 0.0, 1.0, 1.0], [2.0, 0.0, 0.0, 1.0, 1.0]])  # touching
    assert box_pairs_overlapping(two).shape == (0, 2)
    two[1, 0] = 1.5
    np.testing.assert_array_equal(box_pairs_overlapping(two), [[0, 1]])


def test_wrapper_validation_set_grid_and_warmup(wall_cell):
    with pytest.raises(ValueError, match="boxes"):
        wall_cell.hit_walls(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="static"):
        wall_cell.hit_static(np.zeros((3, 5)), np.full((1, 5), np.nan))
    col = Collider(wall_cell.grid)
    box = np.array([[5.5, 5.5, 0.0, 0.2, 0.2]])
    assert col.hit_walls(box)[0]
    col.set_grid(OccupancyGrid(np.zeros((10, 10), dtype=bool), 1.0, (0.0, 0.0)))
    assert not col.hit_walls(box)[0]
    assert boxes_hit_grid(col.grid.cells_bu, 1.0, 0.0, 0.0, np.zeros((0, 5))).shape == (0,)
    assert warmup() >= 0.0
