"""Scan matching kernels on synthetic scans of a polygonal room: known offsets are recovered."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agvsim.slam import scan_matching as sm
from agvsim.slam.mapping import likelihood_field

from helpers import cast_segments

RES = 0.05
ANGLES = np.radians(np.arange(-90.0, 90.0, 1.0))
# an asymmetric 10 m x 8 m room with a pillar, a cupboard and a slanted wall (x0, y0, x1, y1)
WALLS = np.array(
    [
        [0, 0, 10, 0],
        [10, 0, 10, 8],
        [10, 8, 0, 8],
        [0, 8, 0, 0],
        [3, 3, 4, 3],
        [4, 3, 4, 4],
        [4, 4, 3, 4],
        [3, 4, 3, 3],
        [7, 6, 9, 6],
        [9, 6, 9, 8],
        [0, 5, 2, 7.5],
        [6, 0, 6, 1.5],
    ],
    dtype=float,
)


def cast(pose: np.ndarray, walls: np.ndarray = WALLS, angles: np.ndarray = ANGLES) -> np.ndarray:
    """Ranges of beams from ``pose`` to the nearest wall segment (inf: no hit)."""
    return cast_segments(pose, walls, angles)


def points(ranges: np.ndarray) -> np.ndarray:
    ok = np.isfinite(ranges)
    return np.column_stack([ranges[ok] * np.cos(ANGLES[ok]), ranges[ok] * np.sin(ANGLES[ok])])


def room_field(walls: np.ndarray = WALLS, sigma: float = 0.05) -> tuple[np.ndarray, float, float]:
    """Likelihood field of the walls sampled every centimetre (a complete map of the room); the
    walls, at whole metres, run through cell centres."""
    ox, oy = -1.0 - RES / 2, -1.0 - RES / 2
    occ = np.zeros((int(10 / RES), int(12 / RES)), bool)
    for x0, y0, x1, y1 in walls:
        t = np.linspace(0.0, 1.0, int(math.hypot(x1 - x0, y1 - y0) / 0.01) + 2)
        xy = np.column_stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)])
        occ[((xy[:, 1] - oy) / RES).astype(int), ((xy[:, 0] - ox) / RES).astype(int)] = True
    return likelihood_field(occ, sigma, RES), ox, oy


@pytest.mark.parametrize("offset", [(0.12, -0.07, 4.0), (-0.09, 0.11, -5.5), (0.03, 0.02, 0.5)])
def test_correlative_then_gauss_newton_recovers_offset(offset: tuple[float, float, float]) -> None:
    field, ox, oy = room_field()
    truth = np.array([5.0, 2.5, 0.7])
    rng = np.random.default_rng(1)
    ranges = cast(truth) + rng.normal(0.0, 0.01, ANGLES.size)
    guess = truth - np.array([offset[0], offset[1], math.radians(offset[2])])
    pts = points(ranges)
    step = sm.angular_step(RES, 10.0)
    coarse, score = sm.correlative_search(
        field, ox, oy, RES, pts, guess, 0.15, math.radians(6.0), step, 0.0, 0.0
    )
    fine, fine_score, info = sm.gauss_newton(field, ox, oy, RES, pts, coarse, 10, 1e-4)
    assert np.hypot(*(fine[:2] - truth[:2])) < 0.015
    assert abs(fine[2] - truth[2]) < math.radians(0.3)
    assert fine_score > 0.8 and info.shape == (3, 3)
    assert fine_score >= sm.score_pose(field, ox, oy, RES, pts, coarse) - 1e-9


def test_branch_and_bound_finds_large_offset_and_is_exact() -> None:
    field, ox, oy = room_field()
    truth = np.array([4.5, 5.0, -0.4])
    pts = points(cast(truth))
    guess = truth + np.array([0.9, -0.7, math.radians(12.0)])
    step = sm.angular_step(RES, 10.0)
    pyr = sm.max_pyramid(field, 6)
    pose, score = sm.branch_and_bound(
        pyr, ox, oy, RES, pts, guess, 1.2, math.radians(15.0), step, 0.5
    )
    assert np.hypot(*(pose[:2] - truth[:2])) < 0.06 and abs(pose[2] - truth[2]) < 2 * step
    # exact: the same best score as the exhaustive search over the same (smaller) window
    guess2 = truth + np.array([0.2, -0.15, math.radians(2.0)])
    bb_pose, bb = sm.branch_and_bound(
        pyr, ox, oy, RES, pts, guess2, 0.3, math.radians(3.0), step, 0.1
    )
    ex_pose, ex = sm.correlative_search(
        field, ox, oy, RES, pts, guess2, 0.3, math.radians(3.0), step, 0.0, 0.0
    )
    assert bb == pytest.approx(ex, abs=1e-6)
    # below the minimum score nothing is returned
    assert sm.branch_and_bound(pyr, ox, oy, RES, pts, guess, 1.2, 0.2, step, 0.999)[1] == -1.0


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    win_cells=st.integers(1, 23),
    cx=st.floats(-0.5, 2.5),
    cy=st.floats(-0.5, 2.5),
)
def test_branch_and_bound_equals_exhaustive_search(
    seed: int, win_cells: int, cx: float, cy: float
) -> None:
    # random likelihoods on a small grid, a random point cloud around (cx, cy): windows of
    # every size relative to the pyramid's blocks, points falling off every edge of the grid
    rng = np.random.default_rng(seed)
    grid = rng.random((40, 50)).astype(np.float32) ** 4
    pts = rng.normal(0.0, 0.6, (25, 2))
    pose0 = np.array([cx, cy, rng.uniform(-math.pi, math.pi)])
    win, ang, step = win_cells * RES, math.radians(4.0), math.radians(2.0)
    _, bb = sm.branch_and_bound(
        sm.max_pyramid(grid, 4), 0.0, 0.0, RES, pts, pose0, win, ang, step, -0.5
    )  # a minimum score under every score: the best candidate is always returned
    _, ex = sm.correlative_search(grid, 0.0, 0.0, RES, pts, pose0, win, ang, step, 0.0, 0.0)
    assert bb == pytest.approx(ex, abs=1e-6)


def test_max_pyramid_is_block_maximum() -> None:
    rng = np.random.default_rng(3)
    grid = rng.random((13, 17)).astype(np.float32)
    pyr = sm.max_pyramid(grid, 4)
    for lvl in range(4):
        k = 1 << lvl
        iy, ix = 5, 9
        assert pyr[lvl, iy, ix] == grid[iy : iy + k, ix : ix + k].max()
        assert pyr[lvl, 12, 16] == grid[12, 16]  # beyond the edge counts as nothing


def test_angular_step_moves_far_point_one_cell() -> None:
    step = sm.angular_step(0.05, 8.0)
    assert 2 * 8.0 * math.sin(step / 2) == pytest.approx(0.05)


def test_corridor_information_is_weak_along_the_corridor() -> None:
    walls = np.array([[-20, 1, 20, 1], [-20, -1, 20, -1]], float)
    ox, oy = -21.0 - RES / 2, -2.0 - RES / 2
    occ = np.zeros((int(4 / RES), int(42 / RES)), bool)
    occ[[int(1 / RES) - 1, int(3 / RES)], :] = True
    field = likelihood_field(occ, 0.05, RES)
    pose = np.array([0.0, 0.0, 0.0])
    pts = points(cast(pose, walls))
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) < 8.0]
    _, _, h = sm.gauss_newton(field, ox, oy, RES, pts, pose, 5, 1e-4)
    assert h[0, 0] < 0.01 * h[1, 1]
